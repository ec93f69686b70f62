#pragma once
// Synthetic maps for tests, benchmarks and examples: an all-known map (free everywhere) with shapes
// carved in (cylinders, boxes, any predicate) or a seeded random forest, and its ESDF.

#include <cmath>
#include <memory>
#include <string>

#include "topo_planner/plan_env/esdf_map.h"
#include "topo_planner/plan_env/map_generator.h"

namespace topo_planner {

struct SyntheticScene {
  std::shared_ptr<OccupancyMap> occupancy;
  std::unique_ptr<EsdfMap> esdf;

  /// An all-free map of the given size with its lower corner at origin_m.
  explicit SyntheticScene(const Eigen::Vector3d& size_m, double resolution = 0.1,
                          const Eigen::Vector3d& origin_m = Eigen::Vector3d::Zero()) {
    OccupancyMap::Config c;
    c.resolution_m = resolution;
    c.size_m = size_m;
    c.origin_m = origin_m;
    std::string err;
    occupancy = std::shared_ptr<OccupancyMap>(OccupancyMap::create(c, &err));
    fill([](const Eigen::Vector3d&) { return true; }, VoxelState::kFree);
  }
  /// Sets every voxel whose centre satisfies inside(centre) to state.
  template <typename Inside>
  void fill(Inside&& inside, VoxelState state = VoxelState::kOccupied) {
    const GridGeometry& g = occupancy->geometry();
    const VoxelBox w = g.windowBox();
    Eigen::Vector3i i;
    for (i.z() = w.min.z(); i.z() <= w.max.z(); ++i.z())
      for (i.y() = w.min.y(); i.y() <= w.max.y(); ++i.y())
        for (i.x() = w.min.x(); i.x() <= w.max.x(); ++i.x())
          if (inside(g.centerOf(i))) occupancy->setState(i, state);
  }
  /// A vertical cylinder through the whole map height.
  void pillar(double x, double y, double radius) {
    fill([=](const Eigen::Vector3d& p) { return std::hypot(p.x() - x, p.y() - y) <= radius; });
  }
  /// The voxels whose centres lie in [lo, hi].
  void box(const Eigen::Vector3d& lo, const Eigen::Vector3d& hi) {
    fill([=](const Eigen::Vector3d& p) { return (p.array() >= lo.array()).all() && (p.array() <= hi.array()).all(); });
  }
  /// A seeded random forest (map_generator.h) over the whole window.
  void forest(ObstacleDensity density, uint32_t seed) { generateForest(ForestConfig::preset(density), seed, occupancy.get()); }
  /// The closed-loop simulation's layout: a window of 40 x 24 x 3.4 m from (-20, -12, 0.3) with a
  /// seeded forest only over |x| <= 12, |y| <= 10, kept 1.5 m clear of `keep_free` (start, goals).
  static SyntheticScene simulationForest(ObstacleDensity density, uint32_t seed,
                                         const std::vector<Eigen::Vector3d>& keep_free) {
    SyntheticScene scene(Eigen::Vector3d(40.0, 24.0, 3.4), 0.1, Eigen::Vector3d(-20.0, -12.0, 0.3));
    ForestConfig forest = ForestConfig::preset(density);
    forest.keep_free = keep_free;
    forest.keep_free_radius_m = 1.5;
    forest.ground_z_m = 0.3;
    forest.pillar_height_m = 3.4;
    generateForest(forest, seed, scene.occupancy.get());
    scene.fill([](const Eigen::Vector3d& p) { return std::abs(p.x()) > 12.0 || std::abs(p.y()) > 10.0; },
               VoxelState::kFree);
    return scene;
  }
  /// Call after carving: computes the ESDF (2 m truncation).
  const EsdfMap& finish() {
    EsdfMap::Config c;
    c.max_distance_m = 2.0;
    std::string err;
    esdf = EsdfMap::create(c, occupancy, &err);
    esdf->updateAll();
    return *esdf;
  }
};

}  // namespace topo_planner
