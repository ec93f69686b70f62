#include "topo_planner/bspline_opt/bspline_costs.h"

#include <algorithm>
#include <cassert>
#include <cmath>
#include <limits>

namespace topo_planner {

double smoothnessCost(const Eigen::MatrixX3d& q, int first, int last, double weight, Eigen::MatrixX3d* grad) {
  const int n = int(q.rows());
  assert(0 <= first && first <= last && last < n);
  assert(!grad || (grad->rows() == n));
  double cost = 0.0;
  const int lo = std::max(1, first - 1), hi = std::min(n - 2, last + 1);
  for (int i = lo; i <= hi; ++i) {
    const Eigen::RowVector3d r = q.row(i + 1) - 2.0 * q.row(i) + q.row(i - 1);
    cost += r.squaredNorm();
    if (grad) {
      const Eigen::RowVector3d g = 2.0 * weight * r;
      grad->row(i - 1) += g;
      grad->row(i) -= 2.0 * g;
      grad->row(i + 1) += g;
    }
  }
  return cost;
}

double guideCost(const Eigen::MatrixX3d& q, const Eigen::MatrixX3d& guide, int first, int last, double weight,
                 Eigen::MatrixX3d* grad) {
  assert(0 <= first && first <= last && last < q.rows());
  assert(guide.rows() == last - first + 1);
  double cost = 0.0;
  for (int i = first; i <= last; ++i) {
    const Eigen::RowVector3d r = q.row(i) - guide.row(i - first);
    cost += r.squaredNorm();
    if (grad) grad->row(i) += 2.0 * weight * r;
  }
  return cost;
}


double windowDistance(const GridGeometry& g, const Eigen::Vector3d& p, Eigen::Vector3d* inward) {
  // The interpolation domain: voxel centres, i.e. half a voxel inside the window's faces.
  const Eigen::Vector3d half = Eigen::Vector3d::Constant(0.5 * g.resolution());
  const Eigen::Vector3d lo = g.windowMin() + half, hi = g.windowMax() - half;
  double best = std::numeric_limits<double>::infinity();
  for (int axis = 0; axis < 3; ++axis) {
    const double below = p[axis] - lo[axis], above = hi[axis] - p[axis];
    if (below < best) {
      best = below;
      if (inward) *inward = Eigen::Vector3d::Unit(axis);
    }
    if (above < best) {
      best = above;
      if (inward) *inward = -Eigen::Vector3d::Unit(axis);
    }
  }
  return best;
}

double collisionCost(const Eigen::MatrixX3d& q, int first, int last, const EsdfMap& map, double d0_m, double weight,
                     Eigen::MatrixX3d* grad, double min_z_m, double max_z_m, double face_offset_m) {
  assert(0 <= first && first <= last && last < q.rows());
  const GridGeometry& g = map.geometry();
  double cost = 0.0;
  for (int i = first; i <= last; ++i) {
    const Eigen::Vector3d p = q.row(i).transpose();
    if (!p.allFinite()) continue;
    // The nearer of the obstacles (ESDF) and the window's faces (negative outside the window).
    Eigen::Vector3d gradient;
    double distance = windowDistance(g, p, &gradient);
    if (p.z() - min_z_m < distance) distance = p.z() - min_z_m, gradient = Eigen::Vector3d::UnitZ();
    if (max_z_m - p.z() < distance) distance = max_z_m - p.z(), gradient = -Eigen::Vector3d::UnitZ();
    distance += face_offset_m;
    double esdf;
    Eigen::Vector3d esdf_gradient;
    if (distance >= d0_m) {
      if (!map.interpolate(p, &esdf, &esdf_gradient)) continue;  // (cannot happen this far inside)
      distance = esdf;
      gradient = esdf_gradient;
    } else if (map.interpolate(p, &esdf, &esdf_gradient) && esdf < distance) {
      distance = esdf;
      gradient = esdf_gradient;
    }
    const double excess = d0_m - distance;
    if (excess <= 0.0) continue;
    cost += excess * excess;
    if (grad) grad->row(i) -= 2.0 * weight * excess * gradient.transpose();
  }
  return cost;
}

namespace {

// sum over rows r of max(0, ||r|| - limit)^2 for the rows of a difference operator; the rows are
// computed by diff(i) and the gradient is spread by spread(i, d cost / d row).
template <typename Diff, typename Spread>
double excessCost(int rows, double limit, Diff&& diff, Spread&& spread) {
  double cost = 0.0;
  for (int i = 0; i < rows; ++i) {
    const Eigen::RowVector3d v = diff(i);
    const double norm = v.norm();
    if (norm <= limit) continue;
    const double excess = norm - limit;
    cost += excess * excess;
    spread(i, Eigen::RowVector3d(2.0 * excess / norm * v));
  }
  return cost;
}

}  // namespace

double velocityCost(const Eigen::MatrixX3d& q, double dt_s, double max_vel_mps, double weight, Eigen::MatrixX3d* grad) {
  assert(dt_s > 0.0 && max_vel_mps >= 0.0);
  const double inv_dt = 1.0 / dt_s;
  return excessCost(
      int(q.rows()) - 1, max_vel_mps, [&](int i) { return Eigen::RowVector3d((q.row(i + 1) - q.row(i)) * inv_dt); },
      [&](int i, const Eigen::RowVector3d& g) {
        if (!grad) return;
        grad->row(i + 1) += weight * inv_dt * g;
        grad->row(i) -= weight * inv_dt * g;
      });
}

double accelerationCost(const Eigen::MatrixX3d& q, double dt_s, double max_acc_mps2, double weight,
                        Eigen::MatrixX3d* grad) {
  assert(dt_s > 0.0 && max_acc_mps2 >= 0.0);
  const double inv_dt2 = 1.0 / (dt_s * dt_s);
  return excessCost(
      int(q.rows()) - 2, max_acc_mps2,
      [&](int i) { return Eigen::RowVector3d((q.row(i + 2) - 2.0 * q.row(i + 1) + q.row(i)) * inv_dt2); },
      [&](int i, const Eigen::RowVector3d& g) {
        if (!grad) return;
        const Eigen::RowVector3d s = weight * inv_dt2 * g;
        grad->row(i + 2) += s;
        grad->row(i + 1) -= 2.0 * s;
        grad->row(i) += s;
      });
}

}  // namespace topo_planner
