#include "topo_planner/uav_sim/truth_map.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <sstream>

namespace topo_planner {

namespace {
// Distance from p to the axis-aligned cube of voxel v (0 inside).
double distanceToVoxel(const Eigen::Vector3d& p, const Eigen::Vector3i& v, double res) {
  const Eigen::Vector3d lo = v.cast<double>() * res, hi = lo + Eigen::Vector3d::Constant(res);
  return (lo - p).cwiseMax(p - hi).cwiseMax(0.0).norm();
}
}  // namespace

bool TruthMap::Config::validate(std::string* why) const {
  std::ostringstream err;
  std::string esdf_why;
  if (!(std::isfinite(resolution_m) && resolution_m >= 0.01 && resolution_m <= 10.0))
    err << "resolution_m must be in [0.01, 10]; ";
  if (!(std::isfinite(margin_m) && margin_m >= 0.0 && margin_m <= 1000.0)) err << "margin_m must be in [0, 1000]; ";
  for (const Eigen::Vector3d& p : include_points)
    if (!p.allFinite()) {
      err << "include_points must be finite; ";
      break;
    }
  if (!esdf.validate(&esdf_why)) err << "esdf: " << esdf_why << "; ";
  if (!(max_memory_mb > 0.0)) err << "max_memory_mb must be positive; ";
  const std::string s = err.str();
  if (why) *why = s.empty() ? "" : s.substr(0, s.size() - 2);
  return s.empty();
}

std::shared_ptr<const TruthMap> TruthMap::build(const std::vector<Eigen::Vector3d>& points, const Config& config,
                                                std::string* error, BuildStats* stats_out) {
  const auto t0 = std::chrono::steady_clock::now();
  std::string why;
  if (!config.validate(&why)) {
    if (error) *error = "invalid truth map config: " + why;
    return nullptr;
  }
  BuildStats stats;
  stats.points = points.size();
  Eigen::Vector3d lo = Eigen::Vector3d::Constant(INFINITY), hi = Eigen::Vector3d::Constant(-INFINITY);
  // Bounds of the occupied voxels (cubes), not only of their centres.
  const double half = 0.5 * config.resolution_m;
  for (const Eigen::Vector3d& p : points) {
    if (!p.allFinite()) {
      ++stats.invalid_points;
      continue;
    }
    lo = lo.cwiseMin(p - Eigen::Vector3d::Constant(half));
    hi = hi.cwiseMax(p + Eigen::Vector3d::Constant(half));
  }
  for (const Eigen::Vector3d& p : config.include_points) {
    lo = lo.cwiseMin(p);
    hi = hi.cwiseMax(p);
  }
  if (!lo.allFinite()) lo = hi = Eigen::Vector3d::Zero();  // nothing at all: a map around the origin
  OccupancyMap::Config oc;
  oc.resolution_m = config.resolution_m;
  oc.origin_m = lo - Eigen::Vector3d::Constant(config.margin_m);
  // At least one voxel per axis; one more so that rounding the origin down never cuts the top.
  oc.size_m = (hi - lo).array() + 2.0 * config.margin_m + 2.0 * config.resolution_m;
  oc.max_memory_mb = config.max_memory_mb;
  std::shared_ptr<TruthMap> map(new TruthMap());
  map->occupancy_ = std::shared_ptr<OccupancyMap>(OccupancyMap::create(oc, &why));
  if (!map->occupancy_) {
    if (error) *error = "cannot create the truth map window: " + why;
    return nullptr;
  }
  OccupancyMap& occ = *map->occupancy_;
  const GridGeometry& g = occ.geometry();
  const VoxelBox w = g.windowBox();
  Eigen::Vector3i i;
  for (i.z() = w.min.z(); i.z() <= w.max.z(); ++i.z())
    for (i.y() = w.min.y(); i.y() <= w.max.y(); ++i.y())
      for (i.x() = w.min.x(); i.x() <= w.max.x(); ++i.x()) occ.setState(i, VoxelState::kFree);
  for (const Eigen::Vector3d& p : points) {
    if (!p.allFinite()) continue;
    const Eigen::Vector3i v = g.indexOf(p);
    if (!occ.isOccupied(v) && occ.setState(v, VoxelState::kOccupied)) ++stats.occupied_voxels;
  }
  map->occupied_ = stats.occupied_voxels;
  map->esdf_ = EsdfMap::create(config.esdf, map->occupancy_, &why);
  if (!map->esdf_) {
    if (error) *error = "cannot create the truth ESDF: " + why;
    return nullptr;
  }
  map->esdf_->updateAll();
  stats.build_ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
  if (stats_out) *stats_out = stats;
  return map;
}

double TruthMap::obstacleDistance(const Eigen::Vector3d& p, double exact_within_m) const {
  if (!p.allFinite()) return NAN;
  const GridGeometry& g = geometry();
  const double res = g.resolution();
  const double r = std::max(0.0, exact_within_m);
  // Broad phase: a lower bound from the ESDF, or from the distance to the window (every obstacle
  // lies inside it).
  double bound;
  const Eigen::Vector3i v = g.indexOf(p);
  float d_center;
  if (g.inWindow(p) && esdf_->voxelDistance(v, &d_center)) {
    if (d_center <= 0.0f) return 0.0;  // inside an occupied voxel
    bound = double(d_center) - (p - g.centerOf(v)).norm() - 0.5 * std::sqrt(3.0) * res;
  } else {
    bound = (g.windowMin() - p).cwiseMax(p - g.windowMax()).cwiseMax(0.0).norm();
  }
  if (bound >= r) return bound;
  // Narrow phase: every voxel whose cube comes within r of p has its index in this box.
  const VoxelBox box =
      VoxelBox::fromCorners(g.indexOf(p - Eigen::Vector3d::Constant(r)), g.indexOf(p + Eigen::Vector3d::Constant(r)))
          .intersection(g.windowBox());
  double best = r;
  Eigen::Vector3i k;
  for (k.z() = box.min.z(); k.z() <= box.max.z(); ++k.z())
    for (k.y() = box.min.y(); k.y() <= box.max.y(); ++k.y())
      for (k.x() = box.min.x(); k.x() <= box.max.x(); ++k.x())
        if (occupancy_->isOccupied(k)) best = std::min(best, distanceToVoxel(p, k, res));
  return best;  // < r: exact; == r: nothing within r
}

bool TruthMap::sphereInCollision(const Eigen::Vector3d& p, double radius_m, double* distance_m) const {
  const double d = obstacleDistance(p, radius_m);
  if (distance_m) *distance_m = d;
  return d < radius_m;
}

}  // namespace topo_planner
