#include "topo_planner/path_searching/global_router.h"

#include <algorithm>
#include <cmath>
#include <queue>

namespace topo_planner {

bool GlobalRouter::Config::validate(std::string* why) const {
  auto bad = [&](const char* text) {
    if (why) *why = text;
    return false;
  };
  if (!(clearance_m >= 0.0) || !std::isfinite(clearance_m)) return bad("route clearance_m must be finite and >= 0");
  if (cell_voxels < 1 || cell_voxels > 4) return bad("route cell_voxels must be 1 to 4");
  if (!(preferred_clearance_m > 0.0) || !std::isfinite(preferred_clearance_m))
    return bad("route preferred_clearance_m must be finite and > 0");
  if (!(clearance_weight >= 0.0) || !std::isfinite(clearance_weight)) return bad("route clearance_weight must be >= 0");
  if (!(avoid_weight >= 0.0) || !std::isfinite(avoid_weight)) return bad("route avoid_weight must be >= 0");
  if (!(unknown_weight >= 0.0) || !std::isfinite(unknown_weight)) return bad("route unknown_weight must be >= 0");
  if (!(heuristic_weight >= 1.0) || !std::isfinite(heuristic_weight)) return bad("route heuristic_weight must be >= 1");
  if (!(min_z_m < max_z_m)) return bad("route min_z_m must be below max_z_m");
  if (!(band_margin_m >= 0.0) || !std::isfinite(band_margin_m)) return bad("route band_margin_m must be finite and >= 0");
  if (!(end_radius_m >= 0.0) || !std::isfinite(end_radius_m)) return bad("route end_radius_m must be finite and >= 0");
  if (!(start_radius_m >= 0.0) || !std::isfinite(start_radius_m)) return bad("route start_radius_m must be finite and >= 0");
  if (!(end_clearance_m >= 0.0) || !(end_clearance_m <= clearance_m))
    return bad("route end_clearance_m must be in [0, clearance_m]");
  if (max_expansions < 1) return bad("route max_expansions must be >= 1");
  if (shortcut_lookahead < 1) return bad("route shortcut_lookahead must be >= 1");
  return true;
}

void GlobalRouter::setAvoided(const std::vector<Zone>& zones) {
  avoided_.clear();
  for (const Zone& z : zones)
    if (z.center.allFinite() && std::isfinite(z.radius_m) && z.radius_m > 0.0) avoided_.push_back(z);
}

GlobalRouter::Result GlobalRouter::route(const EsdfMap& map, const Eigen::Vector3d& start, const Eigen::Vector3d& goal) {
  const double m = config_.band_margin_m;
  if (m > 0.0 && config_.max_z_m - config_.min_z_m > 2.0 * m) {
    const Result inner = search(map, start, goal, config_.min_z_m + m, config_.max_z_m - m);
    if (inner.status != SearchStatus::kNoPath) return inner;
    Result whole = search(map, start, goal, config_.min_z_m, config_.max_z_m);
    whole.expansions += inner.expansions;
    return whole;
  }
  return search(map, start, goal, config_.min_z_m, config_.max_z_m);
}

GlobalRouter::Result GlobalRouter::search(const EsdfMap& map, const Eigen::Vector3d& start, const Eigen::Vector3d& goal,
                                          double min_z_m, double max_z_m) {
  Result result;
  if (!start.allFinite() || !goal.allFinite() || !config_.validate(nullptr)) return result;
  const GridGeometry& geo = map.geometry();
  if (!geo.inWindow(start) || !geo.inWindow(goal)) {
    result.status = SearchStatus::kOutOfMap;
    return result;
  }
  const int k = config_.cell_voxels;
  const VoxelBox window = geo.windowBox();
  const Eigen::Vector3i n = (window.size().array() + (k - 1)) / k;
  const size_t volume = size_t(n.x()) * size_t(n.y()) * size_t(n.z());
  if (volume >= size_t(INT32_MAX)) return result;  // parents are int32 (a window of 2^31 cells is not a drone's)
  if (stamp_.size() < volume) {
    stamp_.assign(volume, 0u);
    cell_stamp_.assign(volume, 0u);
    g_.resize(volume);
    parent_.resize(volume);
    cell_distance_.resize(volume);
    cell_best_.resize(volume);
    cell_unknown_.resize(volume);
    generation_ = 0;
  }
  if (++generation_ >= 0x7fffffffu) {  // the top bit marks closed cells
    std::fill(stamp_.begin(), stamp_.end(), 0u);
    std::fill(cell_stamp_.begin(), cell_stamp_.end(), 0u);
    generation_ = 1;
  }
  const uint32_t closed = generation_ | 0x80000000u;

  auto cellOf = [&](const Eigen::Vector3d& p) -> Eigen::Vector3i { return (geo.indexOf(p) - window.min) / k; };
  auto address = [&](const Eigen::Vector3i& c) {
    return size_t(c.x()) + size_t(n.x()) * (size_t(c.y()) + size_t(n.y()) * size_t(c.z()));
  };
  auto cellAt = [&](size_t a) {
    const int x = int(a % size_t(n.x())), y = int((a / size_t(n.x())) % size_t(n.y())), z = int(a / (size_t(n.x()) * n.y()));
    return Eigen::Vector3i(x, y, z);
  };
  auto voxelOf = [&](const Eigen::Vector3i& c, int offset) {
    return Eigen::Vector3i(window.min + c * k + Eigen::Vector3i(offset % k, (offset / k) % k, offset / (k * k)));
  };
  // The best voxel of a cell (see the header), computed once per search.
  const OccupancyMap& occupancy = map.occupancy();
  auto bestOf = [&](size_t a, const Eigen::Vector3i& c, bool relaxed) {
    if (cell_stamp_[a] != generation_) {
      float best = -1.0f;
      uint8_t best_offset = 0;
      for (int o = 0; o < k * k * k; ++o) {
        const Eigen::Vector3i v = voxelOf(c, o);
        float d;
        if (!map.voxelDistance(v, &d) || d <= best) continue;
        if (!config_.unknown_is_free && occupancy.state(v) == VoxelState::kUnknown) continue;
        const double z = geo.centerOf(v).z();
        if (!relaxed && (z < min_z_m || z > max_z_m)) continue;
        best = d;
        best_offset = uint8_t(o);
      }
      cell_stamp_[a] = generation_;
      cell_distance_[a] = best;
      cell_best_[a] = best_offset;
      cell_unknown_[a] = best >= 0.0f && occupancy.state(voxelOf(c, best_offset)) == VoxelState::kUnknown;
    }
    return cell_distance_[a];
  };
  const double end_radius2 = config_.end_radius_m * config_.end_radius_m;
  const double start_radius = std::max(config_.end_radius_m, config_.start_radius_m);
  const double start_radius2 = start_radius * start_radius;
  const Eigen::Vector3i cs = cellOf(start), ce = cellOf(goal);
  // Whether a cell may be entered, its best voxel's centre and distance.
  auto usable = [&](size_t a, const Eigen::Vector3i& c, Eigen::Vector3d* centre, float* distance) {
    // Relaxed near the ends: the band does not apply and the clearance is end_clearance_m. The
    // relaxation depends on the cell's centre only, so a cell's best voxel is the same either way
    // it is reached.
    const Eigen::Vector3d cell_centre = geo.centerOf(window.min + c * k) + Eigen::Vector3d::Constant(0.5 * (k - 1) * geo.resolution());
    const bool relaxed = c == cs || c == ce || (cell_centre - start).squaredNorm() <= start_radius2 ||
                         (cell_centre - goal).squaredNorm() <= end_radius2;
    const float d = bestOf(a, c, relaxed);
    if (d < 0.0f) return false;
    *centre = geo.centerOf(voxelOf(c, cell_best_[a]));
    *distance = d;
    return d >= (relaxed ? config_.end_clearance_m : config_.clearance_m);
  };

  const size_t as = address(cs), ae = address(ce);
  Eigen::Vector3d p;
  float d;
  if (map.occupancy().isOccupied(geo.indexOf(start)) || !usable(as, cs, &p, &d)) {
    result.status = SearchStatus::kStartInObstacle;
    return result;
  }
  if (map.occupancy().isOccupied(geo.indexOf(goal)) || !usable(ae, ce, &p, &d)) {
    result.status = SearchStatus::kGoalInObstacle;
    return result;
  }
  const double w = config_.clearance_weight, pref = config_.preferred_clearance_m;
  auto heuristic = [&](const Eigen::Vector3d& q) { return float(config_.heuristic_weight * (q - goal).norm()); };
  // Zones that overlap compound: a place stalled at again weighs more each time.
  auto avoidance = [&](const Eigen::Vector3d& q) {
    double factor = 1.0;
    for (const Zone& z : avoided_)
      if ((q - z.center).squaredNorm() < z.radius_m * z.radius_m) factor *= 1.0 + config_.avoid_weight;
    return factor;
  };
  // A shortcut from a to b crosses a zone that holds neither of them.
  auto crossesZone = [&](const Eigen::Vector3d& a, const Eigen::Vector3d& b) {
    for (const Zone& z : avoided_) {
      const double r2 = z.radius_m * z.radius_m;
      if ((a - z.center).squaredNorm() < r2 || (b - z.center).squaredNorm() < r2) continue;
      const Eigen::Vector3d ab = b - a;
      const double u = ab.squaredNorm() > 0.0 ? std::clamp((z.center - a).dot(ab) / ab.squaredNorm(), 0.0, 1.0) : 0.0;
      if ((a + u * ab - z.center).squaredNorm() < r2) return true;
    }
    return false;
  };

  struct Item {
    float f;
    uint32_t a;
    bool operator>(const Item& o) const { return f > o.f; }
  };
  std::priority_queue<Item, std::vector<Item>, std::greater<Item>> open;
  stamp_[as] = generation_;
  g_[as] = 0.0f;
  parent_[as] = -1;
  open.push({heuristic(start), uint32_t(as)});
  bool found = false;
  while (!open.empty()) {
    const Item top = open.top();
    open.pop();
    if (stamp_[top.a] == closed) continue;
    stamp_[top.a] = closed;
    if (top.a == ae) {
      found = true;
      break;
    }
    if (++result.expansions > config_.max_expansions) {
      result.status = SearchStatus::kBudgetExhausted;
      return result;
    }
    const Eigen::Vector3i cur = cellAt(top.a);
    const Eigen::Vector3d pc = top.a == as ? start : geo.centerOf(voxelOf(cur, cell_best_[top.a]));
    const float gc = g_[top.a];
    for (int dz = -1; dz <= 1; ++dz)
      for (int dy = -1; dy <= 1; ++dy)
        for (int dx = -1; dx <= 1; ++dx) {
          if (dx == 0 && dy == 0 && dz == 0) continue;
          const Eigen::Vector3i nb = cur + Eigen::Vector3i(dx, dy, dz);
          if ((nb.array() < 0).any() || (nb.array() >= n.array()).any()) continue;
          const size_t a = address(nb);
          if (stamp_[a] == closed) continue;
          Eigen::Vector3d pn;
          float dn;
          if (!usable(a, nb, &pn, &dn)) continue;
          if (a == ae) pn = goal;
          double penalty = 1.0 + w * std::max(0.0, pref - double(dn)) / pref;
          if (!avoided_.empty()) penalty *= avoidance(pn);
          if (cell_unknown_[a]) penalty *= 1.0 + config_.unknown_weight;
          const float cost = gc + float((pn - pc).norm() * penalty);
          if (stamp_[a] == generation_ && g_[a] <= cost) continue;
          stamp_[a] = generation_;
          g_[a] = cost;
          parent_[a] = int32_t(top.a);
          open.push({cost + heuristic(pn), uint32_t(a)});
        }
  }
  if (!found) {
    result.status = SearchStatus::kNoPath;
    return result;
  }

  // The raw route: start, the best voxel of every cell between, goal; and which are unknown.
  std::vector<size_t> cells;
  for (int64_t a = int64_t(ae); a >= 0; a = parent_[size_t(a)]) cells.push_back(size_t(a));
  std::reverse(cells.begin(), cells.end());
  Path& raw = result.raw;
  std::vector<uint8_t> raw_unknown;
  raw.push_back(start);
  raw_unknown.push_back(0);
  for (size_t i = 1; i + 1 < cells.size(); ++i) {
    raw.push_back(geo.centerOf(voxelOf(cellAt(cells[i]), cell_best_[cells[i]])));
    raw_unknown.push_back(cell_unknown_[cells[i]]);
  }
  raw.push_back(goal);
  raw_unknown.push_back(0);
  // A shortcut through unknown space where the raw route between its ends went through known space
  // only would undo the preference for the known way.
  auto crossesUnknown = [&](size_t i, size_t j) {
    if (!(config_.unknown_weight > 0.0) || !config_.unknown_is_free) return false;
    for (size_t m = i + 1; m < j; ++m)
      if (raw_unknown[m]) return false;
    const Eigen::Vector3d ab = raw[j] - raw[i];
    const int steps = std::max(1, int(std::ceil(ab.norm() / (0.5 * geo.resolution()))));
    for (int s = 1; s < steps; ++s)
      if (occupancy.state(Eigen::Vector3d(raw[i] + ab * (double(s) / steps))) == VoxelState::kUnknown) return true;
    return false;
  };

  // Shortening by line of sight at the clearance: from each kept point, the farthest raw point
  // visible (looking shortcut_lookahead points past the last visible one); a raw step where none is.
  const VisibilityChecker checker(map, config_.clearance_m, config_.unknown_is_free);
  Path& path = result.path;
  path.push_back(raw.front());
  size_t anchor = 0;
  while (anchor + 1 < raw.size()) {
    size_t best = anchor + 1;
    for (size_t j = anchor + 2; j < raw.size() && j <= best + size_t(config_.shortcut_lookahead); ++j)
      if (checker.lineVisible(raw[anchor], raw[j]) && !crossesZone(raw[anchor], raw[j]) && !crossesUnknown(anchor, j))
        best = j;
    path.push_back(raw[best]);
    anchor = best;
  }
  result.length_m = pathLength(path);
  result.status = SearchStatus::kSuccess;
  return result;
}

}  // namespace topo_planner
