#pragma once
// A closed-loop flight without ROS, in simulated time: the planner's FSM (ReplanFsm) on a map fused
// from a simulated depth camera (uav_sim DepthCamera rendering the true map; plan_env OccupancyMap
// and EsdfMap, as the mapping node fuses), the trajectory server's core (SetpointGenerator: setpoints,
// yaw, its stops), and a vehicle that is where its setpoint says, level, turned to the setpoint's yaw.
// The flight is measured as the flight monitor measures one: goals reached at rest, contacts with the
// true map, clearance, speeds, the speed account and the oracle.
//
// What it leaves out of the ROS loop: message latency, the controller's tracking error and the
// vehicle's tilt, odometry noise. What it keeps: the planner's configuration (config/planner.yaml
// through planner_params.h), the camera's field of view, range and yaw (where it looks decides what
// the known-space commitment lets the vehicle fly), the mapping's rules, the FSM's timing (ticks,
// take-over delays, retries) and the server's stops. Every planning budget is a count and time is
// simulated, so a flight is deterministic and takes seconds: the bench of the speed work
// (make bench-speed-core) and the closed-loop speed tests of make test.
//
// Threads: none of its own (the replanner's pool and the ESDF's workers are the only ones).

#include <Eigen/Geometry>
#include <functional>
#include <string>
#include <vector>

#include "topo_planner/plan_env/esdf_map.h"
#include "topo_planner/plan_env/occupancy_map.h"
#include "topo_planner/plan_manage/flight_oracle.h"
#include "topo_planner/plan_manage/speed_account.h"
#include "topo_planner/topo_replan/replan_fsm.h"
#include "topo_planner/topo_replan/setpoint_generator.h"
#include "topo_planner/uav_sim/depth_camera.h"
#include "topo_planner/uav_sim/truth_map.h"

namespace topo_planner {

class SimFlight {
 public:
  struct Config {
    ReplanFsm::Config fsm;             ///< the planner (readFsmParams on config/planner.yaml)
    SetpointGenerator::Config server;  ///< the trajectory server
    OccupancyMap::Config map;          ///< the planner's map window and fusion (config/mapping.yaml)
    EsdfMap::Config esdf;
    DepthCamera::Config camera;        ///< config/depth_camera.yaml (noise: realistic sensing)
    /// The camera's optical frame in the body frame (looking along body x).
    Eigen::Isometry3d T_body_camera = defaultBodyToCamera();
    double camera_rate_hz = 30.0;      ///< depth frames per second [Hz]
    double plan_period_s = 0.05;       ///< FSM tick and safety check [s]
    double server_period_s = 0.01;     ///< setpoints [s]
    double start_delay_s = 1.0;        ///< hover before the first goal (the camera sees ahead) [s]
    double goal_tolerance_m = 0.5;     ///< a goal is reached this close ... [m]
    double goal_max_speed_mps = 1.0;   ///< ... and this slow (the flight monitor's rule) [m/s]
    double goal_timeout_s = 90.0;      ///< per goal [s]
    double collision_radius_m = 0.15;  ///< the body's radius: a contact below this clearance [m]
    double ground_z_m = 0.0;           ///< the ground counts as an obstacle [m]
    SpeedAccount::Config speed;        ///< the flight's limits (keep them the planner's)
    FlightOracle::Config oracle;       ///< idem, and the route's clearance and band
    bool compute_oracle = true;
    /// Called after every planning call (ReplanFsm::setPlanObserver): diagnostics, e.g. saving problems.
    ReplanFsm::PlanObserver plan_observer;

    static Eigen::Isometry3d defaultBodyToCamera();
    bool validate(std::string* why) const;
  };
  struct Goal {
    Eigen::Vector3d position = Eigen::Vector3d::Zero();
    bool reached = false;
    double time_s = 0.0;         ///< from when it was given to when it was reached (or the flight ended) [s]
    double oracle_time_s = NAN;  ///< [s]
  };
  struct Result {
    bool ok = false;              ///< every goal reached, no contact
    std::string message;          ///< why not, or the summary
    std::vector<Goal> goals;
    int goals_reached = 0;
    int collisions = 0;           ///< contacts of the body with the true map (ContactCounter)
    double min_clearance_m = INFINITY;
    double duration_s = 0.0;      ///< first goal given to the end [s]
    double path_length_m = 0.0;
    double mean_speed_mps = 0.0;
    double max_speed_mps = 0.0;
    SpeedAccount::Totals speed;   ///< the speed account over the flight
    double fast_share = 0.0;
    double oracle_time_s = NAN;   ///< for the goals reached [s]
    double reached_time_s = NAN;  ///< the flight's time for them [s]
    double time_ratio = NAN;      ///< reached_time_s / oracle_time_s
    int replans = 0;              ///< planning calls that published
    int replan_failures = 0;      ///< and that did not
    std::vector<double> replan_ms;  ///< wall time of every planning call [ms]: the FSM's tick that made it
    std::vector<double> planner_ms;  ///< the replanner's part of it (ReplanStats::total_ms) [ms]
    std::vector<FsmEvent> slow_calls;  ///< the planning calls whose tick took 5 ms or more (the tail)
    int emergency_stops = 0;      ///< braking trajectories published
    int max_decel_events = 0;     ///< setpoints decelerating harder than the planning limit + 0.5 m/s^2
    double max_setpoint_step_m = 0.0;  ///< largest position step between setpoints beyond |v| dt [m]
  };
  /// One step of the loop, for traces: the time, the setpoint flown and what the FSM said.
  struct Step {
    double t_s = 0.0;
    Setpoint setpoint;
    double clearance_m = NAN;
    const FsmOutput* output = nullptr;  ///< non-null at the ticks that produced something
    const ExecTrajectory* published = nullptr;  ///< a trajectory published at this step
  };
  using Observer = std::function<void(const Step&)>;

  /// Flies `goals` in turn (each a mission of its own, reached at rest) from `start` at rest over
  /// `truth`. Returns ok = false with the reason for an invalid config too.
  static Result fly(const TruthMap& truth, const Eigen::Vector3d& start, const std::vector<Eigen::Vector3d>& goals,
                    const Config& config, const Observer& observer = {});
};

/// The configuration the nodes fly: config_dir's planner.yaml (readFsmParams), mapping.yaml,
/// depth_camera.yaml and traj_server.yaml, at the flight's limits (the launch files' max_vel and
/// max_acc), with realistic sensing's depth noise and holes when asked; every planning budget a
/// count (deterministic). The map window is config/mapping.yaml's; set the flight's. False with the
/// reason when a file cannot be read or a value is out of range.
bool loadSimFlightConfig(const std::string& config_dir, double max_vel_mps, double max_acc_mps2, bool realistic,
                         SimFlight::Config* config, std::string* why,
                         const std::vector<std::pair<std::string, std::string>>& planner_overrides = {});

/// "goals 3/3, collisions 0, min clearance 0.45 m, 20.1 s (oracle 13.2 s, 1.52x), mean 1.9 m/s, ..."
std::string formatSimFlight(const SimFlight::Result& result);

}  // namespace topo_planner
