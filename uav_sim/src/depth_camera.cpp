#include "uav_sim/depth_camera.h"

#include "plan_env/raycast.h"

#include <algorithm>
#include <cmath>

namespace topo_planner {

DepthCamera::DepthCamera(const Config& config, const EsdfMap& truth) : config_(config), truth_(truth), rng_(config.seed) {}

double DepthCamera::castRay(const Eigen::Vector3d& o, const Eigen::Vector3d& u) const {
  const GridGeometry& g = truth_.geometry();
  const double res = g.resolution(), half_diagonal = 0.5 * std::sqrt(3.0) * res, nudge = 1e-6 * res;
  const double max_t = config_.max_range_m;
  double t = 0.0;
  while (t <= max_t) {
    const Eigen::Vector3d p = o + u * t;
    const Eigen::Vector3i v = g.indexOf(p);
    float d;
    if (!truth_.voxelDistance(v, &d)) return INFINITY;  // left the map: nothing more to see
    if (d <= 0.0f) {
      // Occupied: depth of the entry point into this voxel along the ray.
      const Eigen::Vector3d lo = v.cast<double>() * res, hi = lo + Eigen::Vector3d::Constant(res);
      double t_enter = 0.0;
      for (int k = 0; k < 3; ++k)
        if (std::abs(u[k]) > 1e-12) t_enter = std::max(t_enter, std::min((lo[k] - o[k]) / u[k], (hi[k] - o[k]) / u[k]));
      return t_enter <= max_t ? t_enter : INFINITY;
    }
    double next = t + distanceToBallExit(p, u, g.centerOf(v), double(d) - half_diagonal);
    if (next <= t + nudge) next = t + distanceToVoxelExit(p, u, v, res) + nudge;  // into the next voxel
    t = next;
  }
  return INFINITY;
}

bool DepthCamera::render(const Eigen::Isometry3d& T_world_camera, std::vector<float>* depth) {
  if (!T_world_camera.matrix().allFinite()) return false;
  const PinholeCamera& cam = config_.camera;
  depth->assign(size_t(cam.width) * size_t(cam.height), INFINITY);
  const Eigen::Matrix3d R = T_world_camera.linear();
  const Eigen::Vector3d o = T_world_camera.translation();
  std::normal_distribution<double> noise(0.0, 1.0);
  for (int v = 0; v < cam.height; ++v)
    for (int u = 0; u < cam.width; ++u) {
      const Eigen::Vector3d ray_c((u - cam.cx) / cam.fx, (v - cam.cy) / cam.fy, 1.0);
      const double len = ray_c.norm();  // metres along the ray per metre of depth
      const double t = castRay(o, R * (ray_c / len));
      float& out = (*depth)[size_t(v) * cam.width + u];
      if (std::isinf(t)) continue;
      double z = t / len;
      if (config_.noise_stddev_at_1m > 0.0) z += config_.noise_stddev_at_1m * z * z * noise(rng_);
      out = (z < config_.min_range_m || t / len < config_.min_range_m) ? NAN : float(z);
    }
  return true;
}

void DepthCamera::toMillimetres(const std::vector<float>& depth, std::vector<uint16_t>* mm) {
  mm->resize(depth.size());
  for (size_t i = 0; i < depth.size(); ++i) {
    const float d = depth[i];
    (*mm)[i] = std::isfinite(d) && d > 0.0f ? uint16_t(std::min(65535.0f, std::round(d * 1000.0f))) : uint16_t(0);
  }
}

}  // namespace topo_planner
