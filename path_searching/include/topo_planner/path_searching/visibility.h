#pragma once
// Collision checks of points and segments against the ESDF at map resolution: a voxel is free when
// its centre is at least clearance_m from every obstacle (and it is known, unless unknown space
// counts as free). A segment is visible when every voxel it passes through is free. With unknown
// space free, segments are sphere-traced on the distance field (voxels inside a ball that the field
// proves free are not read; same answer as reading them, tested against a plain DDA); otherwise the
// 3-D DDA reads every voxel for its state.

#include <Eigen/Core>

#include "topo_planner/path_searching/path.h"
#include "topo_planner/plan_env/esdf_map.h"

namespace topo_planner {

class VisibilityChecker {
 public:
  VisibilityChecker(const EsdfMap& esdf, double clearance_m, bool unknown_is_free);

  bool isFreeVoxel(const Eigen::Vector3i& index) const;
  /// False for NaN/inf and out-of-map points.
  bool isFree(const Eigen::Vector3d& point) const;
  /// True when every voxel the segment passes through is free. Otherwise, if first_blocked is
  /// given, it receives the centre of the first blocked voxel from a.
  bool lineVisible(const Eigen::Vector3d& a, const Eigen::Vector3d& b, Eigen::Vector3d* first_blocked = nullptr) const;

  double resolution() const { return esdf_.geometry().resolution(); }
  double clearance() const { return clearance_; }
  const EsdfMap& esdf() const { return esdf_; }

 private:
  const EsdfMap& esdf_;
  float clearance_;
  bool unknown_is_free_;
};

/// Definition 1 of the paper (uniform visibility deformation): paths a and b with common ends are
/// equivalent when every segment between their points of equal normalised arc length s_i = i / K
/// is collision-free; K = ceil(longer length / resolution), at least 2.
bool uniformVisibilityEquivalent(const Path& a, const Path& b, const VisibilityChecker& checker);

}  // namespace topo_planner
