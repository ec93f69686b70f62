#pragma once
// 3-D digital differential analyser (Amanatides & Woo, "A fast voxel traversal algorithm", 1987):
// visits every voxel a segment passes through, in order, with no voxel skipped or repeated.

#include <Eigen/Core>
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdlib>

namespace topo_planner {

/// Calls visit(global_index) for each voxel from the one containing `from` to the one containing
/// `to`, both included, in order along the segment. visit returns false to stop early. Returns
/// false if it was stopped. Both points must be finite; voxels have edge `resolution`.
template <typename Visitor>
bool traverseVoxels(const Eigen::Vector3d& from, const Eigen::Vector3d& to, double resolution, Visitor&& visit) {
  const Eigen::Vector3d a = from / resolution;
  const Eigen::Vector3d b = to / resolution;
  Eigen::Vector3i idx = a.array().floor().cast<int>();
  const Eigen::Vector3i last = b.array().floor().cast<int>();
  const Eigen::Vector3d dir = b - a;

  Eigen::Vector3i step;
  Eigen::Vector3d t_max, t_delta;
  for (int k = 0; k < 3; ++k) {
    if (dir[k] > 0.0) {
      step[k] = 1;
      t_delta[k] = 1.0 / dir[k];
      t_max[k] = (std::floor(a[k]) + 1.0 - a[k]) * t_delta[k];
    } else if (dir[k] < 0.0) {
      step[k] = -1;
      t_delta[k] = -1.0 / dir[k];
      t_max[k] = (a[k] - std::floor(a[k])) * t_delta[k];
    } else {
      step[k] = 0;
      t_delta[k] = INFINITY;
      t_max[k] = INFINITY;
    }
  }
  // The voxel count is bounded by the Manhattan distance of the end voxels; rounding in t_max can
  // never make the walk longer than that.
  const int64_t max_steps =
      int64_t(std::abs(last.x() - idx.x())) + std::abs(last.y() - idx.y()) + std::abs(last.z() - idx.z());
  if (!visit(static_cast<const Eigen::Vector3i&>(idx))) return false;
  for (int64_t n = 0; n < max_steps; ++n) {
    int k = (t_max.x() < t_max.y()) ? (t_max.x() < t_max.z() ? 0 : 2) : (t_max.y() < t_max.z() ? 1 : 2);
    // A component that already reached the last voxel on its axis must not step again.
    if (idx[k] == last[k]) {
      int alt = -1;
      double best = INFINITY;
      for (int j = 0; j < 3; ++j) {
        if (idx[j] != last[j] && t_max[j] < best) {
          best = t_max[j];
          alt = j;
        }
      }
      if (alt < 0) break;
      k = alt;
    }
    idx[k] += step[k];
    t_max[k] += t_delta[k];
    if (!visit(static_cast<const Eigen::Vector3i&>(idx))) return false;
  }
  return true;
}

/// Distance along the unit direction u from p, which lies in voxel v, to where the ray leaves v.
inline double distanceToVoxelExit(const Eigen::Vector3d& p, const Eigen::Vector3d& u, const Eigen::Vector3i& v,
                                  double resolution) {
  double step = INFINITY;
  for (int k = 0; k < 3; ++k) {
    if (u[k] > 0.0) step = std::min(step, ((v[k] + 1) * resolution - p[k]) / u[k]);
    if (u[k] < 0.0) step = std::min(step, (v[k] * resolution - p[k]) / u[k]);
  }
  return std::max(step, 0.0);
}

/// Distance along the unit direction u from p to where the ray leaves the ball (centre, radius);
/// 0 when p is not inside it. The step of sphere tracing on a distance field.
inline double distanceToBallExit(const Eigen::Vector3d& p, const Eigen::Vector3d& u, const Eigen::Vector3d& centre,
                                 double radius) {
  if (!(radius > 0.0)) return 0.0;
  const Eigen::Vector3d w = p - centre;
  const double wu = w.dot(u), ww = w.squaredNorm(), disc = wu * wu - (ww - radius * radius);
  return (ww < radius * radius && disc >= 0.0) ? -wu + std::sqrt(disc) : 0.0;
}

/// Clips the segment from->to to the axis-aligned box [lo, hi]. On success returns true and the
/// parameters 0 <= t0 <= t1 <= 1 of the part inside the box.
inline bool clipSegmentToBox(const Eigen::Vector3d& from, const Eigen::Vector3d& to, const Eigen::Vector3d& lo,
                             const Eigen::Vector3d& hi, double* t0, double* t1) {
  double ta = 0.0, tb = 1.0;
  const Eigen::Vector3d d = to - from;
  for (int k = 0; k < 3; ++k) {
    if (std::abs(d[k]) < 1e-12) {
      if (from[k] < lo[k] || from[k] > hi[k]) return false;
      continue;
    }
    double u = (lo[k] - from[k]) / d[k];
    double v = (hi[k] - from[k]) / d[k];
    if (u > v) std::swap(u, v);
    ta = std::max(ta, u);
    tb = std::min(tb, v);
    if (ta > tb) return false;
  }
  *t0 = ta;
  *t1 = tb;
  return true;
}

}  // namespace topo_planner
