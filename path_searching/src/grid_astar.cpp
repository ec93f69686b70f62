#include "topo_planner/path_searching/grid_astar.h"

#include <algorithm>
#include <cmath>
#include <queue>

namespace topo_planner {

GridAStar::Result GridAStar::search(const EsdfMap& map, const Eigen::Vector3d& start, const Eigen::Vector3d& goal) {
  double margin = config_.search_margin_m;
  Result result = searchBox(map, start, goal, margin);
  int expansions = result.expansions;
  for (int k = 0; k < config_.margin_doublings && result.status == SearchStatus::kNoPath; ++k) {
    margin *= 2.0;
    result = searchBox(map, start, goal, margin);
    expansions += result.expansions;
  }
  result.expansions = expansions;
  return result;
}

GridAStar::Result GridAStar::searchBox(const EsdfMap& map, const Eigen::Vector3d& start, const Eigen::Vector3d& goal,
                                       double margin_m) {
  Result result;
  if (!start.allFinite() || !goal.allFinite()) return result;
  const GridGeometry& g = map.geometry();
  if (!g.inWindow(start) || !g.inWindow(goal)) {
    result.status = SearchStatus::kOutOfMap;
    return result;
  }
  const VisibilityChecker checker(map, config_.clearance_m, config_.unknown_is_free);
  const Eigen::Vector3i s = g.indexOf(start), e = g.indexOf(goal);
  if (!checker.isFreeVoxel(s)) {
    result.status = SearchStatus::kStartInObstacle;
    return result;
  }
  if (!checker.isFreeVoxel(e)) {
    result.status = SearchStatus::kGoalInObstacle;
    return result;
  }

  // The search box and its dense, generation-stamped buffers.
  const int margin = int(std::ceil(std::min(margin_m, 1e6) / g.resolution()));
  VoxelBox box;
  box.extend(s);
  box.extend(e);
  box = box.inflated(margin).intersection(g.windowBox());
  // The height band: the voxels whose centres lie in it (the voxel holding max_z_m reaches half a
  // voxel above it, over a wall top the camera saw past), stretched to hold the start and the goal
  // (a take-off from below it).
  const double half = 0.5 * g.resolution();
  const int band_lo =
      std::min({s.z(), e.z(), g.indexOf(Eigen::Vector3d(0, 0, std::max(config_.min_z_m, -1e6) + half)).z()});
  const int band_hi =
      std::max({s.z(), e.z(), g.indexOf(Eigen::Vector3d(0, 0, std::min(config_.max_z_m, 1e6) - half)).z()});
  box.min.z() = std::max(box.min.z(), band_lo);
  box.max.z() = std::min(box.max.z(), band_hi);
  const Eigen::Vector3i n = box.size();
  const size_t volume = size_t(box.volume());
  if (stamp_.size() < volume) {
    stamp_.assign(volume, 0u);
    g_.resize(volume);
    parent_.resize(volume);
    generation_ = 0;
  }
  // The top bit marks closed voxels: restart the stamps before the generation reaches it.
  if (++generation_ >= 0x7fffffffu) {
    std::fill(stamp_.begin(), stamp_.end(), 0u);
    generation_ = 1;
  }
  auto local = [&](const Eigen::Vector3i& i) {
    const Eigen::Vector3i l = i - box.min;
    return size_t(l.x()) + size_t(n.x()) * (size_t(l.y()) + size_t(n.y()) * size_t(l.z()));
  };
  auto global = [&](size_t k) {
    const int x = int(k % size_t(n.x())), y = int((k / size_t(n.x())) % size_t(n.y())), z = int(k / (size_t(n.x()) * n.y()));
    return Eigen::Vector3i(box.min + Eigen::Vector3i(x, y, z));
  };
  const double weight = std::isfinite(config_.heuristic_weight) ? std::max(1.0, config_.heuristic_weight) : 1.0;
  auto heuristic = [&](const Eigen::Vector3i& i) { return float(weight * (i - e).cast<double>().norm()); };

  struct Item {
    float f;
    size_t k;
    bool operator>(const Item& o) const { return f > o.f; }
  };
  std::priority_queue<Item, std::vector<Item>, std::greater<Item>> open;
  const size_t ks = local(s), ke = local(e);
  stamp_[ks] = generation_;
  g_[ks] = 0.0f;
  parent_[ks] = -1;
  open.push({heuristic(s), ks});
  // Closed voxels carry the stamp with the top bit set.
  const uint32_t closed = generation_ | 0x80000000u;
  while (!open.empty()) {
    const Item top = open.top();
    open.pop();
    if (stamp_[top.k] == closed) continue;
    stamp_[top.k] = closed;
    if (top.k == ke) {
      Path voxels;
      for (int64_t k = int64_t(ke); k >= 0; k = parent_[size_t(k)]) voxels.push_back(g.centerOf(global(size_t(k))));
      std::reverse(voxels.begin(), voxels.end());
      voxels.front() = start;
      if (voxels.size() == 1) voxels.push_back(goal);
      voxels.back() = goal;
      result.path = std::move(voxels);
      result.status = SearchStatus::kSuccess;
      return result;
    }
    if (++result.expansions > config_.max_expansions) {
      result.status = SearchStatus::kBudgetExhausted;
      return result;
    }
    const Eigen::Vector3i cur = global(top.k);
    const float gc = g_[top.k];
    for (int dz = -1; dz <= 1; ++dz)
      for (int dy = -1; dy <= 1; ++dy)
        for (int dx = -1; dx <= 1; ++dx) {
          if (dx == 0 && dy == 0 && dz == 0) continue;
          const Eigen::Vector3i nb = cur + Eigen::Vector3i(dx, dy, dz);
          if (!box.contains(nb)) continue;
          const size_t k = local(nb);
          if (stamp_[k] == closed) continue;
          if (!checker.isFreeVoxel(nb)) continue;
          const float cost = gc + float(std::sqrt(double(dx * dx + dy * dy + dz * dz)));
          if (stamp_[k] == generation_ && g_[k] <= cost) continue;
          stamp_[k] = generation_;
          g_[k] = cost;
          parent_[k] = int32_t(top.k);
          open.push({cost + heuristic(nb), k});
        }
  }
  result.status = SearchStatus::kNoPath;
  return result;
}

}  // namespace topo_planner
