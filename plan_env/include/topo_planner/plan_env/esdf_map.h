#pragma once
// Euclidean signed distance field over an OccupancyMap.
//
// At a free (or unknown) voxel the field is +distance from its centre to the nearest occupied voxel
// centre; at an occupied voxel it is -distance to the nearest non-occupied voxel centre. The
// interpolated zero crossing therefore lies on the voxel faces, half a voxel from the centres.
// Values are exact (checked against brute force in the tests) and truncated at +-max_distance_m.
//
// Computation: separable, exact, for the positive and the negative field, over a thread pool.
// Along x, a two-sweep 1-D distance to the nearest site. Along y and z, the squared distance is
// min over r of f(i + r) + r^2; because values are truncated at R = max_distance_m / resolution
// voxels, only |r| <= R matters, and for R <= kMaxWindowVoxels this windowed minimum is run over
// whole rows of x (contiguous, vectorised, no branches). Larger R use the exact lower-envelope
// transform of Felzenszwalb & Huttenlocher (2012) along each line instead. Because values are
// truncated at D = max_distance_m, a change of occupancy in box C can only alter voxels within D of
// C, whose exact values in turn depend only on voxels within D of those: update() recomputes the
// box C + D from the input box C + 2D, and the result equals a full recompute.
//
// The inflated occupancy used for planning is derived from the field: a voxel is inflated-occupied
// when its distance is at most inflate_radius_m (spherical inflation, exact).
//
// Thread safety: as OccupancyMap; update() writes, queries read. The pool is internal to update().

#include <functional>
#include <memory>
#include <string>
#include <vector>

#include "topo_planner/plan_env/occupancy_map.h"
#include "topo_planner/plan_env/thread_pool.h"

namespace topo_planner {

/// Distance at a point, with its gradient (trilinear interpolation of the voxel-centre values).
struct DistanceQuery {
  QueryStatus status = QueryStatus::kOutOfMap;
  double distance = 0.0;                              ///< [m]; valid for kOk and kUnknown
  Eigen::Vector3d gradient = Eigen::Vector3d::Zero();  ///< d distance / d point
};

struct EsdfUpdateStats {
  VoxelBox written_box;  ///< voxels whose distance was recomputed
  VoxelBox input_box;    ///< voxels read to compute them
  bool full = false;     ///< the whole window was recomputed
};

class EsdfMap {
 public:
  /// Largest truncation radius [voxels] handled by the windowed minimum (see above).
  static constexpr int kMaxWindowVoxels = 32;

  struct Config {
    double max_distance_m = 2.0;    ///< distances are truncated here; bounds the incremental update [m]
    double inflate_radius_m = 0.2;  ///< voxels at most this far from an obstacle are inflated-occupied [m]
    bool unknown_as_occupied = false;  ///< treat unknown voxels as obstacles when building the field
    int num_threads = 2;            ///< workers of the internal pool (the caller included)

    bool validate(std::string* why) const;
  };

  /// nullptr with a reason if the config is invalid or occupancy is null.
  static std::unique_ptr<EsdfMap> create(const Config& config, std::shared_ptr<const OccupancyMap> occupancy,
                                         std::string* error);

  const Config& config() const { return config_; }
  const OccupancyMap& occupancy() const { return *occupancy_; }
  const GridGeometry& geometry() const { return occupancy_->geometry(); }

  /// Recomputes the whole field.
  EsdfUpdateStats updateAll();
  /// Brings the field up to date after the occupancy changed inside `changed` (e.g. a
  /// FusionResult::changed_box). Falls back to updateAll() when the window has moved.
  EsdfUpdateStats update(const VoxelBox& changed);

  /// Distance at a voxel centre (kUnknown still gives the value computed with unknown as free).
  QueryStatus distance(const Eigen::Vector3i& index, double* distance) const;
  /// Distance at a voxel centre, no unknown check: false when out of the window. The fast path
  /// of collision checks.
  bool voxelDistance(const Eigen::Vector3i& index, float* distance) const {
    if (!geometry().inWindow(index)) return false;
    *distance = distance_[geometry().address(index)];
    return true;
  }
  /// Trilinearly interpolated distance and its gradient. kOutOfMap when any of the 8 voxels
  /// around the point is outside the window; kUnknown when one is unknown (values still filled).
  DistanceQuery query(const Eigen::Vector3d& point) const;
  /// The trilinear distance and gradient of query() without its unknown-voxel check: false when any
  /// of the 8 voxels is outside the window or the point is not finite. The fast path of the
  /// optimiser's collision cost.
  bool interpolate(const Eigen::Vector3d& point, double* distance, Eigen::Vector3d* gradient) const;
  /// Distance of the nearest voxel centre, without interpolation.
  DistanceQuery nearest(const Eigen::Vector3d& point) const;

  /// Inflated occupancy: distance <= inflate_radius_m. Out-of-map voxels count as occupied.
  bool isInflatedOccupied(const Eigen::Vector3i& index) const;
  bool isInflatedOccupied(const Eigen::Vector3d& point) const;

  /// Raw distances in ring-buffer order [m]; for tests.
  const std::vector<float>& distances() const { return distance_; }

 private:
  EsdfMap(const Config& config, std::shared_ptr<const OccupancyMap> occupancy);
  void compute(const VoxelBox& input, const VoxelBox& output);
  void computeWindowed(const VoxelBox& input, const VoxelBox& output);
  void computeEnvelope(const VoxelBox& input, const VoxelBox& output);
  void firstPassAlongX(const VoxelBox& input);
  struct LineScratch;
  void forLines(int lines, const std::function<void(int line, LineScratch& s)>& fn);
  // Writes the signed, truncated distance of one output row from squared voxel distances.
  void writeRow(const Eigen::Vector3i& first, int n, const float* pos_sq, const float* neg_sq, float* scratch);

  Config config_;
  std::shared_ptr<const OccupancyMap> occupancy_;
  Eigen::Vector3i computed_origin_;  // window origin the field was computed for
  int margin_voxels_;
  int32_t cap_sq_voxels_;  // squared truncation distance in voxels^2, rounded up
  std::vector<float> distance_;
  ThreadPool pool_;
  // Scratch reused across updates: box-local squared distances of the two fields, and per-worker
  // line buffers.
  // Box-local squared distances in voxels^2 (x fastest), +inf for "at or beyond the truncation".
  std::vector<float> pos_sq_, neg_sq_;
  struct LineScratch {
    std::vector<int32_t> f, d, v;
    std::vector<int64_t> zn, zd;
    std::vector<uint8_t> site;
    std::vector<float> row_a, row_b, row_c, plane;
  };
  std::vector<LineScratch> scratch_;
};

/// Walks up the distance field from `from`: steps of half a voxel along the normalised gradient of
/// the interpolated distance, re-evaluated at every step, until `done(point)` holds. On true, `path`
/// holds the walk, `from` first and the first point where done() holds last. False (path holds the
/// walk so far) when the gradient vanishes (a ridge between obstacles or beyond the truncation), the
/// walk leaves the map, a step would lower the distance, or the walk is longer than max_length_m.
/// How a vehicle or a search start gets out of an obstacle's clearance by the shortest way.
bool ascendDistance(const EsdfMap& map, const Eigen::Vector3d& from,
                    const std::function<bool(const Eigen::Vector3d&)>& done, double max_length_m,
                    std::vector<Eigen::Vector3d>* path);

}  // namespace topo_planner
