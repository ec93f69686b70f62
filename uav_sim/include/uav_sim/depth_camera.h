#pragma once
// Simulated depth camera: renders the depth image a pinhole camera sees of a known voxel map, with
// occlusion (each pixel's ray stops at the first occupied voxel; the reference simulator's CPU
// sensor sees through obstacles). Rays are sphere-traced on the map's distance field: from a voxel
// whose centre is d from the nearest obstacle centre, every point within d - sqrt(3)/2 res of that
// centre lies in a free voxel, so the ray jumps to the edge of that ball; near obstacles it steps
// voxel by voxel, and the depth is that of the entry point into the hit voxel. Optional Gaussian
// noise grows with the square of the depth (structured-light/stereo sensors), seeded.

#include <Eigen/Geometry>
#include <cstdint>
#include <random>
#include <vector>

#include "plan_env/depth_image.h"
#include "plan_env/esdf_map.h"

namespace topo_planner {

class DepthCamera {
 public:
  struct Config {
    PinholeCamera camera;           ///< intrinsics and size (640 x 480 by default)
    double min_range_m = 0.1;       ///< closer surfaces read as invalid (NaN) [m]
    double max_range_m = 6.0;       ///< nothing within it reads as +inf (no return) [m]
    double noise_stddev_at_1m = 0.0;  ///< depth noise sigma at 1 m, scaling with depth^2 [m]
    uint32_t seed = 1;              ///< noise generator seed
  };

  /// The map must outlive the camera; it is only read.
  DepthCamera(const Config& config, const EsdfMap& truth);
  const Config& config() const { return config_; }

  /// Depth [m] per pixel, row-major, float (32FC1 semantics: NaN invalid, +inf no return).
  /// Returns false (image untouched) for a non-finite pose.
  bool render(const Eigen::Isometry3d& T_world_camera, std::vector<float>* depth);
  /// The same image as 16UC1 millimetres (0 = no return or invalid), saturating at 65535.
  static void toMillimetres(const std::vector<float>& depth, std::vector<uint16_t>* mm);

 private:
  // Distance along the unit ray from o to the first occupied voxel, or +inf within max_range.
  double castRay(const Eigen::Vector3d& o, const Eigen::Vector3d& u) const;

  Config config_;
  const EsdfMap& truth_;
  std::mt19937 rng_;
};

}  // namespace topo_planner
