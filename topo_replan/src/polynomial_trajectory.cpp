#include "topo_planner/topo_replan/polynomial_trajectory.h"

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <numeric>

#include "topo_planner/topo_replan/path_speed_profile.h"

namespace topo_planner {

namespace {

constexpr int kN = PolynomialTrajectory::kCoefficients;
constexpr int kFixedOrders = 4;  // position, velocity, acceleration, jerk at each waypoint
using Mat8 = Eigen::Matrix<double, kN, kN>;

// d^r/dtau^r of tau^k, divided by tau^(k - r): k! / (k - r)!.
double falling(int k, int r) {
  double f = 1.0;
  for (int i = 0; i < r; ++i) f *= double(k - i);
  return f;
}

// Maps coefficients to the derivatives (orders 0-3, in tau) at tau = 0 and tau = 1.
const Mat8& endpointMap() {
  static const Mat8 a = [] {
    Mat8 m = Mat8::Zero();
    for (int r = 0; r < kFixedOrders; ++r) {
      m(r, r) = falling(r, r);                                           // at tau = 0 only tau^r survives
      for (int k = r; k < kN; ++k) m(kFixedOrders + r, k) = falling(k, r);  // at tau = 1
    }
    return m;
  }();
  return a;
}

// Snap cost in tau: integral over [0, 1] of (d^4 p / dtau^4)^2 = a^T Q a.
const Mat8& snapCostMatrix() {
  static const Mat8 q = [] {
    Mat8 m = Mat8::Zero();
    for (int j = 4; j < kN; ++j)
      for (int k = 4; k < kN; ++k) m(j, k) = falling(j, 4) * falling(k, 4) / double(j + k - 7);
    return m;
  }();
  return q;
}

// Cost of one segment in terms of its endpoint derivatives in real time, d = S A a with
// S = diag(T^-r): J = T^-7 d^T S^-1 A^-T Q A^-1 S^-1 d.
Mat8 segmentCost(double T) {
  static const Mat8 core = [] {
    const Mat8 a_inv = endpointMap().inverse();
    return Mat8(a_inv.transpose() * snapCostMatrix() * a_inv);
  }();
  Eigen::Matrix<double, kN, 1> s_inv;
  for (int r = 0; r < kFixedOrders; ++r) s_inv(r) = s_inv(kFixedOrders + r) = std::pow(T, r);
  return std::pow(T, -7.0) * s_inv.asDiagonal() * core * s_inv.asDiagonal();
}

}  // namespace

const char* toString(TrajectoryStatus status) {
  switch (status) {
    case TrajectoryStatus::kSuccess: return "success";
    case TrajectoryStatus::kInvalidInput: return "invalid input";
    case TrajectoryStatus::kInfeasible: return "limits not met";
  }
  return "unknown status";
}

double PolynomialTrajectory::duration() const {
  double d = 0.0;
  for (const Segment& s : segments_) d += s.duration;
  return d;
}

Eigen::Vector3d PolynomialTrajectory::derivative(double t, int order) const {
  if (segments_.empty() || order < 0 || order >= kN) return Eigen::Vector3d::Zero();
  t = std::clamp(t, 0.0, duration());
  size_t i = 0;
  while (i + 1 < segments_.size() && t > segments_[i].duration) {
    t -= segments_[i].duration;
    ++i;
  }
  const Segment& s = segments_[i];
  const double tau = std::clamp(t / s.duration, 0.0, 1.0);
  Eigen::Vector3d v = Eigen::Vector3d::Zero();
  for (int k = kN - 1; k >= order; --k) v = v * tau + s.coefficients.row(k).transpose() * falling(k, order);
  return v / std::pow(s.duration, order);
}

FlatState PolynomialTrajectory::state(double t) const {
  FlatState s;
  s.position = derivative(t, 0);
  s.velocity = derivative(t, 1);
  s.acceleration = derivative(t, 2);
  s.jerk = derivative(t, 3);
  return s;
}

// Both samplers take at most about 100000 samples (longer trajectories get a coarser step).
double PolynomialTrajectory::maxSpeed(double dt_s) const {
  double m = 0.0;
  dt_s = std::max(dt_s, duration() * 1e-5);
  for (double t = 0.0; t <= duration() + 1e-12; t += dt_s) m = std::max(m, velocity(t).norm());
  return std::max(m, velocity(duration()).norm());
}

double PolynomialTrajectory::maxAcceleration(double dt_s) const {
  double m = 0.0;
  dt_s = std::max(dt_s, duration() * 1e-5);
  for (double t = 0.0; t <= duration() + 1e-12; t += dt_s) m = std::max(m, acceleration(t).norm());
  return std::max(m, acceleration(duration()).norm());
}

double PolynomialTrajectory::snapCost() const {
  double j = 0.0;
  for (const Segment& s : segments_) {
    const Mat8& q = snapCostMatrix();
    for (int axis = 0; axis < 3; ++axis)
      j += s.coefficients.col(axis).dot(q * s.coefficients.col(axis)) / std::pow(s.duration, 7.0);
  }
  return j;
}

TrajectoryStatus minimumSnapTrajectory(const std::vector<Eigen::Vector3d>& waypoints,
                                       const std::vector<double>& durations, const FlatState& start,
                                       const FlatState& end, PolynomialTrajectory* out) {
  const int m = int(waypoints.size()) - 1;  // segments
  if (m < 1 || int(durations.size()) != m || !start.allFinite() || !end.allFinite()) return TrajectoryStatus::kInvalidInput;
  for (const auto& w : waypoints)
    if (!w.allFinite()) return TrajectoryStatus::kInvalidInput;
  for (double d : durations)
    if (!(std::isfinite(d) && d > 0.0)) return TrajectoryStatus::kInvalidInput;

  // Unknowns: 4 derivatives per waypoint, ordered waypoint-major. Fixed: every position and the
  // end derivatives; free: velocity, acceleration and jerk at the inner waypoints.
  const int n = kFixedOrders * (m + 1);
  Eigen::MatrixXd h = Eigen::MatrixXd::Zero(n, n);
  for (int i = 0; i < m; ++i) h.block(kFixedOrders * i, kFixedOrders * i, kN, kN) += segmentCost(durations[size_t(i)]);
  std::vector<int> fixed, free;
  for (int w = 0; w <= m; ++w)
    for (int r = 0; r < kFixedOrders; ++r) (r == 0 || w == 0 || w == m ? fixed : free).push_back(kFixedOrders * w + r);
  Eigen::MatrixXd d(n, 3);
  for (int w = 0; w <= m; ++w) d.row(kFixedOrders * w) = waypoints[size_t(w)].transpose();
  const FlatState* ends[2] = {&start, &end};
  for (int e = 0; e < 2; ++e) {
    const int base = e == 0 ? 0 : kFixedOrders * m;
    d.row(base + 1) = ends[e]->velocity.transpose();
    d.row(base + 2) = ends[e]->acceleration.transpose();
    d.row(base + 3) = ends[e]->jerk.transpose();
  }
  if (!free.empty()) {
    const int nf = int(fixed.size()), np = int(free.size());
    Eigen::MatrixXd hpp(np, np), hpf(np, nf), df(nf, 3);
    for (int a = 0; a < np; ++a) {
      for (int b = 0; b < np; ++b) hpp(a, b) = h(free[size_t(a)], free[size_t(b)]);
      for (int b = 0; b < nf; ++b) hpf(a, b) = h(free[size_t(a)], fixed[size_t(b)]);
    }
    for (int b = 0; b < nf; ++b) df.row(b) = d.row(fixed[size_t(b)]);
    const Eigen::MatrixXd dp = hpp.ldlt().solve(-hpf * df);
    if (!dp.allFinite()) return TrajectoryStatus::kInvalidInput;
    for (int a = 0; a < np; ++a) d.row(free[size_t(a)]) = dp.row(a);
  }

  const Mat8 a_inv = endpointMap().inverse();
  std::vector<PolynomialTrajectory::Segment> segments(static_cast<size_t>(m));
  for (int i = 0; i < m; ++i) {
    const double T = durations[size_t(i)];
    Eigen::Matrix<double, kN, 3> ends_tau = d.block(kFixedOrders * i, 0, kN, 3);  // real time -> tau: * T^r
    for (int r = 0; r < kFixedOrders; ++r) {
      ends_tau.row(r) *= std::pow(T, r);
      ends_tau.row(kFixedOrders + r) *= std::pow(T, r);
    }
    segments[size_t(i)].duration = T;
    segments[size_t(i)].coefficients = a_inv * ends_tau;
  }
  *out = PolynomialTrajectory(std::move(segments));
  return TrajectoryStatus::kSuccess;
}

FlatState referenceStartState(const FlatState& vehicle, const Eigen::Vector3d& leg) {
  FlatState start = vehicle;
  const double speed = vehicle.velocity.norm(), length = leg.norm();
  if (!(length > 1e-9) || !std::isfinite(length)) return start;
  const Eigen::Vector3d dir = leg / length;
  const double along = vehicle.velocity.dot(dir);
  if (along >= 0.95 * speed) return start;  // along the leg (cos 18 deg = 0.951)
  start.velocity = std::max(0.0, along) * dir;
  start.acceleration.setZero();
  return start;
}

double waypointPassTime(const PolynomialTrajectory& reference, const Eigen::Vector3d& waypoint, double t_from,
                        double radius, double step) {
  const double T = reference.duration();
  if (reference.empty() || !waypoint.allFinite() || !std::isfinite(t_from) || !(radius >= 0.0) ||
      !std::isfinite(radius) || !(step > 0.0) || !std::isfinite(step))
    return NAN;
  double best_t = NAN, best_d = INFINITY;
  for (double s = std::clamp(t_from, 0.0, T);; s = std::min(s + step, T)) {
    const double d = (reference.position(s) - waypoint).norm();
    if (d <= radius && d < best_d) best_d = d, best_t = s;
    if ((d > radius && std::isfinite(best_d)) || s >= T) break;  // the first pass is over
  }
  if (std::isnan(best_t)) return NAN;
  if ((reference.position(best_t) - reference.position(std::clamp(t_from, 0.0, T))).norm() <= radius) return NAN;
  return best_t;
}

TrajectoryStatus referenceTrajectory(const std::vector<Eigen::Vector3d>& waypoints, const FlatState& start,
                                     const FlatState& end, const ReferenceConfig& config, PolynomialTrajectory* out) {
  if (waypoints.size() < 2 || !(config.max_vel_mps > 0.0) || !(config.max_acc_mps2 > 0.0) ||
      !std::isfinite(config.max_vel_mps) || !std::isfinite(config.max_acc_mps2))
    return TrajectoryStatus::kInvalidInput;
  if (!std::isfinite(config.max_segment_length_m) || config.max_segment_length_m < 0.0)
    return TrajectoryStatus::kInvalidInput;
  std::vector<Eigen::Vector3d> points{waypoints.front()};
  for (size_t i = 1; i < waypoints.size(); ++i) {
    const double dist = (waypoints[i] - waypoints[i - 1]).norm();
    if (!std::isfinite(dist)) return TrajectoryStatus::kInvalidInput;
    const int pieces = config.max_segment_length_m > 0.0
                           ? std::min(1000, std::max(1, int(std::ceil(dist / config.max_segment_length_m))))
                           : 1;
    for (int k = 1; k <= pieces; ++k)
      points.push_back(waypoints[i - 1] + (waypoints[i] - waypoints[i - 1]) * (double(k) / pieces));
  }
  // Trapezoidal time at the limits: per segment (rest to rest), or over the whole path (cruise).
  const double v = config.max_vel_mps, a = config.max_acc_mps2;
  std::vector<double> durations;
  for (size_t i = 1; i < points.size(); ++i) {
    const double dist = (points[i] - points[i - 1]).norm();
    double t = dist > v * v / a ? dist / v + v / a : 2.0 * std::sqrt(dist / a);
    if (config.cruise_timing) t = dist / v + ((i == 1) + (i + 1 == points.size())) * v / a;
    durations.push_back(std::max(t, 0.1));
  }
  const double v_allowed = std::max({v, start.velocity.norm(), end.velocity.norm()});
  const double a_allowed = std::max({a, start.acceleration.norm(), end.acceleration.norm()});
  if (config.profile_timing) {
    // Segment times from the time-optimal profile (the speed along the path at the limits), then the
    // segments that break the limits stretched alone: min-snap passes through every waypoint, where
    // the profile rounds the corner, and slows more there; elsewhere it keeps the profile's pace.
    PathSpeedProfile::Config pc;
    pc.max_vel_mps = v;
    pc.max_acc_mps2 = a;
    pc.step_m = 0.05;
    // The ends' speeds along the path (a start moving away from the route counts as at rest).
    auto along = [](const Eigen::Vector3d& vel, const Eigen::Vector3d& from, const Eigen::Vector3d& to) {
      const Eigen::Vector3d d = to - from;
      return d.norm() > 1e-9 ? std::max(0.0, vel.dot(d) / d.norm()) : 0.0;
    };
    const size_t n = points.size();
    const auto profile = PathSpeedProfile::compute(points, pc, std::min(v, along(start.velocity, points[0], points[1])),
                                                   std::min(v, along(end.velocity, points[n - 2], points[n - 1])));
    if (profile && profile->waypointTimes().size() == points.size()) {
      const std::vector<double>& wt = profile->waypointTimes();
      std::vector<double> base(durations.size());
      for (size_t i = 1; i < points.size(); ++i) base[i - 1] = std::max(wt[i] - wt[i - 1], 0.05);
      durations = base;
      for (int k = 0; k <= config.max_rescales; ++k) {
        const TrajectoryStatus s = minimumSnapTrajectory(points, durations, start, end, out);
        if (s != TrajectoryStatus::kSuccess) return s;
        std::vector<double> factor(durations.size(), 1.0);
        bool ok = true;
        double t0 = 0.0;
        for (size_t i = 0; i < durations.size(); ++i) {
          double vm = 0.0, am = 0.0;
          const double dt = std::max(0.01, durations[i] / 50.0);
          for (double t = t0; t <= t0 + durations[i] + 1e-9; t += dt) {
            vm = std::max(vm, out->velocity(t).norm());
            am = std::max(am, out->acceleration(t).norm());
          }
          t0 += durations[i];
          const double f = std::max(vm / v_allowed, std::sqrt(am / a_allowed));
          if (f > 1.0 + 1e-6) {
            ok = false;
            // The segment, and half as much its neighbours: min-snap couples them through the free
            // derivatives at their common waypoints (a segment stretched alone can push its
            // excess into the next one, and the stretching then diverged: 2e12 s for 30 m).
            const double g = std::min(std::max(f, 1.02), 1.5) * 1.01;
            factor[i] = std::max(factor[i], g);
            if (i > 0) factor[i - 1] = std::max(factor[i - 1], std::sqrt(g));
            if (i + 1 < durations.size()) factor[i + 1] = std::max(factor[i + 1], std::sqrt(g));
          }
        }
        // The whole trajectory at the limits (sampled finer than the per-segment scan).
        if (ok && out->maxSpeed() <= v_allowed * (1.0 + 1e-6) && out->maxAcceleration() <= a_allowed * (1.0 + 1e-6))
          return TrajectoryStatus::kSuccess;
        if (ok) std::fill(factor.begin(), factor.end(), 1.02);  // only the fine sampling sees the excess
        for (size_t i = 0; i < durations.size(); ++i) durations[i] = std::min(durations[i] * factor[i], 4.0 * base[i]);
      }
      // Not met segment by segment: the uniform stretch below, from the profile's times.
      durations = base;
    }
  }
  const double initial_total = std::accumulate(durations.begin(), durations.end(), 0.0);
  for (int k = 0; k <= config.max_rescales; ++k) {
    const TrajectoryStatus s = minimumSnapTrajectory(points, durations, start, end, out);
    if (s != TrajectoryStatus::kSuccess) return s;
    // The limits hold, or are broken only as much as the fixed start or end state breaks them
    // (stretching time cannot change those: a vehicle braking harder than the reference's limit
    // starts a reference that way).
    const double vr = out->maxSpeed() / v_allowed, ar = out->maxAcceleration() / a_allowed;
    if (vr <= 1.0 + 1e-6 && ar <= 1.0 + 1e-6) {
      // A reference stretched far beyond its first timing is no plan to fly (and its length in time
      // costs every loop over it): the limits cannot be met from this start.
      return out->duration() <= kMaxReferenceStretch * initial_total + 10.0 ? TrajectoryStatus::kSuccess
                                                                            : TrajectoryStatus::kInfeasible;
    }
    // Stretching time by f divides speeds by f and accelerations by f^2 (exactly so when the end
    // derivatives are zero; otherwise the loop iterates).
    const double f = std::max({vr, std::sqrt(ar), 1.02});
    for (double& d : durations) d *= std::min(f, 2.0) * 1.01;
  }
  return TrajectoryStatus::kInfeasible;
}

}  // namespace topo_planner
