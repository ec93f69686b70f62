#pragma once
// The trajectory server's core: turns the planner's B-spline trajectories into tracking setpoints
// (position, velocity, acceleration, jerk, yaw, yaw rate) at the command rate. A new trajectory
// takes over at its start time (the planner starts it from the state of the current one at that
// time, so the setpoints are continuous); after the last one ends, the end point is held at rest.
//
// Yaw policy: the heading points along the direction of travel over the next lookahead_s
// (the displacement p(t + lookahead) - p(t), so the camera turns towards the path before the
// vehicle speeds up), held when that displacement is shorter than min_displacement_m, and reached
// with a yaw rate limited to max_yaw_rate_radps.

#include <cstdint>
#include <deque>

#include "bspline_opt/uniform_bspline.h"
#include "topo_replan/polynomial_trajectory.h"

namespace topo_planner {

struct Setpoint {
  FlatState state;
  double yaw = 0.0;       ///< [rad]
  double yaw_rate = 0.0;  ///< [rad/s]
  int64_t trajectory_id = -1;
  bool holding = false;   ///< past the end of the last trajectory (holding its end point)
};

class SetpointGenerator {
 public:
  struct Config {
    double max_yaw_rate_radps = 1.5;   ///< yaw rate limit [rad/s]
    double lookahead_s = 1.0;          ///< heading from the displacement over this time ahead [s]
    double min_displacement_m = 0.3;   ///< shorter look-ahead displacements keep the heading [m]
    int max_queued = 4;                ///< trajectories waiting for their start time, at most

    bool validate(std::string* why) const;
  };

  explicit SetpointGenerator(const Config& config) : config_(config) {}
  const Config& config() const { return config_; }

  /// Queues a trajectory starting at start_time_s; refused (false) when the spline is invalid, the
  /// time not finite, or the id not newer than the last one. A trajectory replaces every queued
  /// one that starts at or after it.
  bool add(int64_t id, double start_time_s, const UniformBspline& spline);
  /// Initial heading, used until the first trajectory gives one (e.g. the vehicle's yaw).
  void setYaw(double yaw);
  bool hasTrajectory() const { return active_ || !queue_.empty(); }

  /// The setpoint at time t (non-decreasing across calls); false before the first trajectory starts.
  bool sample(double t, Setpoint* out);

 private:
  struct Entry {
    int64_t id;
    double start;
    UniformBspline pos, vel, acc, jerk;
  };

  Config config_;
  std::deque<Entry> queue_;
  bool active_ = false;
  Entry current_{};
  int64_t last_id_ = -1;
  double yaw_ = 0.0;
  double last_t_ = -1.0;
};

}  // namespace topo_planner
