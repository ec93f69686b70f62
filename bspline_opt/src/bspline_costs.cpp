#include "bspline_opt/bspline_costs.h"

#include <algorithm>
#include <cassert>
#include <cmath>

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

bool interpolateDistance(const EsdfMap& map, const Eigen::Vector3d& point, double* distance,
                         Eigen::Vector3d* gradient) {
  if (!point.allFinite()) return false;
  const GridGeometry& g = map.geometry();
  const Eigen::Vector3d pm = point * g.inverseResolution() - Eigen::Vector3d::Constant(0.5);
  if ((pm.array().abs() > 1e9).any()) return false;
  const Eigen::Vector3d fl = pm.array().floor();
  const Eigen::Vector3i base = fl.cast<int>();
  const Eigen::Vector3d t = pm - fl;
  // Both corners in the window: the 8 voxels are.
  if (!g.inWindow(base) || !g.inWindow(Eigen::Vector3i(base + Eigen::Vector3i::Ones()))) return false;
  double v[2][2][2];
  for (int dx = 0; dx < 2; ++dx)
    for (int dy = 0; dy < 2; ++dy)
      for (int dz = 0; dz < 2; ++dz) {
        float d = 0.0f;
        map.voxelDistance(base + Eigen::Vector3i(dx, dy, dz), &d);
        v[dx][dy][dz] = d;
      }
  // x, then y, then z; the gradient is the derivative of the same trilinear polynomial.
  double vx[2][2], dvx[2][2];
  for (int dy = 0; dy < 2; ++dy)
    for (int dz = 0; dz < 2; ++dz) {
      vx[dy][dz] = (1 - t.x()) * v[0][dy][dz] + t.x() * v[1][dy][dz];
      dvx[dy][dz] = v[1][dy][dz] - v[0][dy][dz];
    }
  double vxy[2], dxy_x[2], dxy_y[2];
  for (int dz = 0; dz < 2; ++dz) {
    vxy[dz] = (1 - t.y()) * vx[0][dz] + t.y() * vx[1][dz];
    dxy_x[dz] = (1 - t.y()) * dvx[0][dz] + t.y() * dvx[1][dz];
    dxy_y[dz] = vx[1][dz] - vx[0][dz];
  }
  *distance = (1 - t.z()) * vxy[0] + t.z() * vxy[1];
  if (gradient) {
    gradient->x() = ((1 - t.z()) * dxy_x[0] + t.z() * dxy_x[1]) * g.inverseResolution();
    gradient->y() = ((1 - t.z()) * dxy_y[0] + t.z() * dxy_y[1]) * g.inverseResolution();
    gradient->z() = (vxy[1] - vxy[0]) * g.inverseResolution();
  }
  return true;
}

double collisionCost(const Eigen::MatrixX3d& q, int first, int last, const EsdfMap& map, double d0_m, double weight,
                     Eigen::MatrixX3d* grad) {
  assert(0 <= first && first <= last && last < q.rows());
  double cost = 0.0;
  for (int i = first; i <= last; ++i) {
    double distance;
    Eigen::Vector3d gradient;
    if (!interpolateDistance(map, q.row(i).transpose(), &distance, &gradient)) continue;
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
