#pragma once
// FlightMonitor: the referee of a closed-loop simulated flight (node `flight_monitor`). It flies the
// planner through the scenario's goal sequence, one goal at a time, and measures the flight against
// the simulator's true map: goals reached, collisions, clearance, speeds, replanning counts and times
// (the figures of Zhou et al. ICRA 2020, Sec. VI). The bookkeeping is the ROS-free FlightRecorder
// (plan_manage/flight_monitor_core.h); the clearance comes from uav_sim's TruthMap.
//
// Sequence: wait for the true map (~global_cloud), odometry and a subscriber on ~waypoints; after
// start_delay_s send goal 1 as a one-pose nav_msgs/Path (stamp now, frame frame_id); when the body is
// within goal_tolerance_m of it and slower than goal_max_speed_mps, log a line and send the next.
// With mission "waypoints" every goal goes at once, as one Path (see the parameter).
// The flight ends when the last goal is reached or one has taken longer than goal_timeout_s; then
// ~result (latched) is published, the report logged, the files written, and, with
// shutdown_when_done, the node shuts down (mark it required in the launch file so roslaunch ends).
// If the map, odometry or planner do not appear within startup_timeout_s (wall time) the flight
// ends as kNoStart; if the node is shut down early it ends as kInterrupted and still writes its files.
//
// Faults (the fault-injection tests and make bench-faults; see uav_sim/ros/quadrotor_sim.h):
//  - Clearance and contacts are measured on the simulator's ground truth (ground_truth_topic), not
//    on the odometry, which an injected jump offsets and a blackout stops; goals are judged on the
//    odometry (the frame the planner flies in).
//  - The monitor's clock is ROS time with the ROS time steps removed (TimeStepFilter on the ground
//    truth's 200 Hz stamps), so a clock step neither stalls nor ends the flight.
//  - Every setpoint (planning/position_cmd) goes through SetpointWatch: worst commanded deceleration
//    and acceleration, setpoint jumps (a step over |v| dt + setpoint_jump_margin_m), and
//    re-anchorings (a step equal to an injected odometry jump, from quadrotor_sim/odom_offset).
//  - The simulator's fault events are recorded with the commanded and true speeds of the moment.
//  - The active goal is sent again resend_settle_s after the planner restarts (a PlannerHeartbeat
//    with a new planner_session) or a fault clears (GoalResendPolicy), once the heartbeat says the
//    planner's inputs are fresh, so that the mission can complete.
//
// Topics (relative names, resolved in the node's namespace; remap them in the launch file)
//   Subscribed
//     odom                           nav_msgs/Odometry        body pose in frame_id; twist in the child
//                                                             (body) frame unless odom_twist_in_world
//     map_generator/global_cloud     sensor_msgs/PointCloud2  occupied voxel centres of the true map (latched)
//     quadrotor/collision            topo_planner/Collision   the simulator's contact counter
//     planning/replan_event          topo_planner/ReplanEvent one per planning call
//     planning/reference_path        nav_msgs/Path            the planner's global reference (each message
//                                                             is a new reference, kept for the plot)
//     planning/position_cmd          topo_planner/PositionCommand  the setpoints
//     planning/bspline               topo_planner/Bspline     the planner's trajectories (the speed account)
//     planning/heartbeat             topo_planner/PlannerHeartbeat the planner's session and input state
//     quadrotor_sim/ground_truth     nav_msgs/Odometry        the true state (ground_truth_topic)
//     quadrotor_sim/fault_event      std_msgs/String          "<kind> <start|end|step> ..." per fault change
//     quadrotor_sim/odom_offset      geometry_msgs/Vector3Stamped  the injected odometry offset so far
//   Published
//     planning/waypoints             nav_msgs/Path (latched)  the active goal
//     ~result                        topo_planner/FlightResult (latched) at the end
//     ~report                        std_msgs/String (latched) at the end: the report JSON (the
//                                                             <name>_report.json text, with the faults)
//
// Parameters (private unless marked global; defaults are those of the config structs)
//   /sim/start_m, /sim/goals_m, /sim/map_resolution_m (global)  the scenario (uav_sim/ros/truth_map.h);
//                                      ~goals_m [x1, y1, z1, ...] overrides the goals
//   goal_tolerance_m           0.5     body within this distance of the goal ... [m]
//   goal_max_speed_mps         1.0     ... and slower than this counts as reached; 0 = any speed [m/s]
//   mission                    "sequential"  one goal at a time, each reached at rest; "waypoints": the
//                                      goals as one mission (one Path of every goal not yet reached),
//                                      flown through: intermediate ones count within waypoint_tolerance_m
//   waypoint_tolerance_m       1.0     see mission (the planner's fsm/waypoint_reached_radius_m) [m]
//   goal_timeout_s             90      time allowed per goal (ROS time) [s]
//   collision_radius_m         0.15    own contact check: clearance below this (the simulator's body
//                                      sphere radius, quadrotor_sim's collision_radius_m) [m]
//   contact_release_m          0.05    a contact ends above collision_radius_m + this [m]
//   ground_z_m                 0.0     the ground plane counts as an obstacle (as in the simulator) [m]
//   clearance_exact_within_m   1.0     clearances below this are exact, above it lower bounds [m]
//   trace_rate_hz              20      rows of <name>.csv per second [Hz]
//   odom_twist_in_world        false   the odometry twist is already in the world frame (some VIOs)
//   frame_id                   "world" frame of the odometry and the waypoints
//   start_delay_s              1.0     wait this long after everything is ready before goal 1 [s]
//   startup_timeout_s          120     give up (kNoStart) if not ready after this wall time [s]
//   resend_period_s            5.0     re-send the active goal while no planning call followed it; 0 = never [s]
//   resend_settle_s            1.0     re-send it this long after a planner restart or a cleared fault [s]
//   ground_truth_topic         "quadrotor_sim/ground_truth"  true state for clearance and the clock;
//                                      "" = the odometry (no fault injection then)
//   setpoint_jump_margin_m     0.05    a setpoint step above |v| dt + this is a jump [m]
//   reanchor_tolerance_m       0.25    a step this close (+ |v| dt) to an injected odometry jump re-anchors [m]
//   reanchor_window_s          2.0     ... within this after the jump [s]
//   truth/margin_m             1.5     true map window margin around obstacles, start and goals [m]
//   truth/max_distance_m       2.0     ESDF truncation of the true map (broad phase) [m]
//   truth/num_threads          1       ESDF threads while building the true map
//   output_dir                 ""      write the files there (absolute path; created); "" = no files
//   name                       "flight"  file name stem: <name>.csv, <name>_events.csv, <name>_map.csv,
//                                      <name>_reference.csv, <name>_report.json
//   shutdown_when_done         false   ros::requestShutdown() once the files are written
//   max_vel_mps, max_acc_mps2  3.0, 2.5  the flight's limits: the speed account and the oracle [m/s, m/s^2]
//   speed_account/fast_fraction 0.8    an instant at or above this x max_vel is fast (SpeedAccount)
//   speed_account/limit_fraction 0.6   commanded accelerations above this x max_acc are at the limits
//   oracle/clearance_m         0.3     the oracle's route clearance (the planner's search/clearance_m) [m]
//   oracle/min_z_m, max_z_m    0.3, 3.0  its height band (the planner's route/min_z_m, max_z_m) [m]
//   oracle/window_m            []      the planner's map window [ox, oy, oz, sx, sy, sz]: the oracle stays in it
//                                      (simulation.launch passes map_origin and map_size) [m]
//   density, seed, max_vel_mps, scenario/<key>   (any scalar) copied into the report's "scenario"
//
// Speed (the speed account and the oracle): path length, mean and max speed are measured on the
// ground truth when there is one. Every instant slower than fast_fraction x max_vel is attributed
// to a cause (SpeedAccount: held, braking, commitment, takeover, tracking, limits, timing) from the
// setpoint in force and the trajectory it follows; the report gives the shares and the time spent
// fast. Before goal 1 the oracle (FlightOracle) computes, on the true map, the time an ideal vehicle
// flying the shortest way at the limits needs per goal; the report gives the flight's time for the
// goals reached over the oracle's.

#include <geometry_msgs/Point.h>
#include <geometry_msgs/Vector3Stamped.h>
#include <nav_msgs/Odometry.h>
#include <nav_msgs/Path.h>
#include <ros/ros.h>
#include <std_msgs/String.h>
#include <topo_planner/Bspline.h>
#include <topo_planner/Collision.h>
#include <topo_planner/PlannerHeartbeat.h>
#include <topo_planner/PositionCommand.h>
#include <topo_planner/ReplanEvent.h>

#include <Eigen/Core>
#include <map>
#include <memory>
#include <string>
#include <vector>

#include "topo_planner/plan_manage/flight_monitor_core.h"
#include "topo_planner/uav_sim/ros/truth_map.h"
#include "topo_planner/uav_sim/truth_map.h"

namespace topo_planner {

/// Sends the goals, watches the flight and reports it. Single-threaded: every callback and timer
/// runs on the node's one spinner thread, so no member needs a lock.
class FlightMonitor {
 public:
  EIGEN_MAKE_ALIGNED_OPERATOR_NEW

  struct Config {
    FlightRecorder::Config recorder;     ///< goal tolerance, timeout, contact check, trace rate
    TruthMap::Config truth;              ///< resolution, window and ESDF of the true map
    FlightOracle::Config oracle;         ///< the oracle's limits, clearance and height band
    /// The planner's map window (the oracle stays in it); NaN: the whole true map [m].
    Eigen::Vector3d oracle_window_origin_m = Eigen::Vector3d::Constant(std::numeric_limits<double>::quiet_NaN());
    Eigen::Vector3d oracle_window_size_m = Eigen::Vector3d::Constant(std::numeric_limits<double>::quiet_NaN());
    double clearance_exact_within_m = 1.0;  ///< clearances below this are exact [m]
    double ground_z_m = 0.0;             ///< height of the ground plane, an obstacle too [m]
    std::vector<Eigen::Vector3d> goals;  ///< the goal sequence [m]
    Eigen::Vector3d start_m = Eigen::Vector3d::Constant(std::numeric_limits<double>::quiet_NaN());  ///< [m]
    std::string frame_id = "world";      ///< frame of odometry, cloud and waypoints
    bool odom_twist_in_world = false;    ///< the odometry twist is in frame_id, not in the body frame
    double start_delay_s = 1.0;          ///< settle time between ready and goal 1 [s]
    double startup_timeout_s = 120.0;    ///< wall time to become ready [s]
    double resend_period_s = 5.0;        ///< re-send a goal no planning call followed; 0 = never [s]
    double resend_settle_s = 1.0;        ///< re-send it this long after a planner restart or a cleared fault [s]
    std::string ground_truth_topic = "quadrotor_sim/ground_truth";  ///< true state; "" = use the odometry
    double check_period_s = 0.1;         ///< period of the readiness/timeout timer [s]
    std::string output_dir;              ///< where the files go; empty = none
    std::string name = "flight";         ///< file name stem
    bool shutdown_when_done = false;     ///< request a ROS shutdown after writing
    std::map<std::string, std::string> scenario;  ///< key -> JSON value text, for the report

    bool validate(std::string* why) const;
  };

  /// Subscribes and advertises in `nh` (the node's namespace) and `pnh` (private). nullptr with a
  /// reason for an invalid config.
  static std::unique_ptr<FlightMonitor> create(const ros::NodeHandle& nh, const ros::NodeHandle& pnh,
                                               const Config& config, std::string* error);

  /// Ends a flight still running as kInterrupted and writes its files (call after the spinner
  /// stopped, e.g. on SIGINT). Does nothing if the flight already ended.
  void finishInterrupted();
  bool done() const { return done_; }

 private:
  FlightMonitor(const ros::NodeHandle& nh, const ros::NodeHandle& pnh, const Config& config);

  void onTruthMap(const std::shared_ptr<const TruthMap>& map);
  void odomCallback(const nav_msgs::OdometryConstPtr& msg);
  void collisionCallback(const topo_planner::CollisionConstPtr& msg);
  void replanCallback(const topo_planner::ReplanEventConstPtr& msg);
  void referenceCallback(const nav_msgs::PathConstPtr& msg);
  void truthCallback(const nav_msgs::OdometryConstPtr& msg);
  void setpointCallback(const topo_planner::PositionCommandConstPtr& msg);
  void bsplineCallback(const topo_planner::BsplineConstPtr& msg);
  void heartbeatCallback(const topo_planner::PlannerHeartbeatConstPtr& msg);
  void faultCallback(const std_msgs::StringConstPtr& msg);
  void offsetCallback(const geometry_msgs::Vector3StampedConstPtr& msg);
  /// The monitor's time of a stamp (zero: now), ROS time steps removed [s].
  double timeOf(const ros::Time& stamp) const;
  /// The monitor's time now: the latest of the steady stream (ground truth) [s].
  double nowS() const;
  /// The clearance of a true body position (the ground counts) [m].
  double clearanceAt(const Eigen::Vector3d& p) const;
  void checkTimer(const ros::TimerEvent&);
  void startupTimeout(const ros::SteadyTimerEvent&);

  /// Why the flight cannot start yet ("" when it can).
  std::string notReadyReason() const;
  void sendGoal(int index);
  /// The oracle's times for the goals (FlightOracle on the true map), before the first goal is sent.
  void computeOracle();
  void handle(const FlightRecorder::Update& update, double now_s);
  /// Publishes the result, logs the report, writes the files (once).
  void finishFlight(bool publish);
  void writeFiles(const FlightSummary& summary) const;
  FlightReportInfo reportInfo() const;

  ros::NodeHandle nh_, pnh_;
  Config config_;
  FlightRecorder recorder_;
  std::shared_ptr<const TruthMap> truth_;
  std::vector<Eigen::Vector3d> map_columns_;

  bool have_odom_ = false;
  double last_odom_t_s_ = 0.0;
  double last_setpoint_t_s_ = -1e300;  // time of the last setpoint taken [s]
  double ready_since_s_ = -1.0;  // negative while not ready
  double goal_sent_t_s_ = 0.0;
  TimeStepFilter clock_;              // ROS time steps out of the monitor's time
  bool have_stream_time_ = false;
  double last_stream_t_s_ = 0.0;      // latest corrected time of the steady stream [s]
  GoalResendPolicy resend_;
  int goal_resends_ = 0;
  Eigen::Vector3d odom_offset_ = Eigen::Vector3d::Zero();  // the injected offset seen so far
  bool planned_since_goal_ = false;  // a planning call arrived after the active goal was sent
  bool done_ = false;
  std::vector<ReferenceRecord> references_;  // t_s absolute here; made relative when written

  std::unique_ptr<TruthMapSubscriber> truth_sub_;
  std::string cloud_topic_;
  ros::Subscriber odom_sub_, collision_sub_, replan_sub_, reference_sub_;
  ros::Subscriber truth_state_sub_, setpoint_sub_, heartbeat_sub_, fault_sub_, offset_sub_, bspline_sub_;
  bool have_truth_position_ = false;
  Eigen::Vector3d truth_position_ = Eigen::Vector3d::Zero();  // the latest true position [m]
  ros::Publisher waypoint_pub_, result_pub_, report_pub_;
  ros::Timer check_timer_;
  ros::SteadyTimer startup_timer_;
};

/// Reads the parameters above (the scenario from /sim, the rest from the private handle `pnh`) into
/// *config, validates them, and returns false after a ROS_ERROR saying what is wrong.
bool readFlightMonitorParams(const ros::NodeHandle& pnh, FlightMonitor::Config* config);

}  // namespace topo_planner
