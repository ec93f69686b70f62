// The seeded forest generator: the benchmark maps stay bit-identical (pinned hashes), the optional
// walls and rings draw nothing when off, and they are rasterised exactly (brute-force oracle over
// every voxel of the window).
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdint>

#include "topo_planner/plan_env/map_generator.h"
#include "test_helpers.h"

namespace topo_planner {
namespace {

// The forest area of the closed-loop scenario, with keep-free points around start and goals.
std::shared_ptr<OccupancyMap> forestWindow() { return test::makeMap({24.0, 20.0, 3.0}, {-12.0, -10.0, 0.0}); }

ForestConfig scenario(ObstacleDensity density) {
  ForestConfig f = ForestConfig::preset(density);
  f.keep_free = {{-15.0, 0.0, 1.0}, {15.0, 5.0, 1.0}, {-11.0, 0.0, 1.0}};
  f.keep_free_radius_m = 1.5;
  return f;
}

// FNV-1a over the occupied indices in the map's scan order.
uint64_t occupiedHash(const OccupancyMap& map, size_t* count) {
  uint64_t h = 1469598103934665603ull;
  *count = 0;
  map.forEachOccupied([&](const Eigen::Vector3i& i) {
    for (int a = 0; a < 3; ++a) {
      h ^= uint64_t(uint32_t(i[a]));
      h *= 1099511628211ull;
    }
    ++*count;
  });
  return h;
}

TEST(MapGenerator, SeededBenchmarkMapsAreUnchanged) {
  // Hashes recorded with the generator before walls and rings existed (libstdc++'s
  // mt19937/uniform_real_distribution; another standard library would give other maps).
  struct Case {
    ObstacleDensity density;
    uint32_t seed;
    int placed;
    size_t occupied;
    uint64_t hash;
  };
  const Case cases[] = {
      {ObstacleDensity::kLow, 42, 37, 30220, 0xab7894d7cc0c8a55ull},
      {ObstacleDensity::kMedium, 1, 75, 53114, 0x7dec3c8a4139f8ceull},
      {ObstacleDensity::kHigh, 7, 113, 95423, 0x082b7c3881802076ull},
  };
  for (const Case& c : cases) {
    auto map = forestWindow();
    EXPECT_EQ(generateForest(scenario(c.density), c.seed, map.get()), c.placed) << toString(c.density);
    size_t count = 0;
    EXPECT_EQ(occupiedHash(*map, &count), c.hash) << toString(c.density);
    EXPECT_EQ(count, c.occupied) << toString(c.density);
  }
}

TEST(MapGenerator, ZeroDensityKindsDrawNothingAndAddedKindsKeepTheOthers) {
  ForestConfig base = scenario(ObstacleDensity::kMedium);
  ForestConfig shaped = base;  // other wall/ring sizes, densities still zero: same map
  shaped.wall_length_max_m = 5.0;
  shaped.ring_radius_min_m = 0.7;
  auto a = forestWindow(), b = forestWindow();
  std::vector<ForestObstacle> placed_a, placed_b;
  generateForest(base, 5, a.get(), &placed_a);
  generateForest(shaped, 5, b.get(), &placed_b);
  EXPECT_EQ(a->logOdds(), b->logOdds());

  // With walls and rings on, the pillars and boxes are the same ones, placed first.
  ForestConfig more = base;
  more.walls_per_m2 = 0.02;
  more.rings_per_m2 = 0.02;
  auto c = forestWindow();
  std::vector<ForestObstacle> placed_c;
  generateForest(more, 5, c.get(), &placed_c);
  ASSERT_GT(placed_c.size(), placed_a.size());
  for (size_t i = 0; i < placed_a.size(); ++i) {
    EXPECT_EQ(placed_c[i].kind, placed_a[i].kind);
    EXPECT_EQ(placed_c[i].center, placed_a[i].center);
  }
  int walls = 0, rings = 0;
  for (const ForestObstacle& o : placed_c) {
    walls += o.kind == ForestObstacle::Kind::kWall;
    rings += o.kind == ForestObstacle::Kind::kRing;
  }
  EXPECT_GT(walls, 0);
  EXPECT_GT(rings, 0);
  // Every voxel occupied before still is (obstacles are only added).
  a->forEachOccupied([&](const Eigen::Vector3i& i) { EXPECT_TRUE(c->isOccupied(i)); });
}

TEST(MapGenerator, WallsAndRingsAreRasterisedExactly) {
  ForestConfig f;
  f.pillars_per_m2 = 0.0;
  f.floating_per_m2 = 0.0;
  f.walls_per_m2 = 0.03;
  f.rings_per_m2 = 0.05;
  f.ring_radius_min_m = 0.6;  // hole clearly larger than the tube
  f.keep_free = {{5.0, 5.0, 1.5}};
  f.keep_free_radius_m = 1.5;
  auto map = test::makeMap({10.0, 10.0, 3.0}, {0.0, 0.0, 0.0});
  std::vector<ForestObstacle> placed;
  const int n = generateForest(f, 11, map.get(), &placed);
  ASSERT_EQ(size_t(n), placed.size());
  ASSERT_GE(n, 3);
  ASSERT_TRUE(std::any_of(placed.begin(), placed.end(),
                          [](const ForestObstacle& o) { return o.kind == ForestObstacle::Kind::kRing; }));

  // Oracle: a voxel is occupied exactly when its centre lies in one of the placed shapes.
  const GridGeometry& g = map->geometry();
  const VoxelBox w = g.windowBox();
  Eigen::Vector3i i;
  size_t occupied = 0, mismatches = 0;
  for (i.z() = w.min.z(); i.z() <= w.max.z(); ++i.z())
    for (i.y() = w.min.y(); i.y() <= w.max.y(); ++i.y())
      for (i.x() = w.min.x(); i.x() <= w.max.x(); ++i.x()) {
        const Eigen::Vector3d p = g.centerOf(i);
        const bool inside =
            std::any_of(placed.begin(), placed.end(), [&](const ForestObstacle& o) { return o.contains(p); });
        occupied += map->isOccupied(i);
        mismatches += inside != map->isOccupied(i);
        EXPECT_NE(map->state(i), VoxelState::kUnknown);
      }
  EXPECT_EQ(mismatches, 0u);
  EXPECT_GT(occupied, 500u);

  for (const ForestObstacle& o : placed) {
    if (o.kind == ForestObstacle::Kind::kRing) {
      // The hole is free; the tube (one radius out along a direction in the ring's plane) is not.
      EXPECT_FALSE(o.contains(o.center));
      const Eigen::Vector3d in_plane = o.center + o.radius_m * Eigen::Vector3d::UnitZ();
      EXPECT_TRUE(o.contains(in_plane));
      EXPECT_GE(o.radius_m, f.ring_radius_min_m);
      EXPECT_LE(o.radius_m, f.ring_radius_max_m);
    } else {
      ASSERT_EQ(o.kind, ForestObstacle::Kind::kWall);
      EXPECT_NEAR(2.0 * o.half_size.y(), f.wall_thickness_m, 1e-12);
      EXPECT_GE(2.0 * o.half_size.x(), f.wall_length_min_m);
      EXPECT_LE(2.0 * o.half_size.x(), f.wall_length_max_m);
      EXPECT_TRUE(o.contains(o.center + Eigen::Vector3d(0.0, 0.0, 1.0)));
      EXPECT_FALSE(o.contains(o.center + Eigen::Vector3d(0.0, 0.0, f.pillar_height_m + 0.01)));
    }
  }
  // The keep-free ball stays free.
  map->forEachOccupied([&](const Eigen::Vector3i& v) {
    EXPECT_GT((g.centerOf(v) - f.keep_free[0]).norm(), f.keep_free_radius_m) << v.transpose();
  });
}

// Window walls close the whole window in y except their openings, which are cut through any
// pillar or box in the slab; the walls keep off the kept points.
TEST(MapGenerator, WindowWallsCloseTheWindowExceptTheirOpenings) {
  ForestConfig f = ForestConfig::preset(ObstacleDensity::kMedium);
  f.window_walls = 2;
  f.keep_free = {{-11.0, 0.0, 1.0}};
  f.keep_free_radius_m = 1.5;
  auto map = forestWindow();
  std::vector<ForestObstacle> placed;
  generateForest(f, 5, map.get(), &placed);
  std::vector<ForestObstacle> walls;
  for (const ForestObstacle& o : placed)
    if (o.kind == ForestObstacle::Kind::kWindowWall) walls.push_back(o);
  ASSERT_EQ(walls.size(), 2u);
  const GridGeometry& g = map->geometry();
  for (const ForestObstacle& o : walls) {
    EXPECT_GE(int(o.openings.size()), f.windows_min);
    EXPECT_LE(int(o.openings.size()), f.windows_max);
    EXPECT_GT(std::abs(o.center.x() - f.keep_free[0].x()), f.keep_free_radius_m);
    // Along the wall's centre plane: occupied exactly outside the openings (whatever else stands there).
    size_t mismatches = 0, free_cells = 0;
    for (double y = -9.95; y < 10.0; y += 0.1)
      for (double z = 0.05; z < 3.0; z += 0.1) {
        const Eigen::Vector3i i = g.indexOf(Eigen::Vector3d(o.center.x(), y, z));
        const Eigen::Vector3d c = g.centerOf(i);
        bool in_opening = false;
        for (const Eigen::Vector4d& op : o.openings)
          in_opening = in_opening || (std::abs(c.y() - op[0]) <= op[2] && std::abs(c.z() - op[1]) <= op[3]);
        mismatches += map->isOccupied(i) == in_opening;
        mismatches += o.contains(c) == in_opening;
        free_cells += in_opening;
      }
    EXPECT_EQ(mismatches, 0u);
    EXPECT_GT(free_cells, size_t(0.8 * 0.8 / 0.01 * 0.5));
    for (const Eigen::Vector4d& op : o.openings) {
      EXPECT_GE(2.0 * op[2], f.window_size_min_m - 1e-9);
      EXPECT_LE(2.0 * op[2], f.window_size_max_m + 1e-9);
    }
  }
  // The pillars and boxes are those of the same seed without window walls (they draw after them).
  ForestConfig plain = f;
  plain.window_walls = 0;
  std::vector<ForestObstacle> before;
  auto a = forestWindow();
  generateForest(plain, 5, a.get(), &before);
  ASSERT_EQ(before.size() + walls.size(), placed.size());
  for (size_t k = 0; k < before.size(); ++k) {
    EXPECT_EQ(before[k].kind, placed[k].kind);
    EXPECT_EQ(before[k].center, placed[k].center);
  }
  std::string why;
  plain.windows_min = 0;
  EXPECT_FALSE(plain.validate(&why));
}

// The styles the simulator and the flight benchmark share.
TEST(MapGenerator, StylesAddTheirObstaclesToTheDensitys) {
  const ForestConfig medium = ForestConfig::preset(ObstacleDensity::kMedium);
  ForestConfig f = medium;
  EXPECT_TRUE(f.applyStyle("forest"));
  EXPECT_EQ(f.walls_per_m2 + f.rings_per_m2 + f.window_walls, 0.0);
  f = medium;
  EXPECT_TRUE(f.applyStyle("windows"));
  EXPECT_EQ(f.window_walls, 2);
  EXPECT_EQ(f.pillars_per_m2, medium.pillars_per_m2);
  f = medium;
  EXPECT_TRUE(f.applyStyle("boxes"));
  EXPECT_EQ(f.pillars_per_m2, 0.5 * medium.pillars_per_m2);
  EXPECT_GT(f.floating_per_m2, medium.floating_per_m2);
  f = medium;
  EXPECT_TRUE(f.applyStyle("mixed"));
  EXPECT_GT(f.walls_per_m2, 0.0);
  EXPECT_GT(f.rings_per_m2, 0.0);
  EXPECT_EQ(f.window_walls, 1);
  f = medium;
  EXPECT_FALSE(f.applyStyle("cave"));
  EXPECT_TRUE(f.validate(nullptr));
}

TEST(MapGenerator, ValidateRefusesBadConfigs) {
  std::string why;
  EXPECT_TRUE(ForestConfig().validate(&why)) << why;
  ForestConfig f;
  f.walls_per_m2 = -1.0;
  EXPECT_FALSE(f.validate(&why));
  EXPECT_NE(why.find("densities"), std::string::npos);
  f = ForestConfig();
  f.ring_radius_min_m = 2.0;  // above the max
  EXPECT_FALSE(f.validate(&why));
  f = ForestConfig();
  f.pillars_per_m2 = NAN;
  EXPECT_FALSE(f.validate(&why));
  f = ForestConfig();
  f.keep_free = {{NAN, 0.0, 0.0}};
  EXPECT_FALSE(f.validate(&why));
}

}  // namespace
}  // namespace topo_planner
