#include "topo_planner/plan_env/map_generator.h"

#include <cmath>
#include <random>
#include <sstream>

namespace topo_planner {

const char* toString(ObstacleDensity density) {
  switch (density) {
    case ObstacleDensity::kLow: return "low";
    case ObstacleDensity::kMedium: return "medium";
    case ObstacleDensity::kHigh: return "high";
  }
  return "?";
}

const char* toString(ForestObstacle::Kind kind) {
  switch (kind) {
    case ForestObstacle::Kind::kPillar: return "pillar";
    case ForestObstacle::Kind::kBox: return "box";
    case ForestObstacle::Kind::kWall: return "wall";
    case ForestObstacle::Kind::kRing: return "ring";
    case ForestObstacle::Kind::kWindowWall: return "window_wall";
  }
  return "?";
}

bool ForestObstacle::contains(const Eigen::Vector3d& p) const {
  const Eigen::Vector3d d = p - center;
  switch (kind) {
    case Kind::kPillar:
      return d.head<2>().norm() <= radius_m && d.z() >= 0.0 && d.z() <= height_m;
    case Kind::kBox:
      return (d.cwiseAbs().array() <= half_size.array()).all();
    case Kind::kWall: {
      const double c = std::cos(yaw_rad), s = std::sin(yaw_rad);
      const double along = c * d.x() + s * d.y(), across = -s * d.x() + c * d.y();
      return std::abs(along) <= half_size.x() && std::abs(across) <= half_size.y() && d.z() >= 0.0 &&
             d.z() <= half_size.z();
    }
    case Kind::kRing: {
      const Eigen::Vector3d axis(std::cos(yaw_rad), std::sin(yaw_rad), 0.0);
      const double a = d.dot(axis), radial = (d - a * axis).norm() - radius_m;
      return radial * radial + a * a <= tube_radius_m * tube_radius_m;
    }
    case Kind::kWindowWall: {
      if (!(std::abs(d.x()) <= half_size.x() && std::abs(d.y()) <= half_size.y() && d.z() >= 0.0 && d.z() <= half_size.z()))
        return false;
      for (const Eigen::Vector4d& o : openings)
        if (std::abs(p.y() - o[0]) <= o[2] && std::abs(p.z() - o[1]) <= o[3]) return false;
      return true;
    }
  }
  return false;
}

ForestConfig ForestConfig::preset(ObstacleDensity density) {
  ForestConfig c;
  const double scale = density == ObstacleDensity::kLow ? 0.5 : (density == ObstacleDensity::kMedium ? 1.0 : 1.5);
  c.pillars_per_m2 = 0.12 * scale;
  c.floating_per_m2 = 0.04 * scale;
  return c;
}

bool ForestConfig::applyStyle(const std::string& style) {
  if (style == "walls") {
    walls_per_m2 = 0.02;
  } else if (style == "rings") {
    rings_per_m2 = 0.02;
  } else if (style == "windows") {
    window_walls = 2;
  } else if (style == "boxes") {
    pillars_per_m2 *= 0.5;
    floating_per_m2 = 0.12;
  } else if (style == "mixed") {
    walls_per_m2 = rings_per_m2 = 0.01;
    window_walls = 1;
  } else if (style != "forest") {
    return false;
  }
  return true;
}

bool ForestConfig::validate(std::string* why) const {
  std::ostringstream err;
  auto density_ok = [](double d) { return std::isfinite(d) && d >= 0.0 && d <= 100.0; };
  auto range_ok = [](double lo, double hi) { return std::isfinite(lo) && std::isfinite(hi) && lo > 0.0 && lo <= hi; };
  if (!density_ok(pillars_per_m2) || !density_ok(floating_per_m2) || !density_ok(walls_per_m2) ||
      !density_ok(rings_per_m2))
    err << "densities must be in [0, 100] per m^2; ";
  if (!range_ok(pillar_radius_min_m, pillar_radius_max_m)) err << "need 0 < pillar_radius_min_m <= pillar_radius_max_m; ";
  if (!range_ok(box_size_min_m, box_size_max_m)) err << "need 0 < box_size_min_m <= box_size_max_m; ";
  if (!(std::isfinite(box_z_min_m) && std::isfinite(box_z_max_m) && box_z_min_m <= box_z_max_m))
    err << "need box_z_min_m <= box_z_max_m; ";
  if (!std::isfinite(ground_z_m)) err << "ground_z_m must be finite; ";
  if (!(std::isfinite(pillar_height_m) && pillar_height_m > 0.0)) err << "pillar_height_m must be positive; ";
  if (!range_ok(wall_length_min_m, wall_length_max_m)) err << "need 0 < wall_length_min_m <= wall_length_max_m; ";
  if (!(std::isfinite(wall_thickness_m) && wall_thickness_m > 0.0)) err << "wall_thickness_m must be positive; ";
  if (!range_ok(ring_radius_min_m, ring_radius_max_m)) err << "need 0 < ring_radius_min_m <= ring_radius_max_m; ";
  if (!(std::isfinite(ring_tube_radius_m) && ring_tube_radius_m > 0.0)) err << "ring_tube_radius_m must be positive; ";
  if (!(std::isfinite(ring_z_min_m) && std::isfinite(ring_z_max_m) && ring_z_min_m <= ring_z_max_m))
    err << "need ring_z_min_m <= ring_z_max_m; ";
  if (!(std::isfinite(keep_free_radius_m) && keep_free_radius_m >= 0.0)) err << "keep_free_radius_m must be >= 0; ";
  if (window_walls < 0 || window_walls > 100) err << "window_walls must be in [0, 100]; ";
  if (windows_min < 1 || windows_max < windows_min || windows_max > 20) err << "need 1 <= windows_min <= windows_max <= 20; ";
  if (!range_ok(window_size_min_m, window_size_max_m)) err << "need 0 < window_size_min_m <= window_size_max_m; ";
  for (const Eigen::Vector3d& k : keep_free)
    if (!k.allFinite()) {
      err << "keep_free points must be finite; ";
      break;
    }
  const std::string s = err.str();
  if (why) *why = s.empty() ? "" : s.substr(0, s.size() - 2);
  return s.empty();
}

int generateForest(const ForestConfig& config, uint32_t seed, OccupancyMap* map,
                   std::vector<ForestObstacle>* placed_obstacles) {
  const GridGeometry& g = map->geometry();
  const VoxelBox w = g.windowBox();
  Eigen::Vector3i i;
  for (i.z() = w.min.z(); i.z() <= w.max.z(); ++i.z())
    for (i.y() = w.min.y(); i.y() <= w.max.y(); ++i.y())
      for (i.x() = w.min.x(); i.x() <= w.max.x(); ++i.x()) map->setState(i, VoxelState::kFree);

  const Eigen::Vector3d lo = g.windowMin(), hi = g.windowMax();
  const double area = (hi.x() - lo.x()) * (hi.y() - lo.y());
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> ux(lo.x(), hi.x()), uy(lo.y(), hi.y()), u01(0.0, 1.0);
  auto keepsFree = [&](const Eigen::Vector3d& c, double reach, bool vertical) {
    for (const Eigen::Vector3d& k : config.keep_free) {
      const Eigen::Vector3d d = vertical ? Eigen::Vector3d(c.x() - k.x(), c.y() - k.y(), 0.0) : Eigen::Vector3d(c - k);
      if (d.norm() < reach + config.keep_free_radius_m) return false;
    }
    return true;
  };
  auto fill = [&](const Eigen::Vector3d& bmin, const Eigen::Vector3d& bmax, auto&& inside) {
    const Eigen::Vector3i a = g.indexOf(bmin).cwiseMax(w.min), b = g.indexOf(bmax).cwiseMin(w.max);
    Eigen::Vector3i v;
    for (v.z() = a.z(); v.z() <= b.z(); ++v.z())
      for (v.y() = a.y(); v.y() <= b.y(); ++v.y())
        for (v.x() = a.x(); v.x() <= b.x(); ++v.x())
          if (inside(g.centerOf(v))) map->setState(v, VoxelState::kOccupied);
  };

  auto record = [&](const ForestObstacle& o) {
    if (placed_obstacles) placed_obstacles->push_back(o);
  };
  // Walls and rings: every voxel whose centre is inside the shape, within its bounding box.
  auto fillShape = [&](const ForestObstacle& o, const Eigen::Vector3d& bmin, const Eigen::Vector3d& bmax) {
    fill(bmin, bmax, [&](const Eigen::Vector3d& p) { return o.contains(p); });
    record(o);
  };

  int placed = 0;
  const int pillars = int(std::lround(config.pillars_per_m2 * area));
  for (int k = 0; k < pillars; ++k) {
    const Eigen::Vector3d c(ux(rng), uy(rng), config.ground_z_m);
    const double r = config.pillar_radius_min_m + u01(rng) * (config.pillar_radius_max_m - config.pillar_radius_min_m);
    if (!keepsFree(c, r, true)) continue;
    fill(Eigen::Vector3d(c.x() - r, c.y() - r, config.ground_z_m),
         Eigen::Vector3d(c.x() + r, c.y() + r, config.ground_z_m + config.pillar_height_m),
         [&](const Eigen::Vector3d& p) { return (p - c).head<2>().norm() <= r; });
    ForestObstacle o;
    o.kind = ForestObstacle::Kind::kPillar;
    o.center = c;
    o.radius_m = r;
    o.height_m = config.pillar_height_m;
    record(o);
    ++placed;
  }
  const int boxes = int(std::lround(config.floating_per_m2 * area));
  for (int k = 0; k < boxes; ++k) {
    const Eigen::Vector3d c(ux(rng), uy(rng),
                            config.box_z_min_m + u01(rng) * (config.box_z_max_m - config.box_z_min_m));
    const Eigen::Vector3d half =
        0.5 * Eigen::Vector3d::NullaryExpr([&] { return config.box_size_min_m + u01(rng) * (config.box_size_max_m - config.box_size_min_m); });
    if (!keepsFree(c, half.norm(), false)) continue;
    fill(c - half, c + half, [](const Eigen::Vector3d&) { return true; });
    ForestObstacle o;
    o.kind = ForestObstacle::Kind::kBox;
    o.center = c;
    o.half_size = half;
    record(o);
    ++placed;
  }
  // The optional kinds: a zero density gives a zero count and no random draws (see the header).
  const int walls = int(std::lround(config.walls_per_m2 * area));
  for (int k = 0; k < walls; ++k) {
    ForestObstacle o;
    o.kind = ForestObstacle::Kind::kWall;
    o.center = Eigen::Vector3d(ux(rng), uy(rng), config.ground_z_m);
    const double length = config.wall_length_min_m + u01(rng) * (config.wall_length_max_m - config.wall_length_min_m);
    o.yaw_rad = M_PI * u01(rng);
    o.half_size = Eigen::Vector3d(0.5 * length, 0.5 * config.wall_thickness_m, config.pillar_height_m);
    const double reach = o.half_size.head<2>().norm();
    if (!keepsFree(o.center, reach, true)) continue;
    fillShape(o, o.center - Eigen::Vector3d(reach, reach, 0.0),
              o.center + Eigen::Vector3d(reach, reach, config.pillar_height_m));
    ++placed;
  }
  const int rings = int(std::lround(config.rings_per_m2 * area));
  for (int k = 0; k < rings; ++k) {
    ForestObstacle o;
    o.kind = ForestObstacle::Kind::kRing;
    o.center = Eigen::Vector3d(ux(rng), uy(rng), config.ring_z_min_m + u01(rng) * (config.ring_z_max_m - config.ring_z_min_m));
    o.radius_m = config.ring_radius_min_m + u01(rng) * (config.ring_radius_max_m - config.ring_radius_min_m);
    o.tube_radius_m = config.ring_tube_radius_m;
    o.yaw_rad = M_PI * u01(rng);
    const double reach = o.radius_m + o.tube_radius_m;
    if (!keepsFree(o.center, reach, false)) continue;
    fillShape(o, o.center - Eigen::Vector3d::Constant(reach), o.center + Eigen::Vector3d::Constant(reach));
    ++placed;
  }
  // Window walls: evenly spaced in x (jittered by a fifth of the spacing), each across the whole
  // window in y; a wall that would pass within the keep-free radius of a kept point is moved off it.
  const double spacing = config.window_walls > 0 ? (hi.x() - lo.x()) / config.window_walls : 0.0;
  for (int k = 0; k < config.window_walls; ++k) {
    ForestObstacle o;
    o.kind = ForestObstacle::Kind::kWindowWall;
    double x = lo.x() + (k + 0.5 + 0.2 * (u01(rng) - 0.5)) * spacing;
    const double ht = 0.5 * config.wall_thickness_m;
    for (const Eigen::Vector3d& kf : config.keep_free)
      if (std::abs(x - kf.x()) < ht + config.keep_free_radius_m)
        x = kf.x() + (x >= kf.x() ? 1.0 : -1.0) * (ht + config.keep_free_radius_m + 0.05);
    o.center = Eigen::Vector3d(x, 0.5 * (lo.y() + hi.y()), config.ground_z_m);
    o.half_size = Eigen::Vector3d(ht, 0.5 * (hi.y() - lo.y()), config.pillar_height_m);
    const int n = config.windows_min + int(u01(rng) * (config.windows_max - config.windows_min + 1) * 0.999999);
    for (int j = 0; j < n; ++j) {
      const double w = config.window_size_min_m + u01(rng) * (config.window_size_max_m - config.window_size_min_m);
      const double h = config.window_size_min_m + u01(rng) * (config.window_size_max_m - config.window_size_min_m);
      const double y_lo = lo.y() + 0.5 * w + 0.3, y_hi = hi.y() - 0.5 * w - 0.3;
      const double z_lo = config.ground_z_m + 0.4 + 0.5 * h, z_hi = config.ground_z_m + config.pillar_height_m - 0.4 - 0.5 * h;
      const double y = y_lo < y_hi ? y_lo + u01(rng) * (y_hi - y_lo) : 0.5 * (lo.y() + hi.y());
      const double z = z_lo < z_hi ? z_lo + u01(rng) * (z_hi - z_lo) : config.ground_z_m + 0.5 * config.pillar_height_m;
      o.openings.emplace_back(y, z, 0.5 * w, 0.5 * h);
    }
    // The openings are cut through whatever stands in the wall's slab too (pillars, boxes): a window is a window.
    const Eigen::Vector3i a = g.indexOf(Eigen::Vector3d(x - ht, lo.y(), config.ground_z_m)).cwiseMax(w.min);
    const Eigen::Vector3i b =
        g.indexOf(Eigen::Vector3d(x + ht, hi.y(), config.ground_z_m + config.pillar_height_m)).cwiseMin(w.max);
    Eigen::Vector3i v;
    for (v.z() = a.z(); v.z() <= b.z(); ++v.z())
      for (v.y() = a.y(); v.y() <= b.y(); ++v.y())
        for (v.x() = a.x(); v.x() <= b.x(); ++v.x()) {
          const Eigen::Vector3d p = g.centerOf(v);
          if (o.contains(p)) {
            map->setState(v, VoxelState::kOccupied);
          } else if (std::abs(p.x() - x) <= ht) {
            for (const Eigen::Vector4d& op : o.openings)
              if (std::abs(p.y() - op[0]) <= op[2] && std::abs(p.z() - op[1]) <= op[3]) map->setState(v, VoxelState::kFree);
          }
        }
    record(o);
    ++placed;
  }
  return placed;
}

}  // namespace topo_planner
