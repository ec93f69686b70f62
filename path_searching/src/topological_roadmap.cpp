#include "path_searching/topological_roadmap.h"

#include <algorithm>
#include <cmath>

namespace topo_planner {

int TopologicalRoadmap::addNode(const Eigen::Vector3d& p, NodeType type) {
  nodes_.push_back({p, type, {}});
  return int(nodes_.size()) - 1;
}

void TopologicalRoadmap::connect(int a, int b) {
  nodes_[size_t(a)].neighbors.push_back(b);
  nodes_[size_t(b)].neighbors.push_back(a);
}

TopologicalRoadmap::Stats TopologicalRoadmap::build(const Eigen::Vector3d& start, const Eigen::Vector3d& goal,
                                                    const VisibilityChecker& checker, std::mt19937* rng) {
  Stats stats;
  nodes_.clear();
  guards_.clear();
  guards_.push_back(addNode(start, NodeType::kGuard));
  guards_.push_back(addNode(goal, NodeType::kGuard));

  // Sampling box aligned with the start-goal direction; a vertical direction takes world x sideways.
  const Eigen::Vector3d axis = (goal - start).normalized();
  Eigen::Vector3d side = Eigen::Vector3d::UnitZ().cross(axis);
  if (side.norm() < 1e-3) side = Eigen::Vector3d::UnitX().cross(axis);
  side.normalize();
  Eigen::Matrix3d rotation;
  rotation << axis, side, axis.cross(side);
  const Eigen::Vector3d centre = 0.5 * (start + goal);
  const Eigen::Vector3d half(0.5 * (goal - start).norm() + config_.sample_inflation_m.x(),
                             config_.sample_inflation_m.y(), config_.sample_inflation_m.z());
  std::uniform_real_distribution<double> unit(-1.0, 1.0);

  const auto t0 = std::chrono::steady_clock::now();
  int unproductive = 0;
  for (int n = 0; n < config_.max_samples; ++n) {
    if (config_.max_unproductive_samples > 0 && unproductive >= config_.max_unproductive_samples) {
      stats.covered = true;
      break;
    }
    const size_t size_before = nodes_.size();
    const int replaced_before = stats.replaced;
    ++unproductive;
    if (config_.max_time_s > 0.0 && (n & 7) == 0 &&
        std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count() > config_.max_time_s) {
      stats.timed_out = true;
      break;
    }
    ++stats.samples;
    const Eigen::Vector3d u(unit(*rng), unit(*rng), unit(*rng));
    const Eigen::Vector3d p = centre + rotation * half.cwiseProduct(u);
    if (!checker.isFree(p)) {
      ++stats.rejected;
      continue;
    }
    int visible[2];
    int count = 0;
    for (int g : guards_) {
      if (!checker.lineVisible(p, nodes_[size_t(g)].position)) continue;
      if (count < 2) visible[count] = g;
      if (++count > 2) break;
    }
    if (count == 0) {
      guards_.push_back(addNode(p, NodeType::kGuard));
      unproductive = 0;
      continue;
    }
    if (count != 2) continue;
    // Connector, unless a connector the two guards share is equivalent (then keep the shorter).
    const Eigen::Vector3d g0 = nodes_[size_t(visible[0])].position;  // copies: addNode may reallocate
    const Eigen::Vector3d g1 = nodes_[size_t(visible[1])].position;
    const Path candidate{g0, p, g1};
    bool distinct = true;
    for (int c : nodes_[size_t(visible[0])].neighbors) {
      const Node& shared = nodes_[size_t(c)];
      if (shared.type != NodeType::kConnector) continue;
      if (std::find(shared.neighbors.begin(), shared.neighbors.end(), visible[1]) == shared.neighbors.end()) continue;
      const Path existing{g0, shared.position, g1};
      if (!uniformVisibilityEquivalent(candidate, existing, checker)) continue;
      distinct = false;
      if (pathLength(candidate) < pathLength(existing)) {
        nodes_[size_t(c)].position = p;  // Replace
        ++stats.replaced;
      }
      break;
    }
    if (distinct) {
      const int c = addNode(p, NodeType::kConnector);
      connect(c, visible[0]);
      connect(c, visible[1]);
    }
    if (nodes_.size() != size_before || stats.replaced != replaced_before) unproductive = 0;
  }
  for (const Node& node : nodes_) (node.type == NodeType::kGuard ? stats.guards : stats.connectors)++;
  return stats;
}

std::vector<Path> TopologicalRoadmap::extractPaths() const {
  std::vector<Path> out;
  std::vector<int> stack{kStart};
  std::vector<char> on_stack(nodes_.size(), 0);
  on_stack[kStart] = 1;
  depthFirst(&stack, &on_stack, &out);
  return out;
}

void TopologicalRoadmap::depthFirst(std::vector<int>* stack, std::vector<char>* on_stack, std::vector<Path>* out) const {
  const Node& cur = nodes_[size_t(stack->back())];
  for (int nb : cur.neighbors) {
    if (nb != kGoal) continue;
    Path p;
    for (int i : *stack) p.push_back(nodes_[size_t(i)].position);
    p.push_back(nodes_[kGoal].position);
    out->push_back(std::move(p));
    if (int(out->size()) >= config_.max_raw_paths) return;
  }
  if (int(stack->size()) >= config_.max_path_nodes) return;
  for (int nb : cur.neighbors) {
    if (nb == kGoal || (*on_stack)[size_t(nb)]) continue;
    stack->push_back(nb);
    (*on_stack)[size_t(nb)] = 1;
    depthFirst(stack, on_stack, out);
    (*on_stack)[size_t(nb)] = 0;
    stack->pop_back();
    if (int(out->size()) >= config_.max_raw_paths) return;
  }
}

}  // namespace topo_planner
