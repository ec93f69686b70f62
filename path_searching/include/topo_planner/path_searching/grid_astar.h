#pragma once
// Grid A* (26-connected, Euclidean step costs, weighted Euclidean heuristic) on the map's voxels, free meaning
// at least clearance_m from obstacles: the single guide path of the baselines and the fallback of
// the replanner. Searches a box around start and goal; its buffers are kept between calls and
// reset by a generation stamp, not reallocated.

#include <cstdint>
#include <vector>

#include "topo_planner/path_searching/path.h"
#include "topo_planner/path_searching/search_status.h"
#include "topo_planner/path_searching/visibility.h"

namespace topo_planner {

class GridAStar {
 public:
  struct Config {
    double clearance_m = 0.3;        ///< [m]
    bool unknown_is_free = true;
    double search_margin_m = 3.0;    ///< the search box is the start-goal box plus this on each side [m]
    /// A box that holds no way (kNoPath: a wall whose opening lies farther aside) is searched again
    /// with the margin doubled, up to this many times (each with the full expansion budget).
    int margin_doublings = 0;
    int max_expansions = 400000;     ///< budget
    /// The heuristic is this times the Euclidean distance to the goal (weighted A*: a path at most
    /// this factor longer than the shortest, found with far fewer expansions; the replanner shortens
    /// it anyway). 1: plain A*, the shortest grid path. >= 1.
    double heuristic_weight = 1.5;
    double min_z_m = -1e9;           ///< height band (a geofence): the box keeps to it, and to start and goal [m]
    double max_z_m = 1e9;
  };
  struct Result {
    SearchStatus status = SearchStatus::kInvalidInput;
    Path path;  ///< start, voxel centres, goal
    int expansions = 0;
  };

  explicit GridAStar(const Config& config) : config_(config) {}
  Result search(const EsdfMap& map, const Eigen::Vector3d& start, const Eigen::Vector3d& goal);

 private:
  Result searchBox(const EsdfMap& map, const Eigen::Vector3d& start, const Eigen::Vector3d& goal, double margin_m);

  Config config_;
  std::vector<float> g_;
  std::vector<int32_t> parent_;
  std::vector<uint32_t> stamp_;
  uint32_t generation_ = 0;
};

}  // namespace topo_planner
