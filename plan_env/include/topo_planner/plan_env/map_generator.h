#pragma once
// Seeded random obstacle fields for benchmarks, tests and the simulator: vertical pillars (full
// height cylinders) plus floating boxes, at a density given in obstacles per square metre of
// ground. The same generator and density definitions serve the path-search, replanning and flight
// benchmarks, so their figures are comparable.
//
// Optional kinds for the simulator, off by default: walls (thin vertical slabs standing on the
// ground, random heading), rings (floating vertical tori, like racing gates) and window walls
// (slabs across the whole window in y, evenly spaced in x, each pierced by rectangular windows:
// rooms and halls, where the way on is through an opening that may lie anywhere). They are placed
// after the pillars and boxes and draw random numbers only when their density is non-zero, so a
// seed gives the same pillars and boxes with or without them (and the benchmark maps are unchanged).
//
// Densities used in the benchmarks (pillars + floating boxes per m^2):
//   low    0.06 + 0.02   (about 1 obstacle per 12.5 m^2)
//   medium 0.12 + 0.04   (1 per 6.3 m^2)
//   high   0.18 + 0.06   (1 per 4.2 m^2)

#include <cstdint>
#include <string>
#include <vector>

#include "topo_planner/plan_env/occupancy_map.h"

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
  double pillar_height_m = 3.0;        ///< [m]; walls are as high
  double walls_per_m2 = 0.0;           ///< walls per square metre of ground (0 = none)
  double wall_length_min_m = 1.0;      ///< wall length range [m]
  double wall_length_max_m = 3.0;
  double wall_thickness_m = 0.2;       ///< [m]
  double rings_per_m2 = 0.0;           ///< rings per square metre of ground (0 = none)
  double ring_radius_min_m = 0.5;      ///< radius of the ring's centre line, range [m]
  double ring_radius_max_m = 1.0;
  double ring_tube_radius_m = 0.1;     ///< half the thickness of the ring's tube [m]
  double ring_z_min_m = 1.0;           ///< ring centre height range [m]
  double ring_z_max_m = 2.0;
  int window_walls = 0;                ///< full-width walls across x, pierced by windows (0 = none)
  int windows_min = 1;                 ///< windows per wall, range
  int windows_max = 3;
  double window_size_min_m = 0.8;      ///< window width and height, each drawn in this range [m]
  double window_size_max_m = 1.5;
  /// Points kept obstacle-free (e.g. a start), with the radius kept free around them [m].
  std::vector<Eigen::Vector3d> keep_free;
  double keep_free_radius_m = 0.8;

  /// The benchmark presets above.
  static ForestConfig preset(ObstacleDensity density);
  /// Adds a map style's obstacles to the density's: forest (none), walls (0.02 walls per m^2),
  /// rings (0.02 rings per m^2), windows (2 window walls), boxes (half the pillars, 0.12 floating
  /// boxes per m^2), mixed (0.01 walls and 0.01 rings per m^2, 1 window wall). False for another name.
  bool applyStyle(const std::string& style);
  /// True when densities are finite and non-negative and every size range is positive and ordered;
  /// otherwise says why.
  bool validate(std::string* why) const;
};

/// One obstacle as placed by generateForest (solid shape, world frame).
struct ForestObstacle {
  enum class Kind { kPillar, kBox, kWall, kRing, kWindowWall };
  Kind kind = Kind::kPillar;
  /// Pillar, wall: centre of the footprint on the ground; box, ring: centre [m].
  Eigen::Vector3d center = Eigen::Vector3d::Zero();
  /// Box: half edges; wall: half length (along the heading), half thickness, height [m]; window
  /// wall: half thickness (x), half span (y), height [m].
  Eigen::Vector3d half_size = Eigen::Vector3d::Zero();
  double radius_m = 0.0;       ///< pillar radius; ring centre-line radius [m]
  double height_m = 0.0;       ///< pillar height [m]
  double tube_radius_m = 0.0;  ///< ring tube radius [m]
  double yaw_rad = 0.0;        ///< wall: direction of its length; ring: direction of its axis [rad]
  /// Window wall: its openings, each (y, z) of the centre and the half width, half height [m].
  std::vector<Eigen::Vector4d> openings;

  /// True if p lies in the solid shape. Walls and rings are rasterised exactly so (a voxel is
  /// occupied when its centre is inside); pillars and boxes cover, as they always have, the voxels
  /// from the one holding their lowest corner to the one holding their highest, so a voxel centre
  /// may lie up to one voxel beyond their top or box faces.
  bool contains(const Eigen::Vector3d& p) const;
};
const char* toString(ForestObstacle::Kind kind);

/// Sets every voxel of the map's window free, then the obstacles occupied. Obstacles are placed
/// uniformly over the window's x-y extent with a generator seeded by `seed`. Returns the number of
/// obstacles placed; `placed` (optional) receives them.
int generateForest(const ForestConfig& config, uint32_t seed, OccupancyMap* map,
                   std::vector<ForestObstacle>* placed = nullptr);

}  // namespace topo_planner
