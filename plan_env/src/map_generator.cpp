#include "plan_env/map_generator.h"

#include <cmath>
#include <random>

namespace topo_planner {

const char* toString(ObstacleDensity density) {
  switch (density) {
    case ObstacleDensity::kLow: return "low";
    case ObstacleDensity::kMedium: return "medium";
    case ObstacleDensity::kHigh: return "high";
  }
  return "?";
}

ForestConfig ForestConfig::preset(ObstacleDensity density) {
  ForestConfig c;
  const double scale = density == ObstacleDensity::kLow ? 0.5 : (density == ObstacleDensity::kMedium ? 1.0 : 1.5);
  c.pillars_per_m2 = 0.12 * scale;
  c.floating_per_m2 = 0.04 * scale;
  return c;
}

int generateForest(const ForestConfig& config, uint32_t seed, OccupancyMap* map) {
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

  int placed = 0;
  const int pillars = int(std::lround(config.pillars_per_m2 * area));
  for (int k = 0; k < pillars; ++k) {
    const Eigen::Vector3d c(ux(rng), uy(rng), config.ground_z_m);
    const double r = config.pillar_radius_min_m + u01(rng) * (config.pillar_radius_max_m - config.pillar_radius_min_m);
    if (!keepsFree(c, r, true)) continue;
    fill(Eigen::Vector3d(c.x() - r, c.y() - r, config.ground_z_m),
         Eigen::Vector3d(c.x() + r, c.y() + r, config.ground_z_m + config.pillar_height_m),
         [&](const Eigen::Vector3d& p) { return (p - c).head<2>().norm() <= r; });
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
    ++placed;
  }
  return placed;
}

}  // namespace topo_planner
