#pragma once
// Renders the depth image a pinhole camera would see of an occupancy map: one DDA ray per pixel to
// the first occupied voxel, so obstacles occlude what lies behind them. Used by the benchmark and
// the mapping demo to feed the fusion with realistic frames of a known map.

#include <Eigen/Geometry>
#include <cmath>
#include <vector>

#include "topo_planner/plan_env/depth_image.h"
#include "topo_planner/plan_env/occupancy_map.h"
#include "topo_planner/plan_env/raycast.h"

namespace topo_planner {

/// Depth [m] per pixel (row-major); +inf where nothing is hit within max_range_m.
inline std::vector<float> renderDepth(const OccupancyMap& truth, const PinholeCamera& cam,
                                      const Eigen::Isometry3d& T_world_camera, double max_range_m) {
  std::vector<float> depth(size_t(cam.width) * cam.height, INFINITY);
  const GridGeometry& g = truth.geometry();
  const Eigen::Vector3d o = T_world_camera.translation();
  for (int v = 0; v < cam.height; ++v)
    for (int u = 0; u < cam.width; ++u) {
      const Eigen::Vector3d ray_c((u - cam.cx) / cam.fx, (v - cam.cy) / cam.fy, 1.0);
      const Eigen::Vector3d dir = T_world_camera.linear() * ray_c;  // |dir| per unit depth
      const Eigen::Vector3d end = o + dir * (max_range_m / dir.norm());
      Eigen::Vector3i hit;
      bool found = false;
      traverseVoxels(o, end, g.resolution(), [&](const Eigen::Vector3i& i) {
        if (truth.state(i) != VoxelState::kOccupied) return true;
        hit = i;
        found = true;
        return false;
      });
      if (!found) continue;
      // Depth of the entry point into the hit voxel (slab test on its faces).
      const Eigen::Vector3d lo = hit.cast<double>() * g.resolution();
      const Eigen::Vector3d hi = lo + Eigen::Vector3d::Constant(g.resolution());
      double t_enter = 0.0;
      for (int k = 0; k < 3; ++k) {
        if (std::abs(dir[k]) < 1e-12) continue;
        const double a = (lo[k] - o[k]) / dir[k], b = (hi[k] - o[k]) / dir[k];
        t_enter = std::max(t_enter, std::min(a, b));
      }
      // A millimetre past the face, so that the measured point lies in the hit voxel, as a real
      // surface point would.
      depth[size_t(v) * cam.width + u] = float(t_enter + 1e-3 / dir.norm());  // ray_c.z = 1: t is the depth
    }
  return depth;
}

/// Camera optical frame looking along `forward` (world), with world +z up in the image.
inline Eigen::Isometry3d cameraLookingAt(const Eigen::Vector3d& position, const Eigen::Vector3d& forward) {
  const Eigen::Vector3d z = forward.normalized();
  Eigen::Vector3d x = z.cross(Eigen::Vector3d::UnitZ());
  if (x.norm() < 1e-6) x = Eigen::Vector3d::UnitX();
  x.normalize();
  const Eigen::Vector3d y = z.cross(x);
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  T.linear().col(0) = x;
  T.linear().col(1) = y;
  T.linear().col(2) = z;
  T.translation() = position;
  return T;
}

inline DepthImageView depthView(const std::vector<float>& depth, const PinholeCamera& cam) {
  DepthImageView view;
  view.data = reinterpret_cast<const uint8_t*>(depth.data());
  view.width = cam.width;
  view.height = cam.height;
  view.row_step_bytes = size_t(cam.width) * sizeof(float);
  view.encoding = DepthEncoding::kFloat32;
  view.depth_scale = 1.0;
  return view;
}

}  // namespace topo_planner
