#pragma once
// The topological roadmap of the paper's Alg. 1 (Sect. IV-B), after Visibility-PRM (Simeon et al.
// 2000): guards explore the free space and never see each other; a connector joins exactly two
// guards, unless a connector they already share gives an equivalent path under uniform visibility
// deformation, in which case the shorter of the two is kept (Replace). Samples are drawn uniformly
// in a box around the start-goal segment, aligned with it.
//
// The graph is an arena of nodes addressed by index (no pointers between nodes), rebuilt by each
// build(): nothing survives a call, so repeated planning never accumulates memory.

#include <chrono>
#include <random>
#include <vector>

#include "topo_planner/path_searching/path.h"
#include "topo_planner/path_searching/visibility.h"

namespace topo_planner {

class TopologicalRoadmap {
 public:
  struct Config {
    /// Sampling box beyond the start-goal segment: (r_x along it, r_y sideways, r_z up) [m].
    Eigen::Vector3d sample_inflation_m{1.0, 3.5, 1.5};
    int max_samples = 160;    ///< N_max: samples drawn per build (sized for the medium benchmark density)
    /// When N_max samples leave start and goal unconnected, sampling goes on in chunks of
    /// max_samples until they connect or this many more were drawn (0 = never).
    int max_extra_samples = 1600;
    /// Coverage criterion of Visibility-PRM: stop after this many consecutive samples that added
    /// no guard or connector and replaced none (0 = off, draw all N_max).
    int max_unproductive_samples = 0;
    double max_time_s = 0.0;  ///< t_max: stop sampling after this long; 0 = by count only [s]
    int max_raw_paths = 300;  ///< cap on the paths the depth-first search extracts
    int max_path_nodes = 20;  ///< longest path (in nodes) the depth-first search follows
    int max_search_expansions = 20000;  ///< budget of node expansions of the depth-first search
    double min_z_m = -1e9;    ///< height band (a geofence): samples outside it are rejected [m]
    double max_z_m = 1e9;
  };
  enum class NodeType : uint8_t { kGuard, kConnector };
  struct Node {
    Eigen::Vector3d position;
    NodeType type;
    std::vector<int> neighbors;
  };
  struct Stats {
    int samples = 0;           ///< drawn
    int rejected = 0;          ///< too close to obstacles or out of the map
    int guards = 0;            ///< start and goal included
    int connectors = 0;
    int replaced = 0;          ///< connectors moved to a shorter equivalent position
    bool timed_out = false;
    bool covered = false;      ///< stopped by max_unproductive_samples
  };

  static constexpr int kStart = 0;  ///< node index of the start guard
  static constexpr int kGoal = 1;   ///< node index of the goal guard

  explicit TopologicalRoadmap(const Config& config) : config_(config) {}

  /// Alg. 1 from start to goal (both assumed free): N_max samples.
  Stats build(const Eigen::Vector3d& start, const Eigen::Vector3d& goal, const VisibilityChecker& checker,
              std::mt19937* rng);
  /// Alg. 1 continued on the current roadmap for `samples` more samples (adds to *stats).
  void extend(int samples, const VisibilityChecker& checker, std::mt19937* rng, Stats* stats);
  /// Depth-first search with a visited list from the start to the goal guard (Sect. IV-B). Branches
  /// that cannot reach the goal within max_path_nodes (breadth-first hop counts) are pruned, and
  /// max_search_expansions bounds the work.
  std::vector<Path> extractPaths() const;

  const std::vector<Node>& nodes() const { return nodes_; }

 private:
  int addNode(const Eigen::Vector3d& p, NodeType type);
  void connect(int a, int b);
  struct SearchState {
    std::vector<int> stack;
    std::vector<char> on_stack;
    std::vector<int> hops_to_goal;  // breadth-first hop count to the goal; -1 = cannot reach it
    int expansions = 0;
  };
  void depthFirst(SearchState* s, std::vector<Path>* out) const;

  Config config_;
  std::vector<Node> nodes_;
  std::vector<int> guards_;
  // Sampling box of the current build.
  Eigen::Matrix3d rotation_ = Eigen::Matrix3d::Identity();
  Eigen::Vector3d centre_ = Eigen::Vector3d::Zero(), half_ = Eigen::Vector3d::Zero();
  std::chrono::steady_clock::time_point started_;
};

}  // namespace topo_planner
