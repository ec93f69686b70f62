#include "topo_planner/topo_replan/path_speed_profile.h"

#include <algorithm>
#include <cmath>

namespace topo_planner {

bool PathSpeedProfile::Config::validate(std::string* why) const {
  std::string e;
  if (!(std::isfinite(max_vel_mps) && max_vel_mps > 0.0)) e += "max_vel_mps must be positive; ";
  if (!(std::isfinite(max_acc_mps2) && max_acc_mps2 > 0.0)) e += "max_acc_mps2 must be positive; ";
  if (!(std::isfinite(step_m) && step_m >= 1e-4 && step_m <= 1.0)) e += "step_m must be in [1e-4, 1]; ";
  if (!(max_corner_fraction > 0.0 && max_corner_fraction <= 0.5)) e += "max_corner_fraction must be in (0, 0.5]; ";
  if (!(std::isfinite(min_speed_mps) && min_speed_mps > 0.0 && min_speed_mps <= max_vel_mps))
    e += "min_speed_mps must be in (0, max_vel_mps]; ";
  if (max_samples < 2) e += "max_samples must be at least 2; ";
  if (why) *why = e.empty() ? "" : e.substr(0, e.size() - 2);
  return e.empty();
}

std::optional<PathSpeedProfile> PathSpeedProfile::compute(const std::vector<Eigen::Vector3d>& waypoints,
                                                          const Config& config, double v_start, double v_end,
                                                          std::string* why) {
  auto fail = [&](const std::string& reason) {
    if (why) *why = reason;
    return std::optional<PathSpeedProfile>();
  };
  std::string bad;
  if (!config.validate(&bad)) return fail("invalid config: " + bad);
  if (!std::isfinite(v_start) || !std::isfinite(v_end)) return fail("non-finite start or end speed");
  std::vector<Eigen::Vector3d> w;
  for (const Eigen::Vector3d& p : waypoints) {
    if (!p.allFinite()) return fail("a non-finite waypoint");
    if (w.empty() || (p - w.back()).norm() > 1e-6) w.push_back(p);
  }
  if (w.size() < 2) return fail("fewer than two distinct waypoints");

  // Legs, and the corners' tangent lengths, radii and angles.
  const size_t n = w.size();
  std::vector<double> leg(n - 1);
  std::vector<Eigen::Vector3d> dir(n - 1);
  for (size_t i = 0; i + 1 < n; ++i) {
    leg[i] = (w[i + 1] - w[i]).norm();
    dir[i] = (w[i + 1] - w[i]) / leg[i];
  }
  std::vector<double> tangent(n, 0.0), curvature(n, 0.0), arc(n, 0.0);
  for (size_t j = 1; j + 1 < n; ++j) {
    const double theta = std::acos(std::clamp(dir[j - 1].dot(dir[j]), -1.0, 1.0));
    if (theta < 1e-6) continue;
    tangent[j] = config.max_corner_fraction * std::min(leg[j - 1], leg[j]);
    if (theta > M_PI - 1e-6) {  // a reversal: a stop at the corner
      tangent[j] = 0.0;
      curvature[j] = INFINITY;
      continue;
    }
    const double radius = tangent[j] / std::tan(0.5 * theta);
    curvature[j] = 1.0 / radius;
    arc[j] = radius * theta;
  }

  // Pieces of the smoothed path: (length, curvature), and where each waypoint lies on it.
  struct Piece {
    double length, curvature;
  };
  std::vector<Piece> pieces;
  std::vector<double> waypoint_s{0.0};
  double total = 0.0;
  for (size_t i = 0; i + 1 < n; ++i) {
    const double straight = std::max(0.0, leg[i] - tangent[i] - tangent[i + 1]);
    pieces.push_back({straight, 0.0});
    total += straight;
    if (i + 2 < n) {
      pieces.push_back({arc[i + 1], curvature[i + 1]});
      waypoint_s.push_back(total + 0.5 * arc[i + 1]);
      total += arc[i + 1];
    }
  }
  waypoint_s.push_back(total);

  // Samples: arc length, the curvature of the step that follows each, and stops (reversals).
  PathSpeedProfile p;
  std::vector<double> step_curvature;
  std::vector<size_t> stops;
  p.s_.push_back(0.0);
  for (const Piece& piece : pieces) {
    if (std::isinf(piece.curvature)) {  // a reversal: no length, the speed is 0 where it is
      stops.push_back(p.s_.size() - 1);
      continue;
    }
    if (piece.length <= 0.0) continue;
    const size_t k = size_t(std::max(1.0, std::ceil(piece.length / config.step_m)));
    if (p.s_.size() + k > config.max_samples) return fail("the path is longer than max_samples steps");
    const double s0 = p.s_.back();
    for (size_t i = 1; i <= k; ++i) {
      step_curvature.push_back(piece.curvature);
      p.s_.push_back(s0 + piece.length * double(i) / double(k));
    }
  }
  const size_t N = p.s_.size();
  if (N < 2) return fail("the path has no length");
  const double a = config.max_acc_mps2, vmax = config.max_vel_mps;
  std::vector<double> vlim(N, vmax);
  for (size_t i = 0; i + 1 < N; ++i) {
    const double l = step_curvature[i] > 0.0 ? std::sqrt(a / step_curvature[i]) : INFINITY;
    vlim[i] = std::min(vlim[i], l);
    vlim[i + 1] = std::min(vlim[i + 1], l);
  }
  for (const size_t i : stops) vlim[i] = 0.0;
  auto tangential = [&](double v, double k) {
    const double normal = v * v * k;
    return std::sqrt(std::max(0.0, a * a - normal * normal));
  };
  p.v_.assign(N, 0.0);
  p.v_[0] = std::clamp(v_start, 0.0, vlim[0]);
  for (size_t i = 0; i + 1 < N; ++i) {
    const double ds = p.s_[i + 1] - p.s_[i];
    p.v_[i + 1] = std::min(vlim[i + 1], std::sqrt(p.v_[i] * p.v_[i] + 2.0 * tangential(p.v_[i], step_curvature[i]) * ds));
  }
  p.v_[N - 1] = std::min(p.v_[N - 1], std::max(0.0, v_end));
  for (size_t i = N - 1; i > 0; --i) {
    const double ds = p.s_[i] - p.s_[i - 1];
    p.v_[i - 1] =
        std::min(p.v_[i - 1], std::sqrt(p.v_[i] * p.v_[i] + 2.0 * tangential(p.v_[i], step_curvature[i - 1]) * ds));
  }
  p.time_.assign(N, 0.0);
  for (size_t i = 0; i + 1 < N; ++i) {
    const double ds = p.s_[i + 1] - p.s_[i];
    p.time_[i + 1] = p.time_[i] + (ds > 0.0 ? 2.0 * ds / std::max(p.v_[i] + p.v_[i + 1], 2.0 * config.min_speed_mps)
                                            : 0.0);
  }
  for (const double s : waypoint_s) p.waypoint_times_.push_back(p.timeAtDistance(s));
  p.waypoint_times_.back() = p.time_.back();
  return p;
}

double PathSpeedProfile::maxSpeed() const { return *std::max_element(v_.begin(), v_.end()); }

namespace {
// Linear interpolation of ys over the sorted xs at x (clamped).
double interpolate(const std::vector<double>& xs, const std::vector<double>& ys, double x) {
  if (!(x > xs.front())) return ys.front();
  if (x >= xs.back()) return ys.back();
  const size_t i = size_t(std::upper_bound(xs.begin(), xs.end(), x) - xs.begin());
  const double span = xs[i] - xs[i - 1];
  const double f = span > 0.0 ? (x - xs[i - 1]) / span : 1.0;
  return ys[i - 1] + f * (ys[i] - ys[i - 1]);
}
}  // namespace

double PathSpeedProfile::speedAt(double s) const { return interpolate(s_, v_, s); }
double PathSpeedProfile::distanceAt(double t) const { return interpolate(time_, s_, t); }
double PathSpeedProfile::timeAtDistance(double s) const { return interpolate(s_, time_, s); }

}  // namespace topo_planner
