#pragma once
// Probabilistic occupancy grid fused from depth images or point clouds.
//
// Each voxel holds a clamped log-odds value (Thrun et al., Probabilistic Robotics, ch. 9) or
// "unknown". Rays are traced from the measured point back to the sensor with a 3-D DDA; the end
// voxel gets a hit, the voxels on the way a miss; a ray longer than max_ray_length_m is cut there
// and marks free space only. Each voxel is updated at most once per frame, hits winning over
// misses. As in Fast-Planner (Zhou et al. RA-L 2019), a ray stops when it reaches a voxel another
// ray of the same frame has already freed (rays converge towards the camera), which bounds a frame
// to a few thousand voxel updates.
//
// Depth images take their free space by projection instead (project_free_space; the projective
// integration of voxblox and nvblox): every window voxel whose centre lies in the camera's view,
// within max_ray_length_m and in front of the nearest surface measured on the pixels around its
// projection, is seen free. Merged rays leave about half of the voxels in view unknown (a ray that
// stops on another's trail leaves its own voxels on the way unseen: measured 30-54% per metre of
// range for one frame of open space), and from a hover the same ones every frame: a vehicle that
// must see its way free, or keep a ball around it observed, waited on voxels it had in view. The
// hits stay per measured point. Rays without merging see everything too, at 20x the cost. Off by
// default for now: with it, the fault_odom_blackout rostest held after the blackout (2 of 2 runs).
//
// Storage is a ring buffer over GridGeometry: the window can follow the vehicle (setOriginIndex /
// recenter) without moving memory. Memory: 8 bytes per voxel (a 40 x 20 x 5 m map at 0.1 m, 4M
// voxels, takes 32 MB); the ESDF layer adds 4 bytes per voxel and, during a full update, 8 bytes
// per voxel of scratch: 20 bytes per voxel at the peak (80 MB for that map).
//
// Thread safety: none inside. One writer at a time, and no reader while it writes; the owner
// (e.g. the mapping node) serialises them, typically with a std::shared_mutex.

#include <Eigen/Geometry>
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include "topo_planner/plan_env/depth_image.h"
#include "topo_planner/plan_env/grid_geometry.h"
#include "topo_planner/plan_env/map_status.h"

namespace topo_planner {

enum class VoxelState : uint8_t { kUnknown, kFree, kOccupied, kOutOfMap };
const char* toString(VoxelState state);

/// What a fusion call did.
struct FusionResult {
  MapStatus status = MapStatus::kSuccess;
  VoxelBox touched_box;  ///< every voxel updated this call lies in it
  VoxelBox changed_box;  ///< every voxel whose state (unknown/free/occupied) changed lies in it
  int rays = 0;           ///< rays traced
  int invalid = 0;        ///< pixels/points skipped: NaN, -inf, zero, closer than min_ray_length_m
  int voxels_updated = 0;
  int voxels_hit = 0;
};

class OccupancyMap {
 public:
  struct Config {
    double resolution_m = 0.1;                    ///< voxel edge [m]
    Eigen::Vector3d size_m{20.0, 20.0, 5.0};      ///< window extent [m], rounded up to whole voxels
    Eigen::Vector3d origin_m{-10.0, -10.0, -1.0};  ///< window lower corner [m], snapped to the voxel grid

    double prob_hit = 0.70;       ///< P(occupied | ray ends in voxel)
    double prob_miss = 0.35;      ///< P(occupied | ray passes through voxel)
    double prob_min = 0.12;       ///< lower clamp of the occupancy probability
    double prob_max = 0.97;       ///< upper clamp
    double prob_occupied = 0.80;  ///< a voxel is occupied above this probability

    double min_ray_length_m = 0.1;  ///< shorter returns are ignored (sensor blind zone) [m]
    double max_ray_length_m = 4.5;  ///< longer rays are cut here and mark free space only [m]
    int depth_pixel_skip = 2;       ///< fuse every n-th pixel in u and v (1 = all)
    int max_image_pixels = 4096 * 4096;  ///< larger images are refused
    bool merge_rays = true;  ///< stop a ray at a voxel another ray of the frame has freed (see class comment)
    bool project_free_space = true;   ///< depth images: free space by projection (see class comment); false: rays
    double max_memory_mb = 4096.0;  ///< refuse maps whose layers would need more [MB]

    /// True when every field is in range; otherwise says why.
    bool validate(std::string* why) const;
  };

  /// Peak bytes per voxel of the occupancy and ESDF layers, ESDF update scratch included (used by
  /// the memory check).
  static constexpr size_t kBytesPerVoxel = 20;

  /// Builds a map; nullptr with a reason for an invalid config or one too large for memory.
  static std::unique_ptr<OccupancyMap> create(const Config& config, std::string* error);

  const Config& config() const { return config_; }
  const GridGeometry& geometry() const { return geometry_; }

  /// Fuses a depth image seen from camera pose T_world_camera (optical frame). On any status but
  /// kSuccess the map is unchanged.
  FusionResult fuseDepthImage(const DepthImageView& image, const PinholeCamera& camera,
                              const Eigen::Isometry3d& T_world_camera);
  /// Fuses world-frame points measured from sensor_origin. NaN points are skipped and counted.
  FusionResult fusePointCloud(const std::vector<Eigen::Vector3d>& points_world, const Eigen::Vector3d& sensor_origin);

  VoxelState state(const Eigen::Vector3i& index) const;
  VoxelState state(const Eigen::Vector3d& point) const;
  bool isOccupied(const Eigen::Vector3i& index) const { return state(index) == VoxelState::kOccupied; }
  /// Largest radius isKnownWithin() accepts [m] (a bound on its work per call).
  static constexpr double kMaxKnownRadius = 1.0;
  /// True when every window voxel whose cube comes closer than `radius` to `point` has been observed
  /// (free or occupied): a body of that radius there touches no unobserved space. Voxels outside
  /// the window are not checked (the window's edge is the map's). False for a point outside the
  /// window, a NaN/inf point, or a radius outside [0, kMaxKnownRadius]. `assume_known(centre)`, when
  /// given, exempts unknown voxels by their centre (e.g. the space a vehicle stood in).
  bool isKnownWithin(const Eigen::Vector3d& point, double radius,
                     const std::function<bool(const Eigen::Vector3d&)>& assume_known = {}) const;
  /// Occupancy probability of a voxel; NaN when unknown or out of the map.
  double probability(const Eigen::Vector3i& index) const;

  /// Sets a voxel as known free or occupied (clamped probabilities), e.g. when loading a map file.
  /// Returns false if the index is out of the window.
  bool setState(const Eigen::Vector3i& index, VoxelState state);
  /// Forgets everything: all voxels unknown.
  void clear();

  /// Largest |origin index| a window may move to (indices stay far from int overflow).
  static constexpr int kMaxOriginIndex = 1 << 28;
  /// Moves the window so that its lowest voxel is origin_index; voxels that leave are forgotten and
  /// the ones that enter are unknown. Returns the changed box (the whole window if it moved; empty,
  /// with the map unchanged, if it did not move or origin_index exceeds kMaxOriginIndex).
  VoxelBox setOriginIndex(const Eigen::Vector3i& origin_index);
  /// Moves the window so that `center` is at its middle (x, y and z); refused (empty box, map
  /// unchanged) for NaN/inf or out-of-range centres.
  VoxelBox recenter(const Eigen::Vector3d& center);

  /// Calls fn(global_index) for every occupied voxel in the window.
  template <typename Fn>
  void forEachOccupied(Fn&& fn) const;
  size_t countState(VoxelState state) const;

  /// For n voxels from `start` along +x (all in the window): out[i] = 1 if the voxel is occupied,
  /// or unknown and unknown_is_site. The ESDF reads the grid through this.
  void readSiteLineX(const Eigen::Vector3i& start, int n, bool unknown_is_site, uint8_t* out) const;

  /// Raw log-odds storage (ring-buffer order); for tests and checksums.
  const std::vector<float>& logOdds() const { return log_odds_; }

 private:
  explicit OccupancyMap(const Config& config);
  bool isOccupiedValue(float l) const { return l > occupied_log_; }
  bool isUnknownValue(float l) const { return l < unknown_threshold_; }
  VoxelState stateOfValue(float l) const {
    return isUnknownValue(l) ? VoxelState::kUnknown : (isOccupiedValue(l) ? VoxelState::kOccupied : VoxelState::kFree);
  }
  // Traces one ray from `end` back to `origin` (both world frame); is_hit marks the end voxel occupied.
  void castRay(const Eigen::Vector3d& origin, const Eigen::Vector3d& end, bool is_hit, FusionResult* result);
  // The end voxel of a ray only (a hit; nothing for a max-range ray), counted as a ray when the
  // segment meets the window: the hits of a projective frame.
  void markRayEnd(const Eigen::Vector3d& origin, const Eigen::Vector3d& end, bool is_hit, FusionResult* result);
  // Marks free every window voxel in view in front of the image's surfaces (see class comment).
  void projectFreeSpace(const DepthImageView& image, const PinholeCamera& camera,
                        const Eigen::Isometry3d& T_world_camera);
  void beginFrame();
  void applyFrame(FusionResult* result);

  Config config_;
  GridGeometry geometry_;
  float hit_log_, miss_log_, min_log_, max_log_, occupied_log_;
  float unknown_value_, unknown_threshold_;
  std::vector<float> log_odds_;
  // Per-voxel frame stamp: (frame << 1) | hit. Lets a frame update each voxel once.
  std::vector<uint32_t> stamp_;
  uint32_t frame_ = 0;
  struct Touched {
    size_t address;
    Eigen::Vector3i index;
  };
  std::vector<Touched> touched_;  // voxels touched in the current frame
};

template <typename Fn>
void OccupancyMap::forEachOccupied(Fn&& fn) const {
  const Eigen::Vector3i lo = geometry_.originIndex();
  const Eigen::Vector3i s = geometry_.size();
  Eigen::Vector3i i;
  for (i.z() = lo.z(); i.z() < lo.z() + s.z(); ++i.z())
    for (i.y() = lo.y(); i.y() < lo.y() + s.y(); ++i.y())
      for (i.x() = lo.x(); i.x() < lo.x() + s.x(); ++i.x())
        if (isOccupiedValue(log_odds_[geometry_.address(i)])) fn(static_cast<const Eigen::Vector3i&>(i));
}

}  // namespace topo_planner
