#include "topo_planner/path_searching/topological_roadmap.h"

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
  rotation_ << axis, side, axis.cross(side);
  centre_ = 0.5 * (start + goal);
  half_ = Eigen::Vector3d(0.5 * (goal - start).norm() + config_.sample_inflation_m.x(), config_.sample_inflation_m.y(),
                          config_.sample_inflation_m.z());
  started_ = std::chrono::steady_clock::now();
  extend(config_.max_samples, checker, rng, &stats);
  return stats;
}

void TopologicalRoadmap::extend(int samples, const VisibilityChecker& checker, std::mt19937* rng, Stats* stats) {
  std::uniform_real_distribution<double> unit(-1.0, 1.0);
  int unproductive = 0;
  for (int n = 0; n < samples; ++n) {
    if (config_.max_time_s > 0.0 && (n & 7) == 0 &&
        std::chrono::duration<double>(std::chrono::steady_clock::now() - started_).count() > config_.max_time_s) {
      stats->timed_out = true;
      break;
    }
    if (config_.max_unproductive_samples > 0 && unproductive >= config_.max_unproductive_samples) {
      stats->covered = true;
      break;
    }
    const size_t size_before = nodes_.size();
    const int replaced_before = stats->replaced;
    ++unproductive;
    ++stats->samples;
    const Eigen::Vector3d u(unit(*rng), unit(*rng), unit(*rng));
    const Eigen::Vector3d p = centre_ + rotation_ * half_.cwiseProduct(u);
    if (p.z() < config_.min_z_m || p.z() > config_.max_z_m || !checker.isFree(p)) {
      ++stats->rejected;
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
        ++stats->replaced;
      }
      break;
    }
    if (distinct) {
      const int c = addNode(p, NodeType::kConnector);
      connect(c, visible[0]);
      connect(c, visible[1]);
    }
    if (nodes_.size() != size_before || stats->replaced != replaced_before) unproductive = 0;
  }
  stats->guards = stats->connectors = 0;
  for (const Node& node : nodes_) (node.type == NodeType::kGuard ? stats->guards : stats->connectors)++;
}

std::vector<Path> TopologicalRoadmap::extractPaths() const {
  std::vector<Path> out;
  SearchState s;
  // Hop counts to the goal, breadth first.
  s.hops_to_goal.assign(nodes_.size(), -1);
  std::vector<int> queue{kGoal};
  s.hops_to_goal[kGoal] = 0;
  for (size_t head = 0; head < queue.size(); ++head)
    for (int nb : nodes_[size_t(queue[head])].neighbors)
      if (s.hops_to_goal[size_t(nb)] < 0) {
        s.hops_to_goal[size_t(nb)] = s.hops_to_goal[size_t(queue[head])] + 1;
        queue.push_back(nb);
      }
  if (s.hops_to_goal[kStart] < 0) return out;  // not connected
  s.stack = {kStart};
  s.on_stack.assign(nodes_.size(), 0);
  s.on_stack[kStart] = 1;
  depthFirst(&s, &out);
  return out;
}

void TopologicalRoadmap::depthFirst(SearchState* s, std::vector<Path>* out) const {
  if (++s->expansions > config_.max_search_expansions) return;
  const Node& cur = nodes_[size_t(s->stack.back())];
  for (int nb : cur.neighbors) {
    if (nb != kGoal) continue;
    Path p;
    for (int i : s->stack) p.push_back(nodes_[size_t(i)].position);
    p.push_back(nodes_[kGoal].position);
    out->push_back(std::move(p));
    if (int(out->size()) >= config_.max_raw_paths) return;
  }
  for (int nb : cur.neighbors) {
    if (nb == kGoal || s->on_stack[size_t(nb)]) continue;
    // The path would have stack + hops_to_goal(nb) + 1 nodes at least.
    const int hops = s->hops_to_goal[size_t(nb)];
    if (hops < 0 || int(s->stack.size()) + 1 + hops > config_.max_path_nodes) continue;
    s->stack.push_back(nb);
    s->on_stack[size_t(nb)] = 1;
    depthFirst(s, out);
    s->on_stack[size_t(nb)] = 0;
    s->stack.pop_back();
    if (int(out->size()) >= config_.max_raw_paths || s->expansions > config_.max_search_expansions) return;
  }
}

}  // namespace topo_planner
