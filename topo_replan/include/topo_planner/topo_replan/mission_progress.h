#pragma once
// How far the vehicle has come along its mission, to tell a stall from a slow flight.
//
// A mission can stall with every plan succeeding: the vehicle hovers at the edge of what it has
// seen, creeps, or shuttles between two places while each plan is short and safe. Counting failed
// plans does not see that; the distance left does. MissionProgress measures the distance left
// along the mission's way (the global route, or the straight legs through the goals not reached),
// from the vehicle's projection onto it, and remembers when that distance last shrank by at least
// min_gain_m. The projection only moves along the way near where it was (a window of arc length),
// so a way that doubles back (around a wall, to a window far aside) is not short-cut through the
// wall, and the measure is the way's length still to fly plus the vehicle's distance from it.
//
// A new way (a re-route, a rebuilt reference) re-bases the measure, keeping the time of the last
// gain: the clock of a stall runs across re-routes, since a re-route is one of the remedies whose
// effect it judges. No ROS, no threads: the FSM calls it under its mutex.

#include <Eigen/Core>
#include <cmath>
#include <vector>

#include "topo_planner/path_searching/path.h"

namespace topo_planner {

class MissionProgress {
 public:
  struct Config {
    double min_gain_m = 0.5;         ///< the distance left must shrink by this to count as progress [m]
    double window_back_m = 1.0;      ///< the projection may move back along the way this far per update [m] ...
    double window_ahead_m = 4.0;     ///< ... and forward this far [m]
  };

  MissionProgress() = default;
  explicit MissionProgress(const Config& config) : config_(config) {}

  /// A new mission (or a new way for it) at time t, with the vehicle at p. `way` is the polyline
  /// to fly (at least one point: the last goal); a first point away from p is fine. keep_clock:
  /// the same mission on a new way (re-based; the time of the last gain kept); false: a new mission
  /// (the clock restarts at t).
  void reset(const Path& way, double t, const Eigen::Vector3d& p, bool keep_clock);
  /// No mission: update() does nothing until the next reset().
  void clear() { way_.clear(); }
  bool active() const { return !way_.empty(); }

  /// The vehicle at p at time t: the distance left [m] (NaN when not active or p not finite).
  double update(double t, const Eigen::Vector3d& p);

  /// The point of the way d metres on from the vehicle's projection (its end when shorter); where
  /// the vehicle was heading. Zero when not active.
  Eigen::Vector3d ahead(double d) const;
  double remaining() const { return remaining_; }  ///< at the last update [m]
  double best() const { return best_; }            ///< smallest distance left since the last gain or re-base [m]
  double lastGain() const { return last_gain_s_; } ///< time of the last gain (or the mission's start) [s]
  double sinceGain(double t) const { return active() ? t - last_gain_s_ : 0.0; }
  /// Moves the time of the last gain by dt: a time jump of the clock, or a pause that is no stall
  /// (the inputs were stale: nothing was planned).
  void shift(double dt) {
    if (std::isfinite(dt)) last_gain_s_ += dt;
  }

 private:
  /// Projection of p on the way with arc length in [lo, hi]: (arc length, distance left).
  void project(const Eigen::Vector3d& p, double lo, double hi, double* s, double* left) const;

  Config config_;
  Path way_;
  std::vector<double> arc_;  // arc length at each point of way_
  double s_ = 0.0;           // arc length of the last projection
  double remaining_ = NAN;
  double best_ = INFINITY;
  double last_gain_s_ = 0.0;
};

}  // namespace topo_planner
