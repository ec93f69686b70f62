#pragma once
// The trajectory server's core: turns the planner's B-spline trajectories into tracking setpoints
// (position, velocity, acceleration, jerk, yaw, yaw rate) at the command rate, and owns the
// trajectory server's failure behaviour (issue 11, items 3 and 4):
//
// - Take-over: a new trajectory takes over at its start time (the planner starts it from the state
//   of the current one at that time, so the setpoints are continuous).
// - Ordering: trajectory ids increase within one planner session; a trajectory of another session
//   (a restarted planner, whose ids start again at 0) is accepted whatever its id.
// - Continuity: a trajectory whose start state differs from the state commanded at its start time
//   (on the trajectory, stop or hold the setpoints come from; what the planner plans from) by more
//   than max_takeover_gap_m in position or max_takeover_velocity_gap_mps in velocity is refused at
//   its take-over (counted; the setpoint goes on as before): the planner planned from a state the
//   vehicle is not commanded to be in (it missed a watchdog stop, or a restarted planner started
//   from odometry). Judged at the start time, a trajectory that arrives late (an emergency brake
//   starting "now" at the planner) is not refused for the velocity it has changed since; but when
//   setpoints past its start went out before it arrived, its position at the last of them is judged
//   too (the step the vehicle would see; a stall of the sampling is no such delay). One that starts
//   before the current trajectory took over is judged on the source that one replaced. A refusal while moving
//   starts the smooth stop along the current path at once (the planner replaced that trajectory, so
//   it is no longer checked; the planner then plans from the hold). The planner learns the commanded
//   setpoint from the published position command (mode, trajectory id, planner session) and plans
//   again from it. A re-anchoring trajectory (the planner holds at the measured position after an
//   odometry jump) is exempt: its step is deliberate.
// - Watchdog: when neither a planner heartbeat (noteHeartbeat) nor a trajectory (add) came for
//   heartbeat_timeout_s while the setpoint moves faster than moving_speed_mps, the vehicle stops
//   smoothly along the current trajectory's path (the path the planner checked), then holds; queued
//   trajectories of the silent planner are dropped. Exception: when the current trajectory itself
//   comes to rest no later than that stop would, it is followed to its end (it is a stop already,
//   possibly a harder braking one). A trajectory added afterwards takes over normally.
// - End stop: a trajectory that ends moving is continued by the same smooth stop (straight on along
//   its last direction) instead of a hold at its end point (a velocity step).
// - Smooth stop: a jerk-limited S-curve of the speed along the path: the tangential acceleration
//   ramps at stop_jerk_mps3 from its current value to -A, A = max(stop_acc_mps2, the current
//   deceleration) (a harder braking is never softened), stays there and ramps back to 0 as the
//   speed reaches 0. Position, velocity and acceleration are continuous at the switch; past the
//   end of the path the stop goes on straight along its last direction.
// - Time jumps: ROS time going backwards, or forward by more than max_time_step_s between two
//   samples (a companion computer without RTC, NTP, a looping bag), shifts every stored time (the
//   active and queued trajectories, the stop, the last input) by the jump minus nominal_period_s, so
//   the setpoint goes on from where it was. Trajectories added afterwards are in the new time base.
// - Yaw: the heading points along the direction of travel over the next lookahead_s (the
//   displacement p(t + lookahead) - p(t), so the camera turns towards the path before the vehicle
//   speeds up). When that displacement is shorter than min_displacement_m (at rest, stopping,
//   holding) it points at the trajectory's heading target, if there is one farther than
//   min_displacement_m horizontally (a vehicle stopped at the edge of the known space looks where
//   it plans to go), and is held otherwise. The yaw rate is limited to max_yaw_rate_radps.
// - Hold before the first trajectory (optional, for PX4 OFFBOARD, which needs a setpoint stream
//   before it can be switched on): the last vehicle pose given by setVehiclePose, at rest.
//
// Times are the caller's clock (ROS time) in seconds; nothing here reads a clock. Not thread-safe:
// the trajectory server calls it under one mutex.

#include <Eigen/Core>
#include <cstdint>
#include <deque>
#include <optional>
#include <string>
#include <vector>

#include "topo_planner/bspline_opt/uniform_bspline.h"
#include "topo_planner/topo_replan/polynomial_trajectory.h"

namespace topo_planner {

struct Setpoint {
  enum class Mode {
    kHoldBeforeFirst,  ///< before the first trajectory: holding the vehicle's pose
    kTrajectory,       ///< on a trajectory
    kEndStop,          ///< stopping after the end of a trajectory that ended moving
    kWatchdogStop,     ///< stopping: no heartbeat or trajectory for heartbeat_timeout_s
    kHold,             ///< at rest after a trajectory or a stop
  };
  FlatState state;
  double yaw = 0.0;       ///< [rad]
  double yaw_rate = 0.0;  ///< [rad/s]
  int64_t trajectory_id = -1;  ///< the trajectory it comes from (the last one when stopping or holding)
  uint64_t planner_session = 0;  ///< that trajectory's planner session
  Mode mode = Mode::kTrajectory;
  bool moving() const { return mode == Mode::kTrajectory || mode == Mode::kEndStop || mode == Mode::kWatchdogStop; }
};
const char* toString(Setpoint::Mode mode);

class SetpointGenerator {
 public:
  struct Config {
    double max_yaw_rate_radps = 1.5;   ///< yaw rate limit [rad/s]
    double lookahead_s = 1.0;          ///< heading from the displacement over this time ahead [s]
    double min_displacement_m = 0.3;   ///< shorter look-ahead displacements keep the heading [m]
    int max_queued = 4;                ///< trajectories waiting for their start time, at most
    double heartbeat_timeout_s = 0.5;  ///< watchdog: stop without heartbeat or trajectory this long [s]
    double moving_speed_mps = 0.05;    ///< the watchdog acts above this setpoint speed [m/s]
    double stop_acc_mps2 = 2.5;        ///< deceleration of the watchdog and end stops [m/s^2]
    double stop_jerk_mps3 = 10.0;      ///< rate of change of that deceleration [m/s^3]
    /// A larger forward step of the time between samples is a jump [s]. Keep it equal to the planner's
    /// time_jump_threshold_s: a stall shorter than this is flown on in time by both (not shifted).
    double max_time_step_s = 1.0;
    double nominal_period_s = 0.01;    ///< the sampling period (1 / rate) assumed across a jump [s]
    bool hold_before_first_trajectory = false;  ///< sample() holds the vehicle pose before the first one
    double max_takeover_gap_m = 0.05;             ///< larger position steps at a take-over are refused [m]
    double max_takeover_velocity_gap_mps = 0.3;   ///< larger velocity steps at a take-over are refused [m/s]

    bool validate(std::string* why) const;
  };

  /// Counts since construction, for logs and tests.
  struct Stats {
    int64_t accepted = 0;               ///< trajectories accepted by add()
    int64_t refused = 0;                ///< refused (invalid, or an old id of the same session)
    int64_t session_changes = 0;        ///< accepted trajectories of a new planner session
    int64_t watchdog_stops = 0;
    int64_t end_stops = 0;
    int64_t backward_time_jumps = 0;
    int64_t forward_time_jumps = 0;
    int64_t dropped_on_watchdog = 0;    ///< queued trajectories dropped by a watchdog stop
    int64_t discontinuous_refused = 0;  ///< refused at their take-over: not continuous with the setpoint
    int64_t refusal_stops = 0;          ///< smooth stops started by such a refusal
    double last_takeover_gap_m = 0.0;   ///< position step of the last refused take-over [m]
    double last_takeover_velocity_gap_mps = 0.0;  ///< its velocity step [m/s]
    int64_t last_refused_id = -1;       ///< its trajectory id
    double last_time_jump_s = 0.0;      ///< the last jump (new time - expected time) [s]
    double last_input_age_s = 0.0;      ///< input age when the last watchdog stop began [s]
    double last_stop_speed_mps = 0.0;   ///< speed when the last stop began [m/s]
  };

  explicit SetpointGenerator(const Config& config) : config_(config) {}
  const Config& config() const { return config_; }
  const Stats& stats() const { return stats_; }

  /// Queues a trajectory of planner session `session` starting at start_time_s, with an optional
  /// heading target (world frame). Refused (false) when the spline is invalid or of degree < 3,
  /// the time or heading target not finite, or the id not newer than the last accepted one of the
  /// same session. A trajectory replaces every queued one that starts at or after it; one of a new
  /// session replaces every queued one. Counts as the planner's liveness (like a heartbeat at the
  /// next sample). It takes over at its start time from any mode (after a stop too).
  /// `reanchor`: the trajectory deliberately starts away from the current setpoint (exempt from the
  /// continuity check).
  bool add(uint64_t session, int64_t id, double start_time_s, const UniformBspline& spline,
           const std::optional<Eigen::Vector3d>& heading_target = std::nullopt, bool reanchor = false);
  /// The planner is alive at time t (its heartbeat's arrival, caller's clock).
  void noteHeartbeat(double t);
  /// Initial heading, used until the first trajectory gives one (e.g. the vehicle's yaw).
  void setYaw(double yaw);
  /// The vehicle's pose (odometry): the hold setpoint before the first trajectory (when
  /// hold_before_first_trajectory) and the initial heading. Ignored once a trajectory has started.
  void setVehiclePose(const Eigen::Vector3d& position, double yaw);
  bool hasTrajectory() const { return active_ || !queue_.empty(); }
  /// A trajectory has started (sample() has taken one over).
  bool started() const { return active_; }

  /// The setpoint at time t; false before the first trajectory starts (unless holding before it).
  /// t normally increases by about nominal_period_s per call; other steps are time jumps.
  bool sample(double t, Setpoint* out);

 private:
  struct Entry {
    uint64_t session = 0;
    int64_t id = -1;
    double start = 0.0;
    UniformBspline pos, vel, acc, jerk;
    std::optional<Eigen::Vector3d> heading_target;
    bool reanchor = false;
  };
  /// The jerk-limited stop: a speed profile along a path, from a start state.
  struct Stop {
    double t0 = 0.0;          ///< start [s, caller's clock]
    double tau0 = 0.0;        ///< trajectory time of the start on the path [s]
    // Speed profile along the path: phase 1 (jerk j1 for t1), phase 2 (acceleration -ap for t2),
    // phase 3 (jerk j3 for t3, acceleration back to 0 as the speed reaches 0).
    double v0 = 0.0, a0 = 0.0, j1 = 0.0, t1 = 0.0, ap = 0.0, t2 = 0.0, j3 = 0.0, t3 = 0.0;
    double length_m = 0.0;    ///< distance to rest [m]
    // The path: positions at arc lengths s_m (from the start), then straight on along end_dir.
    std::vector<double> s_m, tau_s;  ///< arc length and trajectory time of the samples
    Entry path;               ///< the trajectory whose path is followed (invalid pos: straight line only)
    Eigen::Vector3d start_pos = Eigen::Vector3d::Zero(), end_pos = Eigen::Vector3d::Zero();
    Eigen::Vector3d end_dir = Eigen::Vector3d::UnitX();
    bool follow_trajectory = false;  ///< the trajectory itself stops: follow it in time

    double duration() const { return t1 + t2 + t3; }
  };
  struct Profile1d {
    double s = 0.0, v = 0.0, a = 0.0, j = 0.0;
  };

  FlatState trajectoryState(const Entry& e, double tau) const;
  /// The state commanded at time t (<= now): by the current source (trajectory, stop or hold), or
  /// before the current trajectory's start by the one it replaced; false before the first trajectory
  /// unless a hold is streamed.
  bool commandedAt(double t, FlatState* state) const;
  /// The state of a stop at t (clamped to its duration).
  FlatState stopStateOf(const Stop& stop, double t) const;
  void startStop(double t0, const Entry& path, double tau0, const FlatState& state, Setpoint::Mode mode);
  static Profile1d evaluateProfile(const Stop& stop, double t);
  FlatState stopState(double t) const;
  void shiftTimes(double shift);
  double updateYaw(double dt, const Eigen::Vector3d& position, const Eigen::Vector3d& ahead, double* rate);

  Config config_;
  Stats stats_;
  std::deque<Entry> queue_;
  bool active_ = false;
  Entry current_{};
  // The source the current trajectory replaced (what was commanded before its start time): a take-over
  // that starts before it (a brake built on the trajectory the planner still flew) is judged on it.
  struct Before {
    bool valid = false;
    Setpoint::Mode mode = Setpoint::Mode::kTrajectory;  // kTrajectory, a stop, or kHold
    Entry trajectory;
    Stop stop;
    Eigen::Vector3d hold_position = Eigen::Vector3d::Zero();
  };
  Before before_;
  Setpoint::Mode mode_ = Setpoint::Mode::kTrajectory;
  Stop stop_;
  Eigen::Vector3d hold_position_ = Eigen::Vector3d::Zero();
  bool have_last_ = false;  // an accepted trajectory: last_session_, last_id_ are set
  uint64_t last_session_ = 0;
  int64_t last_id_ = -1;
  double yaw_ = 0.0;
  bool have_pose_ = false;
  Eigen::Vector3d vehicle_position_ = Eigen::Vector3d::Zero();
  bool sampled_ = false;  // last_t_ is set
  double last_t_ = 0.0;
  double hold_since_ = 0.0;       // when the hold began [s, caller's clock]
  bool hold_after_stop_ = false;  // the hold ends a stop (stop_ is its history)
  double last_input_t_ = -1e300;  // last heartbeat or trajectory [s, caller's clock]
  bool input_pending_ = false;    // a trajectory was added since the last sample
};

}  // namespace topo_planner
