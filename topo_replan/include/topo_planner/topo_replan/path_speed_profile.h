#pragma once
// The fastest a vehicle can fly along a path within a speed limit and an acceleration limit on the
// norm: a time-optimal path parametrisation (Bobrow; Verscheure et al.) of a smoothed polyline.
//
// Path. Each inner corner of the polyline is replaced by a circular arc tangent to both legs; the
// arc takes at most max_corner_fraction of each leg next to it (two corners share a leg), so its
// radius is as large as the legs allow: r = T / tan(theta / 2) for a turn by theta with tangent
// length T. The arc is flown instead of the corner: an optimistic path (it cuts the corner by
// r (1 / cos(theta / 2) - 1)), as a bound should be.
//
// Speed. Sampled every step_m of arc length, the speed is limited by max_vel and, on an arc of
// curvature k, by sqrt(max_acc / k) (all the acceleration turning). A forward pass accelerates from
// the start speed with the tangential acceleration left over, sqrt(max_acc^2 - (v^2 k)^2), and a
// backward pass brakes the same way into the end speed: the speed at every sample is the largest
// both passes allow, which is the time-optimal profile of a point mass under these limits (no jerk
// limit). The time between samples is the step over the mean of their speeds.
//
// Uses: the flight monitor's oracle (the time an ideal vehicle that knows the map needs for a leg)
// and the reference's time allocation (segment times from the time the profile spends on each).
// No ROS, no threads, no state between calls.

#include <Eigen/Core>
#include <optional>
#include <string>
#include <vector>

namespace topo_planner {

class PathSpeedProfile {
 public:
  struct Config {
    double max_vel_mps = 3.0;           ///< speed limit [m/s]
    double max_acc_mps2 = 2.5;          ///< limit on the norm of the acceleration [m/s^2]
    double step_m = 0.02;               ///< arc-length step of the passes [m]
    double max_corner_fraction = 0.5;   ///< a corner's arc takes at most this fraction of each leg, in (0, 0.5]
    double min_speed_mps = 0.05;        ///< speeds are floored here (a reversal would otherwise take forever) [m/s]
    size_t max_samples = 2000000;       ///< refuse longer paths (memory) [samples]

    bool validate(std::string* why) const;
  };

  /// The profile along `waypoints` (at least two distinct points) from speed v_start to v_end
  /// (clamped to the limits; 0: rest to rest). nullopt with the reason in *why for an invalid
  /// config, non-finite or too few points, or a path longer than max_samples steps.
  static std::optional<PathSpeedProfile> compute(const std::vector<Eigen::Vector3d>& waypoints, const Config& config,
                                                 double v_start = 0.0, double v_end = 0.0, std::string* why = nullptr);

  double duration() const { return time_.back(); }   ///< [s]
  double length() const { return s_.back(); }        ///< of the smoothed path [m]
  double maxSpeed() const;                            ///< [m/s]
  /// Time at which the profile passes each waypoint (the middle of its corner's arc; the first is
  /// 0, the last the duration), one per distinct waypoint given [s].
  const std::vector<double>& waypointTimes() const { return waypoint_times_; }
  /// Speed at arc length s (linear between samples; clamped to [0, length]) [m/s].
  double speedAt(double s) const;
  /// Arc length reached at time t (clamped to [0, duration]) [m].
  double distanceAt(double t) const;
  /// The samples' arc lengths [m] (the passes' grid: the speed is exact there).
  const std::vector<double>& sampleDistances() const { return s_; }
  /// Time at which arc length s is reached (clamped to [0, length]) [s].
  double timeAtDistance(double s) const;

 private:
  PathSpeedProfile() = default;
  std::vector<double> s_;     // arc length of each sample [m]
  std::vector<double> v_;     // speed there [m/s]
  std::vector<double> time_;  // time there [s]
  std::vector<double> waypoint_times_;
};

}  // namespace topo_planner
