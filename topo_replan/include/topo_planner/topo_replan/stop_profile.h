#pragma once
// Stops along a path: the geometry and the speed profile every stop of the planner uses (the FSM's
// braking trajectories, the known-space commitment's stop before unknown space). No state, no ROS.

#include <Eigen/Core>
#include <algorithm>
#include <cmath>
#include <vector>

#include "topo_planner/bspline_opt/uniform_bspline.h"

namespace topo_planner {

// A trajectory's path from time tau0 on, by arc length: where a stop along the path goes. Past the
// path's end it continues straight along the last direction (a stop longer than the path).
class PathByLength {
 public:
  PathByLength(const UniformBspline& spline, double tau0, double dt) {
    const double T = spline.duration();
    for (double tau = std::clamp(tau0, 0.0, T);; tau = std::min(T, tau + dt)) {
      const Eigen::Vector3d p = spline.evaluate(tau);
      s_.push_back(p_.empty() ? 0.0 : s_.back() + (p - p_.back()).norm());
      p_.push_back(p);
      if (tau >= T) break;
    }
    direction_ = spline.derivative().evaluate(T);
    for (size_t i = p_.size(); direction_.norm() < 1e-6 && i >= 2; --i) direction_ = p_[i - 1] - p_[i - 2];
    if (direction_.norm() > 1e-9) direction_.normalize();
  }
  void setDirection(const Eigen::Vector3d& d) {
    if (d.norm() > 1e-9) direction_ = d.normalized();
  }
  double length() const { return s_.back(); }
  Eigen::Vector3d at(double s) const {
    if (s >= s_.back()) return p_.back() + (s - s_.back()) * direction_;
    const size_t i = size_t(std::upper_bound(s_.begin(), s_.end(), s) - s_.begin());
    if (i == 0) return p_.front();
    const double span = s_[i] - s_[i - 1];
    const double f = span > 0.0 ? (s - s_[i - 1]) / span : 0.0;
    return p_[i - 1] + f * (p_[i] - p_[i - 1]);
  }

 private:
  std::vector<double> s_;
  std::vector<Eigen::Vector3d> p_;
  Eigen::Vector3d direction_ = Eigen::Vector3d::Zero();
};

// A stop from speed v along a path: the acceleration along it goes from its present value a0 to the
// deceleration a within kOnsetRamp seconds per a (a linear ramp), holds a, and eases back to 0 over
// the last kStopRamp seconds, so that the cubic spline fitted to it (which starts with the flown
// acceleration and ends with none) need not overshoot a anywhere. A stop that began at full
// deceleration however the vehicle accelerated (the earlier profile) made the fit ring: 4-5 m/s^2
// commanded for a 2.5 m/s^2 brake, 6-8 m/s^2 for a harder one. Integrated numerically (2 ms steps).
class StopProfile {
 public:
  static constexpr double kOnsetRamp = 0.1;  // [s per a] from no acceleration to full deceleration
  static constexpr double kStopRamp = 0.2;   // [s] from full deceleration to none, at the end
  static constexpr double kStep = 0.002;     // [s]
  /// keep_samples false: only length() is kept (the commitment sizes many stops).
  StopProfile(double speed, double decel, double start_acc, bool keep_samples = true) {
    s_.push_back(0.0);
    double v = std::isfinite(speed) ? std::max(0.0, speed) : 0.0;
    if (v <= 1e-6) return;
    const double a = std::isfinite(decel) && decel > 1e-3 ? decel : 1e-3;
    const double j_on = a / kOnsetRamp, j_off = a / kStopRamp;
    double acc = std::isfinite(start_acc) ? std::clamp(start_acc, -4.0 * a, 4.0 * a) : -a;
    double dist = 0.0;
    bool easing = false;
    for (int k = 0; k < 1000000; ++k) {
      // Ease off once the speed left is what the ramp from this deceleration to none takes away.
      if (acc < 0.0 && v <= acc * acc / (2.0 * j_off)) easing = true;
      double next;
      if (easing) next = std::min(0.0, acc + j_off * kStep);
      else if (acc > -a) next = std::max(-a, acc - j_on * kStep);
      else next = std::min(-a, acc + j_on * kStep);
      const double v_next = v + 0.5 * (acc + next) * kStep;
      if (v_next <= 0.0 || (easing && next >= 0.0)) {
        // At rest within this step (the speed falls about linearly over it).
        const double f = v_next < 0.0 ? v / (v - v_next) : 1.0;
        s_.push_back(dist + 0.5 * v * f * kStep + (v_next > 0.0 ? 0.5 * v_next * kStep : 0.0));
        end_fraction_ = f;
        return;
      }
      dist += 0.5 * (v + v_next) * kStep;
      v = v_next;
      acc = next;
      if (keep_samples) s_.push_back(dist);
    }
  }
  /// (With keep_samples only.)
  double duration() const { return s_.size() <= 1 ? 0.0 : (double(s_.size()) - 2.0 + end_fraction_) * kStep; }
  double length() const { return s_.back(); }
  double distance(double tau) const {
    if (!(tau > 0.0) || s_.size() <= 1) return 0.0;
    if (tau >= duration()) return s_.back();
    const double x = tau / kStep;
    const size_t i = std::min(s_.size() - 2, size_t(x));
    const double span = i + 2 == s_.size() ? end_fraction_ : 1.0;
    const double f = span > 0.0 ? std::clamp((x - double(i)) / span, 0.0, 1.0) : 1.0;
    return s_[i] + f * (s_[i + 1] - s_[i]);
  }

 private:
  std::vector<double> s_;  // distance every kStep from the start; the last step may be a fraction
  double end_fraction_ = 1.0;
};

// The acceleration of `a` along the unit direction of `v` (0 at rest).
inline double alongAcceleration(const Eigen::Vector3d& v, const Eigen::Vector3d& a) {
  const double speed = v.norm();
  return speed > 1e-6 ? a.dot(v) / speed : 0.0;
}

// Positions every `interval` of a stop from speed v along `path` (from arc length s0) at
// deceleration a (StopProfile).
inline std::vector<Eigen::Vector3d> stopPoints(const PathByLength& path, double s0, double v, double a, double a0,
                                               double* interval) {
  const StopProfile stop(v, a, a0);
  const double T = stop.duration();
  const int n = std::max(4, int(std::ceil(T / 0.05)));
  *interval = T > 0.0 ? T / n : 0.1;
  std::vector<Eigen::Vector3d> points;
  for (int k = 0; k <= n; ++k) points.push_back(path.at(s0 + (T > 0.0 ? stop.distance(k * *interval) : 0.0)));
  return points;
}


}  // namespace topo_planner
