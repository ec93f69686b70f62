#pragma once
// Seeded random obstacle fields for benchmarks, tests and the simulator: vertical pillars (full
// height cylinders) plus floating boxes, at a density given in obstacles per square metre of
// ground. The same generator and density definitions serve the path-search, replanning and flight
// benchmarks, so their figures are comparable.
//
// Densities used in the benchmarks (pillars + floating boxes per m^2):
//   low    0.06 + 0.02   (about 1 obstacle per 12.5 m^2)
//   medium 0.12 + 0.04   (1 per 6.3 m^2)
//   high   0.18 + 0.06   (1 per 4.2 m^2)

#include <cstdint>
#include <string>
#include <vector>

#include "plan_env/occupancy_map.h"

namespace topo_planner {

enum class ObstacleDensity { kLow, kMedium, kHigh };
const char* toString(ObstacleDensity density);

struct ForestConfig {
  double pillars_per_m2 = 0.12;        ///< vertical cylinders per square metre of ground
  double floating_per_m2 = 0.04;       ///< floating boxes per square metre of ground
  double pillar_radius_min_m = 0.15;   ///< [m]
  double pillar_radius_max_m = 0.45;   ///< [m]
  double box_size_min_m = 0.4;         ///< floating box edge range [m]
  double box_size_max_m = 1.2;
  double box_z_min_m = 0.5;            ///< floating box centre height range [m]
  double box_z_max_m = 2.5;
  double ground_z_m = 0.0;             ///< pillars stand on this height [m]
  double pillar_height_m = 3.0;        ///< [m]
  /// Points kept obstacle-free (e.g. a start), with the radius kept free around them [m].
  std::vector<Eigen::Vector3d> keep_free;
  double keep_free_radius_m = 0.8;

  /// The benchmark presets above.
  static ForestConfig preset(ObstacleDensity density);
};

/// Sets every voxel of the map's window free, then the obstacles occupied. Obstacles are placed
/// uniformly over the window's x-y extent with a generator seeded by `seed`. Returns the number of
/// obstacles placed.
int generateForest(const ForestConfig& config, uint32_t seed, OccupancyMap* map);

}  // namespace topo_planner
