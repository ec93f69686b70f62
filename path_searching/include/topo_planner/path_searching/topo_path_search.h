#pragma once
// The front end of the replanner (paper, Sect. IV and V): a topological roadmap between start and
// goal, depth-first path extraction, shortening (Alg. 2), pruning of equivalent paths, and selection
// of the K_max shortest distinct ones, dropping those longer than r_max times the shortest.
// Pruning and selection run together in order of length: a path is kept unless it is equivalent to
// a shorter kept one, and the walk stops at K_max kept paths or at r_max, which selects exactly what
// pruning all paths first would, with far fewer equivalence checks. Only the max_shortened_paths
// shortest raw paths are shortened.
//
// Repeatable: the random generator is seeded from Config::seed at every call. Counts bound the work
// (TopologicalRoadmap::Config::max_samples); a time limit can be added for online use.

#include <string>
#include <utility>
#include <vector>

#include "topo_planner/path_searching/path_shortener.h"
#include "topo_planner/path_searching/search_status.h"
#include "topo_planner/path_searching/topological_roadmap.h"

namespace topo_planner {

/// The roadmap as plain data, for visualisation (rviz markers in the nodes).
struct RoadmapGraph {
  std::vector<Eigen::Vector3d> guards;
  std::vector<Eigen::Vector3d> connectors;
  std::vector<std::pair<Eigen::Vector3d, Eigen::Vector3d>> edges;
};

struct TopoSearchStats {
  TopologicalRoadmap::Stats roadmap;
  int raw_paths = 0;        ///< from the depth-first search
  int shortened_paths = 0;  ///< after Alg. 2 (fallbacks to the raw path included)
  int shortening_fallbacks = 0;
  int distinct_paths = 0;   ///< distinct paths met while selecting (pruning stops at K_max)
  int selected_paths = 0;   ///< after the K_max / r_max selection
  double roadmap_ms = 0.0, extraction_ms = 0.0, shortening_ms = 0.0, pruning_ms = 0.0, total_ms = 0.0;
};

struct TopoSearchResult {
  SearchStatus status = SearchStatus::kInvalidInput;
  std::vector<Path> paths;      ///< selected guide paths, shortest first
  std::vector<Path> raw_paths;  ///< as extracted, for visualisation
  RoadmapGraph roadmap;
  TopoSearchStats stats;
};

class TopoPathSearch {
 public:
  struct Config {
    TopologicalRoadmap::Config roadmap;
    double clearance_m = 0.3;       ///< samples and segments keep this distance from obstacles [m]
    bool unknown_is_free = true;    ///< plan through unobserved space (replanning in a partial map)
    int max_paths = 5;              ///< K_max
    int max_shortened_paths = 16;   ///< only the shortest raw paths are shortened (Alg. 2)
    double max_length_ratio = 2.0;  ///< r_max: drop paths longer than this times the shortest
    uint32_t seed = 1;              ///< the generator is re-seeded with it at every search
    bool keep_raw_paths = false;    ///< fill TopoSearchResult::raw_paths and roadmap

    bool validate(std::string* why) const;
  };

  explicit TopoPathSearch(const Config& config) : config_(config), roadmap_(config.roadmap) {}
  const Config& config() const { return config_; }

  /// seed_offset is added to Config::seed: a caller retrying the same problem draws another roadmap.
  TopoSearchResult search(const EsdfMap& map, const Eigen::Vector3d& start, const Eigen::Vector3d& goal,
                          uint32_t seed_offset = 0);

 private:
  Config config_;
  TopologicalRoadmap roadmap_;
};

}  // namespace topo_planner
