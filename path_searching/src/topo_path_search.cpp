#include "topo_planner/path_searching/topo_path_search.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <numeric>
#include <sstream>

namespace topo_planner {

namespace {
double msSince(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
}
}  // namespace

bool TopoPathSearch::Config::validate(std::string* why) const {
  std::ostringstream err;
  if (!(std::isfinite(clearance_m) && clearance_m >= 0.0)) err << "clearance_m must be >= 0; ";
  if (max_paths < 1) err << "max_paths must be >= 1; ";
  if (max_shortened_paths < 1) err << "max_shortened_paths must be >= 1; ";
  if (!(max_length_ratio >= 1.0)) err << "max_length_ratio must be >= 1; ";
  if (!(roadmap.sample_inflation_m.allFinite() && (roadmap.sample_inflation_m.array() >= 0.0).all()))
    err << "sample_inflation_m must be >= 0; ";
  if (roadmap.max_samples < 1) err << "max_samples must be >= 1; ";
  if (roadmap.max_extra_samples < 0) err << "max_extra_samples must be >= 0; ";
  if (!(roadmap.max_time_s >= 0.0)) err << "max_time_s must be >= 0; ";
  if (roadmap.max_raw_paths < 1) err << "max_raw_paths must be >= 1; ";
  if (roadmap.max_path_nodes < 3) err << "max_path_nodes must be >= 3; ";
  if (roadmap.max_search_expansions < 1) err << "max_search_expansions must be >= 1; ";
  const std::string s = err.str();
  if (why) *why = s.empty() ? "" : s.substr(0, s.size() - 2);
  return s.empty();
}

TopoSearchResult TopoPathSearch::search(const EsdfMap& map, const Eigen::Vector3d& start,
                                        const Eigen::Vector3d& goal, uint32_t seed_offset) {
  const auto t_start = std::chrono::steady_clock::now();
  TopoSearchResult result;
  if (!start.allFinite() || !goal.allFinite() || (goal - start).norm() < 1e-6 || !config_.validate(nullptr)) {
    result.status = SearchStatus::kInvalidInput;
    return result;
  }
  if (!map.geometry().inWindow(start) || !map.geometry().inWindow(goal)) {
    result.status = SearchStatus::kOutOfMap;
    return result;
  }
  const VisibilityChecker checker(map, config_.clearance_m, config_.unknown_is_free);
  if (!checker.isFree(start)) {
    result.status = SearchStatus::kStartInObstacle;
    return result;
  }
  if (!checker.isFree(goal)) {
    result.status = SearchStatus::kGoalInObstacle;
    return result;
  }
  TopoSearchStats& stats = result.stats;
  if (checker.lineVisible(start, goal)) {  // the segment itself: one class, the shortest
    result.paths.push_back({start, goal});
    stats.raw_paths = stats.shortened_paths = stats.distinct_paths = stats.selected_paths = 1;
    stats.total_ms = msSince(t_start);
    result.status = SearchStatus::kSuccess;
    return result;
  }

  // Alg. 1, then the depth-first search.
  std::mt19937 rng(config_.seed + seed_offset);
  auto t = std::chrono::steady_clock::now();
  stats.roadmap = roadmap_.build(start, goal, checker, &rng);
  stats.roadmap_ms = msSince(t);
  t = std::chrono::steady_clock::now();
  std::vector<Path> raw = roadmap_.extractPaths();
  // Unconnected after N_max samples: keep sampling, a chunk at a time, within the extra budget.
  stats.extraction_ms = msSince(t);
  for (int extra = 0; raw.empty() && extra < config_.roadmap.max_extra_samples && !stats.roadmap.timed_out;
       extra += config_.roadmap.max_samples) {
    t = std::chrono::steady_clock::now();
    roadmap_.extend(std::min(config_.roadmap.max_samples, config_.roadmap.max_extra_samples - extra), checker, &rng,
                    &stats.roadmap);
    stats.roadmap_ms += msSince(t);
    t = std::chrono::steady_clock::now();
    raw = roadmap_.extractPaths();
    stats.extraction_ms += msSince(t);
  }
  stats.raw_paths = int(raw.size());

  // Alg. 2 on the shortest raw paths.
  t = std::chrono::steady_clock::now();
  std::vector<double> raw_length(raw.size());
  for (size_t i = 0; i < raw.size(); ++i) raw_length[i] = pathLength(raw[i]);
  std::vector<size_t> raw_order(raw.size());
  std::iota(raw_order.begin(), raw_order.end(), 0);
  std::stable_sort(raw_order.begin(), raw_order.end(), [&](size_t a, size_t b) { return raw_length[a] < raw_length[b]; });
  if (int(raw_order.size()) > config_.max_shortened_paths) raw_order.resize(size_t(config_.max_shortened_paths));
  const PathShortener shortener(checker);
  std::vector<Path> shortened;
  shortened.reserve(raw_order.size());
  for (size_t i : raw_order) {
    bool fell_back = false;
    shortened.push_back(shortener.shorten(raw[i], &fell_back));
    stats.shortening_fallbacks += fell_back;
  }
  stats.shortened_paths = int(shortened.size());
  stats.shortening_ms = msSince(t);

  // Pruning: keep a path only if it is not equivalent to a shorter kept one; then the K_max
  // shortest within r_max of the shortest.
  t = std::chrono::steady_clock::now();
  std::vector<double> length(shortened.size());
  for (size_t i = 0; i < shortened.size(); ++i) length[i] = pathLength(shortened[i]);
  std::vector<size_t> order(shortened.size());
  std::iota(order.begin(), order.end(), 0);
  std::stable_sort(order.begin(), order.end(), [&](size_t a, size_t b) { return length[a] < length[b]; });
  std::vector<size_t> kept;
  for (size_t i : order) {
    if (int(kept.size()) >= config_.max_paths) break;
    if (!kept.empty() && length[i] > config_.max_length_ratio * length[kept.front()]) break;
    bool equivalent = false;
    for (size_t k : kept) {
      equivalent = shortened[i] == shortened[k] || uniformVisibilityEquivalent(shortened[i], shortened[k], checker);
      if (equivalent) break;
    }
    if (!equivalent) kept.push_back(i);
  }
  for (size_t i : kept) result.paths.push_back(shortened[i]);
  stats.distinct_paths = stats.selected_paths = int(kept.size());
  stats.pruning_ms = msSince(t);

  if (config_.keep_raw_paths) {
    result.raw_paths = std::move(raw);
    const auto& nodes = roadmap_.nodes();
    for (size_t i = 0; i < nodes.size(); ++i) {
      (nodes[i].type == TopologicalRoadmap::NodeType::kGuard ? result.roadmap.guards : result.roadmap.connectors)
          .push_back(nodes[i].position);
      for (int nb : nodes[i].neighbors)
        if (size_t(nb) > i) result.roadmap.edges.emplace_back(nodes[i].position, nodes[size_t(nb)].position);
    }
  }
  result.status = result.paths.empty() ? SearchStatus::kBudgetExhausted : SearchStatus::kSuccess;
  stats.total_ms = msSince(t_start);
  return result;
}

}  // namespace topo_planner
