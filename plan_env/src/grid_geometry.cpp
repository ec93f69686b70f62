#include "topo_planner/plan_env/grid_geometry.h"

#include <cassert>

namespace topo_planner {

namespace {
int positiveModulo(int a, int n) { return ((a % n) + n) % n; }
}  // namespace

GridGeometry::GridGeometry(double resolution_m, const Eigen::Vector3i& size_voxels, const Eigen::Vector3i& origin_index)
    : resolution_(resolution_m), inv_resolution_(1.0 / resolution_m), size_(size_voxels) {
  assert(resolution_m > 0.0);
  assert((size_voxels.array() > 0).all());
  setOriginIndex(origin_index);
}

void GridGeometry::setOriginIndex(const Eigen::Vector3i& origin_index) {
  origin_ = origin_index;
  for (int a = 0; a < 3; ++a) offset_[a] = positiveModulo(origin_[a], size_[a]);
}

}  // namespace topo_planner
