#include "topo_planner/topo_replan/mission_progress.h"

#include <algorithm>

namespace topo_planner {

void MissionProgress::reset(const Path& way, double t, const Eigen::Vector3d& p, bool keep_clock) {
  way_.clear();
  arc_.clear();
  for (const Eigen::Vector3d& q : way)
    if (q.allFinite()) way_.push_back(q);
  if (way_.empty() || !std::isfinite(t)) {
    way_.clear();
    return;
  }
  arc_.push_back(0.0);
  for (size_t i = 1; i < way_.size(); ++i) arc_.push_back(arc_.back() + (way_[i] - way_[i - 1]).norm());
  if (!keep_clock || !std::isfinite(last_gain_s_)) last_gain_s_ = t;
  // The first projection: anywhere along the way's first stretch (the way starts near the vehicle).
  s_ = 0.0;
  remaining_ = NAN;
  if (p.allFinite()) project(p, 0.0, config_.window_ahead_m, &s_, &remaining_);
  best_ = std::isfinite(remaining_) ? remaining_ : INFINITY;
}

void MissionProgress::project(const Eigen::Vector3d& p, double lo, double hi, double* s, double* left) const {
  const double total = arc_.back();
  double best_d = INFINITY, best_s = std::clamp(*s, 0.0, total);
  if (way_.size() == 1) {
    *s = 0.0;
    *left = (p - way_.front()).norm();
    return;
  }
  for (size_t i = 0; i + 1 < way_.size(); ++i) {
    if (arc_[i + 1] < lo || arc_[i] > hi) continue;
    const Eigen::Vector3d a = way_[i], ab = way_[i + 1] - way_[i];
    const double len2 = ab.squaredNorm();
    double u = len2 > 0.0 ? (p - a).dot(ab) / len2 : 0.0;
    // Within the window only.
    const double len = std::sqrt(len2);
    const double u_lo = len > 0.0 ? (lo - arc_[i]) / len : 0.0, u_hi = len > 0.0 ? (hi - arc_[i]) / len : 1.0;
    u = std::clamp(u, std::max(0.0, u_lo), std::min(1.0, u_hi));
    const double d = (a + u * ab - p).norm();
    if (d < best_d) best_d = d, best_s = arc_[i] + u * len;
  }
  if (!std::isfinite(best_d)) best_d = (p - way_.back()).norm(), best_s = total;
  *s = best_s;
  *left = best_d + (total - best_s);
}

Eigen::Vector3d MissionProgress::ahead(double d) const {
  if (!active()) return Eigen::Vector3d::Zero();
  const double s = std::clamp(s_ + std::max(0.0, d), 0.0, arc_.back());
  for (size_t i = 0; i + 1 < way_.size(); ++i)
    if (s <= arc_[i + 1]) {
      const double len = arc_[i + 1] - arc_[i];
      return len > 0.0 ? way_[i] + (way_[i + 1] - way_[i]) * ((s - arc_[i]) / len) : way_[i];
    }
  return way_.back();
}

double MissionProgress::update(double t, const Eigen::Vector3d& p) {
  if (!active() || !p.allFinite() || !std::isfinite(t)) return NAN;
  project(p, s_ - config_.window_back_m, s_ + config_.window_ahead_m, &s_, &remaining_);
  if (remaining_ < best_ - config_.min_gain_m || !std::isfinite(best_)) {
    best_ = remaining_;
    last_gain_s_ = t;
  }
  return remaining_;
}

}  // namespace topo_planner
