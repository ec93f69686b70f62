#include "topo_planner/topo_replan/route_watch.h"

#include <algorithm>
#include <cmath>

namespace topo_planner {

void RouteWatch::reset(const Path& route, const EsdfMap& map) {
  samples_.clear();
  blocked_when_searched_.clear();
  at_ = 0;
  const double step = map.geometry().resolution();
  for (size_t i = 1; i < route.size(); ++i) {
    const Eigen::Vector3d a = route[i - 1], b = route[i];
    const int n = std::max(1, int(std::ceil((b - a).norm() / step)));
    for (int k = i == 1 ? 0 : 1; k <= n; ++k) samples_.push_back(a + (b - a) * (double(k) / n));
  }
  blocked_when_searched_.reserve(samples_.size());
  for (const Eigen::Vector3d& p : samples_) {
    const DistanceQuery q = map.query(p);
    const bool known = q.status == QueryStatus::kOk || q.status == QueryStatus::kUnknown;
    blocked_when_searched_.push_back(known && q.distance < config_.safety_clearance_m);
  }
}

bool RouteWatch::blockedAt(const Eigen::Vector3d& p, const EsdfMap& map, double* distance) const {
  const DistanceQuery q = map.query(p);
  *distance = q.distance;
  return (q.status == QueryStatus::kOk || q.status == QueryStatus::kUnknown) && q.distance < config_.safety_clearance_m;
}

bool RouteWatch::bypassed(size_t i, const EsdfMap& map) const {
  const double step = map.geometry().resolution();
  const double band_lo = std::max(config_.min_z_m, map.geometry().windowMin().z() + step);
  const double band_hi = std::min(config_.max_z_m, map.geometry().windowMax().z() - step);
  const Eigen::Vector3d p = samples_[i];
  Eigen::Vector3d normal = i > 0 ? map.query(samples_[i - 1]).gradient : Eigen::Vector3d::Zero();
  if (!(normal.norm() > 0.1)) normal = samples_[std::min(i + 1, samples_.size() - 1)] - samples_[i > 0 ? i - 1 : 0];
  if (!(normal.norm() > 1e-6)) normal = Eigen::Vector3d::UnitX();
  normal.normalize();
  // Across the face: horizontal along it, and up it (vertical for a vertical face).
  Eigen::Vector3d along = normal.cross(Eigen::Vector3d::UnitZ());
  along = along.norm() > 0.1 ? along.normalized() : Eigen::Vector3d::UnitX();
  const Eigen::Vector3d up = along.cross(normal).normalized();
  const int n = int(std::round(kBypassM / step));
  for (int a = -n; a <= n; ++a)
    for (int b = -n; b <= n; ++b) {
      const Eigen::Vector3d q = p + along * (a * step) + up * (b * step);
      if (q.z() < band_lo || q.z() > band_hi) continue;
      const DistanceQuery d = map.query(q);
      if ((d.status == QueryStatus::kOk || d.status == QueryStatus::kUnknown) && d.distance >= config_.route_clearance_m)
        return true;
    }
  return false;
}

std::optional<RouteWatch::Blocked> RouteWatch::check(const Eigen::Vector3d& here, const EsdfMap& map) {
  if (samples_.empty()) return std::nullopt;
  const double step = map.geometry().resolution();
  const size_t window = size_t(20.0 / step);
  size_t at = at_;
  double best = INFINITY;
  for (size_t i = at_; i < samples_.size() && i <= at_ + window; ++i) {
    const double d = (samples_[i] - here).squaredNorm();
    if (d < best) best = d, at = i;
  }
  at_ = at;
  // From 1 m ahead of the vehicle (the local planner's), up to the check length.
  const size_t first = at + size_t(1.0 / step), last = at + size_t(config_.check_length_m / step);
  bool in_bypassed = false;  // within an obstacle found bypassable: its next samples need no new look
  for (size_t i = first; i < samples_.size() && i <= last; ++i) {
    double distance = 0.0;
    if (blocked_when_searched_[i] || !blockedAt(samples_[i], map, &distance)) {
      in_bypassed = false;  // (as close when it was searched: not news)
      continue;
    }
    if (in_bypassed) continue;
    if (bypassed(i, map)) {
      in_bypassed = true;
      continue;
    }
    Blocked b;
    b.ahead_m = double(i - at) * step;
    b.where = samples_[i];
    b.distance_m = distance;
    return b;
  }
  return std::nullopt;
}

}  // namespace topo_planner
