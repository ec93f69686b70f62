#include "topo_planner/path_searching/visibility.h"

#include <algorithm>
#include <cmath>

#include "topo_planner/plan_env/raycast.h"

namespace topo_planner {

VisibilityChecker::VisibilityChecker(const EsdfMap& esdf, double clearance_m, bool unknown_is_free)
    : esdf_(esdf), clearance_(float(clearance_m)), unknown_is_free_(unknown_is_free) {}

bool VisibilityChecker::isFreeVoxel(const Eigen::Vector3i& index) const {
  float d;
  if (!esdf_.voxelDistance(index, &d) || d < clearance_) return false;
  return unknown_is_free_ || esdf_.occupancy().state(index) != VoxelState::kUnknown;
}

bool VisibilityChecker::isFree(const Eigen::Vector3d& point) const {
  if (!esdf_.geometry().inWindow(point)) return false;
  return isFreeVoxel(esdf_.geometry().indexOf(point));
}

bool VisibilityChecker::lineVisible(const Eigen::Vector3d& a, const Eigen::Vector3d& b,
                                    Eigen::Vector3d* first_blocked) const {
  const GridGeometry& g = esdf_.geometry();
  if (!g.inWindow(a) || !g.inWindow(b)) {
    if (first_blocked) *first_blocked = g.inWindow(a) ? b : a;
    return false;
  }
  const double res = g.resolution();
  auto blockedAt = [&](const Eigen::Vector3i& i) {
    if (first_blocked) *first_blocked = g.centerOf(i);
    return false;
  };
  if (!unknown_is_free_) {  // every voxel must be read for its state: plain DDA
    Eigen::Vector3i blocked;
    const bool clear = traverseVoxels(a, b, res, [&](const Eigen::Vector3i& i) {
      if (isFreeVoxel(i)) return true;
      blocked = i;
      return false;
    });
    return clear ? true : blockedAt(blocked);
  }
  // Sphere tracing on the distance field. The field is 1-Lipschitz between voxel centres, so from a
  // voxel v with distance d every voxel whose centre is within d - clearance of v's centre is free;
  // a point within rho = d - clearance - sqrt(3)/2 res of v's centre lies in such a voxel. The walk
  // jumps to where the segment leaves that ball, and steps voxel by voxel where the ball is too
  // small, so it reads the map rarely in open space and at every voxel near obstacles.
  const Eigen::Vector3d delta = b - a;
  const double length = delta.norm();
  const Eigen::Vector3d u = length > 0.0 ? Eigen::Vector3d(delta / length) : Eigen::Vector3d::UnitX();
  const double half_diagonal = 0.5 * std::sqrt(3.0) * res;
  const double nudge = 1e-6 * res;
  double t = 0.0;
  for (;;) {
    const Eigen::Vector3d p = a + u * t;
    const Eigen::Vector3i v = g.indexOf(p);
    float d;
    if (!esdf_.voxelDistance(v, &d) || d < clearance_) return blockedAt(v);
    double next = t + distanceToBallExit(p, u, g.centerOf(v), double(d - clearance_) - half_diagonal);
    if (next <= t + nudge) next = t + distanceToVoxelExit(p, u, v, res) + nudge;  // into the next voxel
    if (next >= length) return true;  // the voxel of b has been read or lies in the ball
    t = next;
  }
}

bool uniformVisibilityEquivalent(const Path& a, const Path& b, const VisibilityChecker& checker) {
  const double longer = std::max(pathLength(a), pathLength(b));
  const int k = std::max(2, int(std::ceil(longer / checker.resolution())));
  const Path da = discretizeByArcLength(a, k), db = discretizeByArcLength(b, k);
  for (int i = 1; i < k; ++i)  // s = 0 and s = 1 are the shared ends
    if (!checker.lineVisible(da[size_t(i)], db[size_t(i)])) return false;
  return true;
}

}  // namespace topo_planner
