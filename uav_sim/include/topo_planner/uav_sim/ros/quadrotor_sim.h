#pragma once
// QuadrotorSim: the simulated vehicle. Integrates the uav_sim Quadrotor (RK4, 1 kHz) under the
// latest rotor command, publishes its odometry and tf, and reports collisions of its body sphere
// with the true map. The node `quadrotor_sim_node` runs one.
//
// Topics (relative names, resolved in the node's namespace: /odom etc. at the root)
//   Subscribed
//     controller/rotor_command     topo_planner/RotorCommand   rotor speeds, held until the next one
//     map_generator/global_cloud   sensor_msgs/PointCloud2     the true map (latched)
//   Published
//     odom                 nav_msgs/Odometry   frame world_frame, child body_frame, twist in the body frame,
//                                              at odom_rate_hz (with optional noise and delay)
//     tf                   world_frame -> body_frame with every odometry message (same pose and stamp);
//                          static body_frame -> camera_frame (camera_extrinsic)
//     quadrotor/collision  topo_planner/Collision  on each new contact
//     ~ground_truth        nav_msgs/Odometry   the true state (no noise, no delay), when subscribed
//     ~fc_odom             nav_msgs/Odometry   the flight controller's estimate: the odometry's drift and
//                                              jumps, no white noise, no delay (when subscribed)
//     /clock               rosgraph_msgs/Clock every step, when publish_clock
//     ~depth_blackout      std_msgs/Bool (latched) true inside a depth blackout window: the depth
//                          camera (uav_sim/ros/depth_camera_server.h) publishes no image meanwhile
//     ~odom_offset         geometry_msgs/Vector3Stamped (latched) the offset the odometry jumps have
//                          added to the published position so far (zero without jumps) [m]
//     ~fault_event         std_msgs/String one line per fault change, FaultSchedule's describe():
//                          "<kind> <start|end|step> t=<simulated s> ...", e.g.
//                          "odom_blackout end t=14.000 s" (what the flight monitor reads)
//
// Time. With publish_clock (the default when /use_sim_time is true) the simulator owns the clock: it
// starts at clock_start_s, advances by step_s per step and is paced at realtime_factor times wall
// speed. Without it, the loop follows the wall clock at real time and stamps with ros::Time.
// Steps run in batches of one odometry period (5 steps at 200 Hz): the loop sleeps until the batch's
// wall time, integrates the 5 steps (each with the command current at that step), then publishes the
// odometry. A loop that falls behind (a loaded machine) catches up by up to max_lag_s of wall time
// and otherwise drops the backlog: with sim time the clock then runs slower than asked (the status
// line reports the achieved factor); in real time the simulated time jumps.
//
// Lockstep (sim time only, `lockstep`). The controller runs on each odometry message and stamps its
// RotorCommand with that odometry's stamp. After publishing odometry the simulator waits (at most
// lockstep_timeout_s of wall time) for the command answering it, so the controller keeps up at any
// real-time factor and load: the loop is closed at the odometry rate with no transport delay, and
// the run does not depend on scheduling. A timeout suspends the lockstep until the next command
// arrives (so a dead controller does not slow the clock to a crawl).
//
// Perception lockstep (sim time with lockstep, `perception_topic` set: simulation.launch sets the
// planner's ~mapping/depth_fused). The mapping announces every depth frame that reached its map
// (std_msgs/Header, the frame's stamp). Before the clock moves on past the last frame fused by more
// than perception_max_lag_s of simulated time, the simulator waits for the next one (at most
// perception_timeout_s of wall time), so the camera, the mapping and the planner's depth freshness
// keep up with the clock at any load (sanitizers, a loaded machine). Not before the first frame, nor
// while a depth blackout fault runs; a timeout suspends it until the next frame arrives (a dead
// planner or camera does not slow the clock to a crawl).
//
// Planner lockstep (the same, `planner_topic` set: simulation.launch sets the planner's ~tick_done).
// The planner announces every planning tick it finished (std_msgs/Header, the tick's time); the
// clock leads the last one by at most planner_max_lag_s (two ticks), so a plan that takes long in
// wall time (a sanitizer's slowdown) does not come late in simulated time. Same timeout and suspension.
//
// Setpoint lockstep (the same, `setpoint_topic` set: simulation.launch sets the trajectory server's
// topo_planner/PositionCommand stream). The clock leads the newest setpoint by at most
// setpoint_max_lag_s (two 100 Hz periods), so the controller never tracks a setpoint that the clock
// has left behind: without it, a trajectory server starved of CPU for a moment (the planner's
// threads and the mapping on a 2-core machine) left the controller holding a setpoint up to 0.19 s of
// simulated time old, 0.5 m behind a vehicle at 2.7 m/s, and then jumping forward. Same timeout and
// suspension (a stopped server does not slow the clock to a crawl).
//
// Commands. Before the first command the rotors hold hover speed (the vehicle hangs still at the
// start). A command is held (zero-order hold) until the next one; when none arrives for
// command_timeout_s of simulated time, the failsafe takes over: `hold` (default) emulates a flight
// controller's position hold (an internal geometric controller keeps the position and heading of
// the moment the commands stopped) until commands resume; `cut` drops the rotors to their minimum
// speed (the vehicle falls; the crash shows up as a collision). NaN, infinite or negative rotor
// speeds are refused (throttled warning) and the previous command stays. So is a stale command: one
// that answers odometry more than max_command_age_s older than the newest the controller could
// answer (a controller that lags the clock: a loaded machine on the wall clock, a lockstep wait that
// timed out). The rotor-level loop closed over ROS diverges on a state 30 ms old (its attitude gains;
// stable at 20 ms): a vehicle at 0.9 m/s reached 2 m/s at 30 ms and 16 m/s at 50 ms, where a flight
// controller's own loop would never run late. Refused, it counts as silence, and the failsafe holds
// the vehicle until fresh commands come back (a flight controller's offboard-loss failsafe).
//
// Faults (uav_sim/fault_schedule.h; faults/* parameters, none by default), at simulated times t =
// seconds since the clock started (the physics clock, not moved by clock steps), or, with
// faults/start_on_speed_mps > 0, since the vehicle's true speed first exceeded that (so that a
// schedule lands at the same point of a flight however long the start-up took):
//   depth blackout [t0, t1)     ~depth_blackout is true: the depth camera sends no image.
//   odometry blackout [t0, t1)  no odometry and no tf are published (the physics goes on, ~ground_truth
//                               too). The controller runs on odometry, so its commands stop as well and
//                               after command_timeout_s the failsafe above holds the vehicle, as a real
//                               flight controller without its state estimate would. Delayed odometry
//                               due inside the window is dropped.
//   odometry jump at t by d     from t on, d is added to the published position and tf (jumps add
//                               up: a VIO relocalisation). Velocity and attitude are untouched.
//   clock step at t by s        /clock and every stamp jump by s seconds (sim time only); the physics
//                               and the lockstep go on (the lockstep forgets the answers stamped before).
// Each change is published on ~fault_event and logged (ROS_WARN).
//
// Collisions. The body is a sphere of collision_radius_m. A contact is the sphere overlapping an
// occupied voxel cube (exact: TruthMap::obstacleDistance, an ESDF lower bound as broad phase and
// point-to-cube distances within the radius as narrow phase) or the ground plane (centre below
// ground_z_m + radius), checked every step. Entering contact counts one collision; the contact ends
// when the clearance is back above the radius by collision_release_m (ContactCounter: a vehicle resting
// at a surface is one collision, leaving and re-entering counts again); each is published with the running count and logged (ROS_WARN). The
// vehicle passes through obstacles, but not the ground: its centre stops at ground_z_m and a
// downward velocity is cancelled (it lies there, in contact, until the rotors lift it).
//
// Parameters (private; defaults are the Config defaults below)
//   /sim/start_m, /sim/goals_m, /sim/map_resolution_m   the scenario (uav_sim/ros/truth_map.h)
//   start_yaw_rad 0, step_s 0.001, odom_rate_hz 200, publish_clock (/use_sim_time), clock_start_s 1,
//   realtime_factor 1, max_lag_s 0.05, lockstep true, lockstep_timeout_s 0.05, command_timeout_s 0.1,
//   max_command_age_s 0.025, failsafe hold|cut, collision_radius_m 0.15,
//   collision_release_m 0.05, ground_z_m 0, odom_noise/position_m 0,
//   odom_noise/velocity_mps 0, odom_noise/seed 1, odom_delay_s 0, world_frame world, body_frame
//   base_link, camera_frame camera_optical, camera_extrinsic/translation_m [0 0 0],
//   camera_extrinsic/quaternion_xyzw [-0.5 0.5 -0.5 0.5], truth_map_margin_m 1.5, map_wait_s 30,
//   status_period_s 10, vehicle/* (Quadrotor::Config, see config/vehicle.yaml),
//   faults/depth_blackouts_s [] ([t0, t1, ...] windows), faults/odom_blackouts_s [] (windows),
//   faults/odom_jumps [] ([t, dx, dy, dz, ...] [s, m]), faults/clock_steps [] ([t, step_s, ...] [s]),
//   faults/start_on_speed_mps 0 (0: fault times from the clock start; > 0: from the first moment the
//   true speed exceeds this) [m/s].
// config/quadrotor.yaml documents each. Invalid parameters stop the node with a ROS_ERROR.

#include <nav_msgs/Odometry.h>
#include <ros/callback_queue.h>
#include <ros/ros.h>
#include <std_msgs/Header.h>
#include <tf2_ros/static_transform_broadcaster.h>
#include <tf2_ros/transform_broadcaster.h>
#include <topo_planner/RotorCommand.h>

#include <atomic>
#include <chrono>
#include <condition_variable>
#include <deque>
#include <memory>
#include <mutex>
#include <random>
#include <string>
#include <thread>

#include "topo_planner/uav_sim/fault_schedule.h"
#include "topo_planner/uav_sim/geometric_controller.h"
#include "topo_planner/uav_sim/quadrotor.h"
#include "topo_planner/uav_sim/ros/truth_map.h"

namespace topo_planner {

class QuadrotorSim {
 public:
  EIGEN_MAKE_ALIGNED_OPERATOR_NEW

  enum class Failsafe { kHold, kCut };

  struct Config {
    Quadrotor::Config vehicle;            ///< the simulated airframe (vehicle/*)
    SimScenario scenario;                 ///< start, goals, map resolution (/sim/*)
    double start_yaw_rad = 0.0;           ///< initial heading [rad]
    double step_s = 0.001;                ///< integration step (RK4) [s]
    double odom_rate_hz = 200.0;          ///< odometry and tf rate; step_s * odom_rate_hz must divide 1 [Hz]
    bool publish_clock = false;           ///< own the clock (/clock); default: the value of /use_sim_time
    double clock_start_s = 1.0;           ///< first /clock value (> 0: ros::Time 0 means "no time yet") [s]
    double realtime_factor = 1.0;         ///< simulated seconds per wall second, with publish_clock
    double max_lag_s = 0.05;              ///< wall time the loop may catch up after falling behind [s]
    bool lockstep = true;                 ///< with publish_clock: wait for the controller's answer to each odometry
    double lockstep_timeout_s = 0.05;     ///< longest wait for that answer (wall) [s]
    std::string perception_topic;         ///< depth frames fused (std_msgs/Header); empty: no perception lockstep
    double perception_max_lag_s = 0.2;    ///< the clock leads the last frame fused by at most this [s]
    double perception_timeout_s = 2.0;    ///< longest wait for the next frame fused, planning tick or setpoint (wall) [s]
    std::string planner_topic;            ///< planning ticks finished (std_msgs/Header); empty: no planner lockstep
    double planner_max_lag_s = 0.1;       ///< the clock leads the last planning tick by at most this [s]
    std::string setpoint_topic;           ///< the setpoints (topo_planner/PositionCommand); empty: no setpoint lockstep
    double setpoint_max_lag_s = 0.02;     ///< the clock leads the newest setpoint by at most this [s]
    double command_timeout_s = 0.1;       ///< simulated time without commands before the failsafe [s]
    double max_command_age_s = 0.025;     ///< a command answering odometry older than this is stale [s]
    Failsafe failsafe = Failsafe::kHold;  ///< what the vehicle does then
    double collision_radius_m = 0.15;     ///< body sphere radius [m]
    double collision_release_m = 0.05;    ///< a contact ends at a clearance of radius + this [m]
    double ground_z_m = 0.0;              ///< height of the ground plane [m]
    double position_noise_m = 0.0;        ///< odometry position noise sigma per axis [m]
    double velocity_noise_mps = 0.0;      ///< odometry velocity noise sigma per axis [m/s]
    /// Odometry position drift: a random walk of this sigma per axis per square-root second (a VIO's
    /// slow error; the depth camera, rendering from the true pose, then maps with it) [m/sqrt(s)].
    double position_drift_m_per_sqrt_s = 0.0;
    uint32_t noise_seed = 1;              ///< odometry noise seed
    double odom_delay_s = 0.0;            ///< odometry published this long after its stamp (rounded to steps) [s]
    std::string world_frame = "world";            ///< frame of odometry, tf and collisions
    std::string body_frame = "base_link";         ///< child frame of the odometry
    std::string camera_frame = "camera_optical";  ///< static tf child of body_frame
    Eigen::Isometry3d T_body_camera = defaultBodyToCamera();  ///< static tf body -> camera optical frame
    double truth_map_margin_m = 1.5;  ///< free margin of the true map's window (uav_sim/truth_map.h) [m]
    double map_wait_s = 30.0;         ///< with publish_clock: hold the clock until the true map arrives (wall) [s]
    double status_period_s = 10.0;    ///< period of the status line (wall) [s]
    FaultSchedule faults;             ///< faults injected at set simulated times (none by default)
    double faults_start_on_speed_mps = 0.0;  ///< > 0: fault times count from the first moment faster than this [m/s]

    /// Camera looking along body +x (optical z = body x, x = -body y, y = -body z).
    static Eigen::Isometry3d defaultBodyToCamera();
    bool validate(std::string* why) const;
  };

  /// Counters, for the status line and tests.
  struct Stats {
    uint64_t steps = 0;
    uint32_t collisions = 0;
    uint64_t commands = 0;      ///< rotor commands accepted
    uint64_t bad_commands = 0;  ///< refused (NaN/inf/negative)
    uint64_t stale_commands = 0;  ///< refused: computed on odometry older than max_command_age_s
    uint64_t lockstep_waits = 0;     ///< odometry messages the clock waited to be answered for
    uint64_t lockstep_timeouts = 0;  ///< ... in vain
    uint64_t perception_waits = 0;     ///< times the clock waited for the mapping
    uint64_t perception_timeouts = 0;  ///< ... in vain
    uint64_t planner_waits = 0;        ///< times the clock waited for the planner
    uint64_t planner_timeouts = 0;     ///< ... in vain
    uint64_t setpoint_waits = 0;       ///< times the clock waited for the trajectory server's setpoints
    uint64_t setpoint_timeouts = 0;    ///< ... in vain
    uint64_t failsafe_events = 0;
    uint64_t lag_events = 0;  ///< backlogs dropped
    uint64_t fault_events = 0;      ///< fault changes applied (starts, ends, jumps, steps)
    uint64_t odom_dropped = 0;      ///< odometry messages not published (odometry blackout)
  };

  /// Starts the simulation loop thread. `nh` resolves the topics, `pnh` is the private handle.
  static std::unique_ptr<QuadrotorSim> create(const ros::NodeHandle& nh, const ros::NodeHandle& pnh,
                                              const Config& config, std::string* error);
  ~QuadrotorSim();

  Stats stats() const;

 private:
  QuadrotorSim(const ros::NodeHandle& nh, const ros::NodeHandle& pnh, const Config& config);
  void commandCallback(const topo_planner::RotorCommandConstPtr& msg);
  void loop();
  bool waitForMap();
  /// One RK4 step under the current command, then the ground and collision checks.
  void step(const std::shared_ptr<const TruthMap>& map);
  void checkCollision(const std::shared_ptr<const TruthMap>& map);
  /// Queues the odometry of the current state and publishes what is due, and the flight controller's
  /// undelayed estimate (fc_odom) when subscribed; returns the stamp the controller answers: the
  /// estimate's when published, else the newest odometry's (zero if none).
  ros::Time publishOdometry();
  void waitForReply(const ros::Time& odom_stamp);
  /// A report of the mapping (kMapping), the planner (kPlanner) or the trajectory server (kSetpoints, its
  /// setpoints' stamps): caught up with `stamp`.
  enum Source { kMapping = 0, kPlanner = 1, kSetpoints = 2, kNumSources = 3 };
  void reportCallback(Source source, const ros::Time& stamp);
  /// The perception, planner and setpoint locksteps: waits for each armed source to report within its lag.
  void waitForPerception(const ros::Time& clock);
  void publishClock();
  /// Applies the faults whose changes fall in (t0_s, t1_s] of simulated time (loop thread).
  void applyFaults(double t0_s, double t1_s);
  ros::Time stampOf(uint64_t step) const;
  void logStatus(double wall_s, uint64_t steps_in_period);

  ros::NodeHandle nh_, pnh_;
  Config config_;
  Quadrotor quad_;
  GeometricController failsafe_controller_;
  int64_t step_ns_ = 1000000;
  int steps_per_odom_ = 5;
  uint64_t delay_steps_ = 0;

  // Loop state (loop thread only).
  uint64_t step_ = 0;
  ros::Time anchor_stamp_;  // stamp of step anchor_step_
  uint64_t anchor_step_ = 0;
  ContactCounter contact_;
  bool in_failsafe_ = false;
  TrackingReference failsafe_reference_;
  std::mt19937 noise_rng_;
  Eigen::Vector3d drift_ = Eigen::Vector3d::Zero();  // the odometry's position drift so far [m]
  struct Pending {
    uint64_t release_step;
    nav_msgs::Odometry msg;
  };
  std::deque<Pending> pending_;
  Eigen::Vector3d odom_offset_ = Eigen::Vector3d::Zero();  // odometry jumps so far [m]
  bool odom_blackout_ = false;                              // inside an odometry blackout
  int64_t fault_origin_step_ = -1;  // step the fault schedule counts from (-1: not yet)

  // Command state, written by the command callback (own queue and spinner thread), read by the loop.
  mutable std::mutex command_mutex_;
  std::condition_variable command_cv_;
  bool have_command_ = false;
  Eigen::Vector4d command_ = Eigen::Vector4d::Zero();
  ros::Time command_answers_;  // odometry stamp the latest command answers
  ros::Time newest_published_;  // stamp of the newest odometry published
  uint64_t command_step_ = 0;  // step at which it arrived
  bool lockstep_suspended_ = false;
  std::atomic<uint64_t> current_step_{0};

  // Perception, planner and setpoint lockstep state, written by the report callbacks (the command queue's thread).
  std::mutex perception_mutex_;
  std::condition_variable perception_cv_;
  ros::Time reported_[kNumSources];  // stamp of the last report per Source (zero: none yet)
  bool suspended_[kNumSources] = {false, false, false};
  bool depth_blackout_ = false;      // inside a depth blackout fault (the loop's thread)

  mutable std::mutex stats_mutex_;
  Stats stats_;

  std::unique_ptr<TruthMapSubscriber> truth_;
  ros::CallbackQueue command_queue_;
  std::unique_ptr<ros::AsyncSpinner> command_spinner_;
  ros::Subscriber command_sub_, fused_sub_, planner_sub_, setpoint_sub_;
  ros::Publisher odom_pub_, truth_pub_, fc_odom_pub_, collision_pub_, clock_pub_;
  ros::Publisher depth_blackout_pub_, odom_offset_pub_, fault_event_pub_, status_pub_;
  tf2_ros::TransformBroadcaster tf_broadcaster_;
  tf2_ros::StaticTransformBroadcaster static_broadcaster_;
  std::atomic<bool> stop_{false};
  std::thread thread_;
};

/// Reads the parameters into *config (defaults: the values already there); false with a ROS_ERROR
/// when any is invalid.
bool readQuadrotorSimParams(const ros::NodeHandle& pnh, QuadrotorSim::Config* config);

}  // namespace topo_planner
