// The true map of the simulation: window from the points, exact obstacle distances against a
// brute-force oracle (every occupied cube), sphere contacts, and bad input.
#include <gtest/gtest.h>

#include <cmath>
#include <random>

#include "topo_planner/plan_env/map_generator.h"
#include "topo_planner/uav_sim/truth_map.h"

namespace topo_planner {
namespace {

double cubeDistance(const Eigen::Vector3d& p, const Eigen::Vector3d& center, double res) {
  const Eigen::Vector3d lo = center - Eigen::Vector3d::Constant(0.5 * res), hi = lo + Eigen::Vector3d::Constant(res);
  return (lo - p).cwiseMax(p - hi).cwiseMax(0.0).norm();
}

// Occupied voxel centres of a small seeded forest.
std::vector<Eigen::Vector3d> forestPoints(uint32_t seed) {
  OccupancyMap::Config c;
  c.size_m = {6.0, 5.0, 3.0};
  c.origin_m = {-3.0, -2.5, 0.0};
  std::string error;
  auto map = OccupancyMap::create(c, &error);
  ForestConfig f = ForestConfig::preset(ObstacleDensity::kHigh);
  f.rings_per_m2 = 0.05;
  generateForest(f, seed, map.get());
  std::vector<Eigen::Vector3d> points;
  map->forEachOccupied([&](const Eigen::Vector3i& i) { points.push_back(map->geometry().centerOf(i)); });
  return points;
}

TEST(TruthMap, WindowHoldsPointsAndIncludePoints) {
  const std::vector<Eigen::Vector3d> points = forestPoints(3);
  ASSERT_GT(points.size(), 100u);
  TruthMap::Config c;
  c.include_points = {{-8.0, 0.0, 1.0}, {6.0, 1.0, 1.0}};
  c.margin_m = 1.0;
  std::string error;
  TruthMap::BuildStats stats;
  const auto map = TruthMap::build(points, c, &error, &stats);
  ASSERT_TRUE(map) << error;
  EXPECT_EQ(stats.occupied_voxels, points.size());
  EXPECT_EQ(map->numOccupied(), points.size());
  const GridGeometry& g = map->geometry();
  EXPECT_LE(g.windowMin().x(), -9.0 + 1e-9);
  EXPECT_GE(g.windowMax().x(), 7.0 - 1e-9);
  EXPECT_LE(g.windowMin().z(), -1.0 + 1e-9);
  for (const Eigen::Vector3d& p : points) EXPECT_TRUE(map->occupancy().isOccupied(g.indexOf(p)));
  EXPECT_EQ(map->occupancy().countState(VoxelState::kUnknown), 0u);  // all known: queries say kOk
  EXPECT_EQ(map->esdf().query(Eigen::Vector3d(-8.0, 0.0, 1.0)).status, QueryStatus::kOk);
}

TEST(TruthMap, ObstacleDistanceMatchesBruteForce) {
  const std::vector<Eigen::Vector3d> points = forestPoints(5);
  TruthMap::Config c;
  c.include_points = {{-5.0, 0.0, 1.0}};
  std::string error;
  const auto map = TruthMap::build(points, c, &error);
  ASSERT_TRUE(map) << error;
  const double res = c.resolution_m;
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> ux(-6.0, 4.5), uy(-4.0, 4.0), uz(-0.5, 3.5);
  int exact = 0, inside = 0;
  for (int k = 0; k < 3000; ++k) {
    const Eigen::Vector3d p(ux(rng), uy(rng), uz(rng));
    double truth = INFINITY;
    for (const Eigen::Vector3d& q : points) truth = std::min(truth, cubeDistance(p, q, res));
    for (const double r : {0.15, 0.6}) {
      const double d = map->obstacleDistance(p, r);
      if (truth < r) {
        ASSERT_NEAR(d, truth, 1e-9) << p.transpose() << " r " << r;
        ++exact;
        inside += truth == 0.0;
      } else {
        ASSERT_GE(d, r) << p.transpose();             // says "at least r"
        ASSERT_LE(d, truth + 1e-9) << p.transpose();  // and is a true lower bound
      }
      double reported;
      EXPECT_EQ(map->sphereInCollision(p, r, &reported), truth < r);
      EXPECT_EQ(reported, d);
    }
  }
  EXPECT_GT(exact, 200);  // the narrow phase was exercised
  EXPECT_GT(inside, 10);
}

TEST(TruthMap, OutsideTheWindowAndBadInput) {
  TruthMap::Config c;
  c.margin_m = 0.5;
  std::string error;
  const auto map = TruthMap::build({{0.05, 0.05, 0.05}, {NAN, 0.0, 0.0}}, c, &error);
  ASSERT_TRUE(map) << error;
  // Far outside: the distance to the window bounds it from below.
  const double d = map->obstacleDistance({10.0, 0.0, 0.0}, 0.15);
  EXPECT_GE(d, 9.0);
  EXPECT_LE(d, 10.0);
  EXPECT_NEAR(map->obstacleDistance({0.35, 0.05, 0.05}, 0.5), 0.25, 1e-9);
  EXPECT_TRUE(std::isnan(map->obstacleDistance({NAN, 0.0, 0.0}, 0.15)));
  EXPECT_FALSE(map->sphereInCollision({NAN, 0.0, 0.0}, 0.15));

  TruthMap::BuildStats stats;
  const auto empty = TruthMap::build({}, c, &error, &stats);
  ASSERT_TRUE(empty) << error;
  EXPECT_EQ(stats.occupied_voxels, 0u);
  EXPECT_GE(empty->obstacleDistance({0.0, 0.0, 0.0}, 0.15), 0.15);

  TruthMap::Config bad = c;
  bad.resolution_m = 0.0;
  EXPECT_FALSE(TruthMap::build({}, bad, &error));
  EXPECT_NE(error.find("resolution_m"), std::string::npos);
  // A stray point far away would need a huge window: refused, not allocated.
  EXPECT_FALSE(TruthMap::build({{0.0, 0.0, 0.0}, {5000.0, 5000.0, 100.0}}, c, &error));
}

// The simulator's collision count: a vehicle hovering at a surface, its clearance jittering around the
// radius (as a lagging controller left it under TSan: 0.1498 m, then 0.1502 m, then 0.1499 m), is one
// collision; backing off past the release margin and coming back is a second.
TEST(ContactCounter, JitterAtTheSurfaceIsOneContact) {
  ContactCounter c(0.15, 0.05);
  EXPECT_FALSE(c.update(0.30));
  EXPECT_FALSE(c.inContact());
  EXPECT_TRUE(c.update(0.1498));
  int new_contacts = 0;
  for (int i = 0; i < 100; ++i) new_contacts += c.update(i % 2 ? 0.1499 : 0.1502);
  EXPECT_EQ(new_contacts, 0);
  EXPECT_FALSE(c.update(0.1999));  // not yet clear by the margin
  EXPECT_FALSE(c.update(0.14));
  EXPECT_TRUE(c.inContact());
  EXPECT_FALSE(c.update(NAN));  // no position: no change
  EXPECT_TRUE(c.inContact());
  EXPECT_FALSE(c.update(0.21));  // clear by more than the margin: the contact ends
  EXPECT_FALSE(c.inContact());
  EXPECT_TRUE(c.update(0.10));  // and entering again is a new one
  EXPECT_DOUBLE_EQ(c.exactWithin(), 0.20);

  ContactCounter no_margin(0.15, 0.0);  // the old rule: every crossing counts
  int crossings = 0;
  for (int i = 0; i < 10; ++i) crossings += no_margin.update(i % 2 ? 0.1502 : 0.1498);
  EXPECT_EQ(crossings, 5);
}

}  // namespace
}  // namespace topo_planner
