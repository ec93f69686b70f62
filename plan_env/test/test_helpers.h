#pragma once
// Small synthetic scenes shared by the plan_env tests.

#include <Eigen/Geometry>
#include <cmath>
#include <cstdint>
#include <memory>
#include <random>
#include <vector>

#include "topo_planner/plan_env/depth_image.h"
#include "topo_planner/plan_env/esdf_map.h"
#include "topo_planner/plan_env/occupancy_map.h"

namespace topo_planner {
namespace test {

inline std::shared_ptr<OccupancyMap> makeMap(const Eigen::Vector3d& size_m, const Eigen::Vector3d& origin_m,
                                             double resolution_m = 0.1) {
  OccupancyMap::Config c;
  c.resolution_m = resolution_m;
  c.size_m = size_m;
  c.origin_m = origin_m;
  std::string err;
  return std::shared_ptr<OccupancyMap>(OccupancyMap::create(c, &err));
}

inline std::unique_ptr<EsdfMap> makeEsdf(std::shared_ptr<OccupancyMap> occ, double max_distance_m,
                                         bool unknown_as_occupied = false, int threads = 2) {
  EsdfMap::Config c;
  c.max_distance_m = max_distance_m;
  c.inflate_radius_m = std::min(0.2, 0.5 * max_distance_m);
  c.unknown_as_occupied = unknown_as_occupied;
  c.num_threads = threads;
  std::string err;
  return EsdfMap::create(c, occ, &err);
}

/// Sets every voxel of the window free or occupied at random (and unknown with p_unknown).
inline void randomFill(OccupancyMap* map, double p_occupied, std::mt19937* rng, double p_unknown = 0.0) {
  std::uniform_real_distribution<double> u(0.0, 1.0);
  const VoxelBox w = map->geometry().windowBox();
  Eigen::Vector3i i;
  for (i.z() = w.min.z(); i.z() <= w.max.z(); ++i.z())
    for (i.y() = w.min.y(); i.y() <= w.max.y(); ++i.y())
      for (i.x() = w.min.x(); i.x() <= w.max.x(); ++i.x()) {
        const double r = u(*rng);
        map->setState(i, r < p_unknown ? VoxelState::kUnknown
                                        : (r < p_unknown + p_occupied ? VoxelState::kOccupied : VoxelState::kFree));
      }
}

/// Camera at `position` looking along world +x (optical z = world x, optical x = -y, optical y = -z).
inline Eigen::Isometry3d cameraLookingAlongX(const Eigen::Vector3d& position) {
  Eigen::Matrix3d R;
  R << 0, 0, 1, -1, 0, 0, 0, -1, 0;
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  T.linear() = R;
  T.translation() = position;
  return T;
}

/// Ray parameter of the first intersection of p + t d (t > 0) with the box [lo, hi]; inf if none.
inline double intersectBox(const Eigen::Vector3d& p, const Eigen::Vector3d& d, const Eigen::Vector3d& lo,
                           const Eigen::Vector3d& hi) {
  double t0 = 0.0, t1 = INFINITY;
  for (int k = 0; k < 3; ++k) {
    if (std::abs(d[k]) < 1e-15) {
      if (p[k] < lo[k] || p[k] > hi[k]) return INFINITY;
      continue;
    }
    double a = (lo[k] - p[k]) / d[k], b = (hi[k] - p[k]) / d[k];
    if (a > b) std::swap(a, b);
    t0 = std::max(t0, a);
    t1 = std::min(t1, b);
    if (t0 > t1) return INFINITY;
  }
  return t0;
}

/// Renders a float depth image [m] of an axis-aligned box; pixels that miss it hold +inf (no return).
inline std::vector<float> renderBox(const PinholeCamera& cam, const Eigen::Isometry3d& T_w_c, const Eigen::Vector3d& lo,
                                    const Eigen::Vector3d& hi) {
  std::vector<float> depth(size_t(cam.width) * cam.height);
  for (int v = 0; v < cam.height; ++v)
    for (int u = 0; u < cam.width; ++u) {
      const Eigen::Vector3d ray_c((u - cam.cx) / cam.fx, (v - cam.cy) / cam.fy, 1.0);
      const double t = intersectBox(T_w_c.translation(), T_w_c.linear() * ray_c, lo, hi);
      depth[size_t(v) * cam.width + u] = std::isinf(t) ? INFINITY : float(t);  // ray_c.z = 1: t is the depth
    }
  return depth;
}

inline DepthImageView viewOf(const std::vector<float>& depth, const PinholeCamera& cam) {
  DepthImageView view;
  view.data = reinterpret_cast<const uint8_t*>(depth.data());
  view.width = cam.width;
  view.height = cam.height;
  view.row_step_bytes = size_t(cam.width) * sizeof(float);
  view.encoding = DepthEncoding::kFloat32;
  view.depth_scale = 1.0;
  return view;
}

inline PinholeCamera smallCamera() {
  PinholeCamera cam;
  cam.width = 160;
  cam.height = 120;
  cam.fx = cam.fy = 100.0;
  cam.cx = 79.5;
  cam.cy = 59.5;
  return cam;
}

}  // namespace test
}  // namespace topo_planner
