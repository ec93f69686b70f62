// The global route: it finds openings anywhere in a wall, proves closed maps unreachable, keeps its
// clearance and height band, and starts from a hover closer to an obstacle than its clearance.
#include <gtest/gtest.h>

#include "topo_planner/path_searching/global_router.h"
#include "topo_planner/path_searching/topo_path_search.h"
#include "topo_planner/plan_env/synthetic_scene.h"

namespace topo_planner {
namespace {

// A 24 x 16 x 3 m hall cut by a 0.2 m wall at x = 12 with one 1.0 x 1.0 m window at (y, z).
SyntheticScene wallWithWindow(double window_y, double window_z) {
  SyntheticScene scene(Eigen::Vector3d(24.0, 16.0, 3.0));
  scene.fill([=](const Eigen::Vector3d& p) {
    const bool in_wall = p.x() >= 11.9 && p.x() <= 12.1;
    const bool in_window = std::abs(p.y() - window_y) <= 0.5 && std::abs(p.z() - window_z) <= 0.5;
    return in_wall && !in_window;
  });
  return scene;
}

// Every segment keeps `clearance` (interpolated ESDF sampled every 2 cm), except within `skip` of the ends.
double minClearance(const EsdfMap& map, const Path& path, double skip) {
  double worst = INFINITY;
  const Path fine = resamplePath(path, 0.02);
  for (const Eigen::Vector3d& p : fine) {
    if ((p - path.front()).norm() < skip || (p - path.back()).norm() < skip) continue;
    worst = std::min(worst, map.query(p).distance);
  }
  return worst;
}

TEST(GlobalRouter, FindsAWindowFarAsideInAWall) {
  SyntheticScene scene = wallWithWindow(14.5, 1.5);  // 6.5 m aside of the start-goal line
  const EsdfMap& map = scene.finish();
  GlobalRouter router{GlobalRouter::Config()};
  const Eigen::Vector3d start(2, 8, 1.5), goal(22, 8, 1.5);
  const GlobalRouter::Result r = router.route(map, start, goal);
  ASSERT_EQ(r.status, SearchStatus::kSuccess);
  EXPECT_EQ(r.path.front(), start);
  EXPECT_EQ(r.path.back(), goal);
  // Through the window: every crossing of x = 12 is inside it.
  int crossings = 0, outside = 0;
  const Path fine = resamplePath(r.path, 0.05);
  for (size_t i = 1; i < fine.size(); ++i)
    if ((fine[i - 1].x() - 12.0) * (fine[i].x() - 12.0) <= 0.0) {
      ++crossings;
      outside += !(std::abs(fine[i].y() - 14.5) < 0.5 && std::abs(fine[i].z() - 1.5) < 0.5);
    }
  EXPECT_GE(crossings, 1);
  EXPECT_EQ(outside, 0);
  // It keeps the clearance (a 1 m window leaves 0.2 m of play at 0.3 m) and is short: the detour
  // around the wall's window is at most 25% longer than the straight ways to and from the window.
  EXPECT_GE(minClearance(map, r.path, 0.0), 0.3 - 1e-6);
  const Eigen::Vector3d window(12, 14.5, 1.5);
  EXPECT_LT(r.length_m, 1.25 * ((window - start).norm() + (goal - window).norm()));
  EXPECT_LE(r.path.size(), 8u);  // shortened to a few corners

  // The local search alone, from the same start, samples around the line and finds no way.
  TopoPathSearch::Config sc;
  sc.roadmap.max_time_s = 0.0;
  TopoPathSearch search(sc);
  const TopoSearchResult local = search.search(map, start, goal);
  EXPECT_NE(local.status, SearchStatus::kSuccess);
}

// Where the line of the route crosses x = 12 (every crossing), resampled at 5 cm.
std::vector<Eigen::Vector3d> wallCrossings(const Path& path) {
  std::vector<Eigen::Vector3d> crossings;
  const Path fine = resamplePath(path, 0.05);
  for (size_t i = 1; i < fine.size(); ++i)
    if ((fine[i - 1].x() - 12.0) * (fine[i].x() - 12.0) <= 0.0) crossings.push_back(fine[i]);
  return crossings;
}

// Avoided zones (the FSM's stalls) weigh: the route takes the other window when the near one is
// avoided, goes through an avoided one when it is the only way (no false proof of unreachability),
// and its shortcuts do not cut through a zone.
TEST(GlobalRouter, AvoidedZonesWeighButNeverBlock) {
  SyntheticScene scene(Eigen::Vector3d(24.0, 16.0, 3.0));
  scene.fill([](const Eigen::Vector3d& p) {
    const bool in_wall = p.x() >= 11.9 && p.x() <= 12.1;
    const bool near = std::abs(p.y() - 8.0) <= 0.5 && std::abs(p.z() - 1.5) <= 0.5;
    const bool far = std::abs(p.y() - 13.0) <= 0.5 && std::abs(p.z() - 1.5) <= 0.5;
    return in_wall && !near && !far;
  });
  const EsdfMap& map = scene.finish();
  GlobalRouter router{GlobalRouter::Config()};
  const Eigen::Vector3d start(2, 8, 1.5), goal(22, 8, 1.5);
  GlobalRouter::Result r = router.route(map, start, goal);
  ASSERT_EQ(r.status, SearchStatus::kSuccess);
  for (const Eigen::Vector3d& c : wallCrossings(r.path)) EXPECT_NEAR(c.y(), 8.0, 0.5);

  router.setAvoided({{Eigen::Vector3d(11.0, 8.0, 1.5), 1.5}, {Eigen::Vector3d(NAN, 0, 0), 1.0}});
  ASSERT_EQ(router.avoided().size(), 1u);  // the non-finite zone is dropped
  r = router.route(map, start, goal);
  ASSERT_EQ(r.status, SearchStatus::kSuccess);
  const std::vector<Eigen::Vector3d> crossings = wallCrossings(r.path);
  ASSERT_FALSE(crossings.empty());
  for (const Eigen::Vector3d& c : crossings) EXPECT_NEAR(c.y(), 13.0, 0.5);
  for (const Eigen::Vector3d& p : resamplePath(r.path, 0.05))
    EXPECT_GT((p - Eigen::Vector3d(11.0, 8.0, 1.5)).norm(), 1.5 - 0.2) << p.transpose();

  // Zones at one place compound: at a light weight one zone is not worth the far window, three are.
  GlobalRouter::Config light;
  light.avoid_weight = 0.5;
  GlobalRouter light_router(light);
  const GlobalRouter::Zone near_window{Eigen::Vector3d(11.0, 8.0, 1.5), 1.5};
  light_router.setAvoided({near_window});
  r = light_router.route(map, start, goal);
  ASSERT_EQ(r.status, SearchStatus::kSuccess);
  for (const Eigen::Vector3d& c : wallCrossings(r.path)) EXPECT_NEAR(c.y(), 8.0, 0.5);
  light_router.setAvoided({near_window, near_window, near_window});
  r = light_router.route(map, start, goal);
  ASSERT_EQ(r.status, SearchStatus::kSuccess);
  for (const Eigen::Vector3d& c : wallCrossings(r.path)) EXPECT_NEAR(c.y(), 13.0, 0.5);

  // The far window closed: the avoided near one is the only way, and it is taken.
  SyntheticScene one = wallWithWindow(8.0, 1.5);
  const EsdfMap& one_map = one.finish();
  r = router.route(one_map, start, goal);
  ASSERT_EQ(r.status, SearchStatus::kSuccess);
  for (const Eigen::Vector3d& c : wallCrossings(r.path)) EXPECT_NEAR(c.y(), 8.0, 0.5);
  router.setAvoided({});
  EXPECT_TRUE(router.avoided().empty());
}

TEST(GlobalRouter, AClosedWallProvesTheGoalUnreachable) {
  SyntheticScene scene(Eigen::Vector3d(24.0, 8.0, 3.0));
  scene.box({11.8, -1, -1}, {12.2, 9, 4});
  const EsdfMap& map = scene.finish();
  GlobalRouter router{GlobalRouter::Config()};
  const GlobalRouter::Result r = router.route(map, {2, 4, 1.5}, {22, 4, 1.5});
  EXPECT_EQ(r.status, SearchStatus::kNoPath);
  EXPECT_TRUE(r.path.empty());
}

TEST(GlobalRouter, KeepsToTheHeightBand) {
  // The wall stops 0.6 m below the ceiling: over it is the only way.
  SyntheticScene scene(Eigen::Vector3d(24.0, 8.0, 3.0));
  scene.box({11.8, -1, -1}, {12.2, 9, 2.4});
  const EsdfMap& map = scene.finish();
  GlobalRouter::Config c;
  GlobalRouter open_band(c);
  const GlobalRouter::Result over = open_band.route(map, {2, 4, 1.0}, {22, 4, 1.0});
  ASSERT_EQ(over.status, SearchStatus::kSuccess);
  double top = 0.0;
  for (const Eigen::Vector3d& p : over.path) top = std::max(top, p.z());
  EXPECT_GT(top, 2.4);
  c.max_z_m = 2.2;  // a geofence below the gap
  GlobalRouter fenced(c);
  EXPECT_EQ(fenced.route(map, {2, 4, 1.0}, {22, 4, 1.0}).status, SearchStatus::kNoPath);
}

TEST(GlobalRouter, KeepsAMarginInsideTheBandWhereItCan) {
  // A wall as high as the band (3 m) whose top 0.4 m the camera has not seen, and a window in it
  // 4 m aside. Without the margin the route goes over the wall through the unknown top; with it,
  // through the window. With the window closed the unknown top is the only way: taken (kNoPath
  // would claim the goal unreachable).
  for (const bool window : {true, false}) {
    SCOPED_TRACE(window ? "window" : "no window");
    SyntheticScene scene(Eigen::Vector3d(24.0, 12.0, 3.4));
    scene.box({11.8, -1, -1}, {12.2, 13, 3.0});
    scene.fill([](const Eigen::Vector3d& p) { return p.x() >= 11.8 && p.x() <= 12.2 && p.z() >= 2.6 && p.z() <= 3.0; },
               VoxelState::kUnknown);
    if (window)
      scene.fill([](const Eigen::Vector3d& p) { return p.x() >= 11.7 && p.x() <= 12.3 && std::abs(p.y() - 10.0) <= 0.6 &&
                                                      std::abs(p.z() - 1.5) <= 0.6; },
                 VoxelState::kFree);
    const EsdfMap& map = scene.finish();
    GlobalRouter::Config c;
    c.min_z_m = 0.3;
    c.max_z_m = 3.0;
    auto top = [](const GlobalRouter::Result& r) {
      double z = 0.0;
      for (const Eigen::Vector3d& p : r.raw) z = std::max(z, p.z());
      return z;
    };
    const GlobalRouter::Result none = GlobalRouter(c).route(map, {2, 6, 1.5}, {22, 6, 1.5});
    ASSERT_EQ(none.status, SearchStatus::kSuccess);
    EXPECT_GT(top(none), 2.7);  // over the wall
    c.band_margin_m = 0.3;
    const GlobalRouter::Result kept = GlobalRouter(c).route(map, {2, 6, 1.5}, {22, 6, 1.5});
    ASSERT_EQ(kept.status, SearchStatus::kSuccess);
    if (window) {
      EXPECT_LE(top(kept), 2.7 + 1e-9);
      bool through = false;
      for (const Eigen::Vector3d& p : kept.raw) through |= std::abs(p.x() - 12.0) < 0.3 && std::abs(p.y() - 10.0) < 0.6;
      EXPECT_TRUE(through);
    } else {
      EXPECT_GT(top(kept), 2.7);
    }
  }
}

TEST(GlobalRouter, RoutesThroughUnknownSpaceOnlyWhenAllowed) {
  // The only way past the wall is a gap of unknown space.
  SyntheticScene scene(Eigen::Vector3d(24.0, 8.0, 3.0));
  scene.box({11.8, -1, -1}, {12.2, 9, 4});
  scene.box({11.8, 3.0, 0.5}, {12.2, 5.0, 2.5});
  scene.fill([](const Eigen::Vector3d& p) { return p.x() >= 11.8 && p.x() <= 12.2 && p.y() >= 3.0 && p.y() <= 5.0 &&
                                                  p.z() >= 0.5 && p.z() <= 2.5; },
             VoxelState::kUnknown);
  const EsdfMap& map = scene.finish();
  GlobalRouter::Config c;
  EXPECT_EQ(GlobalRouter(c).route(map, {2, 4, 1.5}, {22, 4, 1.5}).status, SearchStatus::kSuccess);
  c.unknown_is_free = false;
  EXPECT_EQ(GlobalRouter(c).route(map, {2, 4, 1.5}, {22, 4, 1.5}).status, SearchStatus::kNoPath);
}

TEST(GlobalRouter, StartsFromAHoverInsideItsClearance) {
  SyntheticScene scene(Eigen::Vector3d(24.0, 8.0, 3.0));
  scene.pillar(5.0, 4.0, 0.4);
  const EsdfMap& map = scene.finish();
  GlobalRouter router{GlobalRouter::Config()};
  const Eigen::Vector3d start(5.0, 4.0 - 0.4 - 0.18, 1.5);  // 0.18 m from the pillar
  ASSERT_LT(map.query(start).distance, 0.3);
  const GlobalRouter::Result r = router.route(map, start, {20, 4, 1.5});
  ASSERT_EQ(r.status, SearchStatus::kSuccess);
  EXPECT_GE(minClearance(map, r.path, 0.6), 0.3 - 1e-6);
  // ... but not from inside an obstacle.
  EXPECT_EQ(router.route(map, {5.0, 4.0, 1.5}, {20, 4, 1.5}).status, SearchStatus::kStartInObstacle);
  EXPECT_EQ(router.route(map, {20, 4, 1.5}, {5.0, 4.0, 1.5}).status, SearchStatus::kGoalInObstacle);
}

TEST(GlobalRouter, ForestRoutesAreNearlyStraightAndCheap) {
  for (uint32_t seed = 1; seed <= 4; ++seed) {
    const Eigen::Vector3d start(-15, 0, 1), goal(15, -4, 1.3);
    SyntheticScene scene = SyntheticScene::simulationForest(ObstacleDensity::kHigh, seed, {start, goal});
    const EsdfMap& map = scene.finish();
    GlobalRouter router{GlobalRouter::Config()};
    const GlobalRouter::Result r = router.route(map, start, goal);
    ASSERT_EQ(r.status, SearchStatus::kSuccess) << "seed " << seed;
    EXPECT_LT(r.length_m, 1.2 * (goal - start).norm()) << "seed " << seed;
    // The shortcuts keep 0.3 m at the voxel centres they cross; between centres the interpolated
    // field may dip up to about half a voxel below.
    EXPECT_GE(minClearance(map, r.path, 0.0), 0.25) << "seed " << seed;
    // Weighted A* on 0.2 m cells: a few thousand expansions for a 30 m crossing.
    EXPECT_LT(r.expansions, 30000) << "seed " << seed;
    std::printf("forest seed %u: route %.1f m (straight %.1f), %zu corners, %d expansions\n", seed, r.length_m,
                (goal - start).norm(), r.path.size(), r.expansions);
  }
}

TEST(GlobalRouter, RefusesBadInputAndStopsAtItsBudget) {
  SyntheticScene scene = wallWithWindow(14.5, 1.5);
  const EsdfMap& map = scene.finish();
  GlobalRouter router{GlobalRouter::Config()};
  EXPECT_EQ(router.route(map, {NAN, 1, 1}, {22, 8, 1.5}).status, SearchStatus::kInvalidInput);
  EXPECT_EQ(router.route(map, {2, 8, 1.5}, {INFINITY, 8, 1.5}).status, SearchStatus::kInvalidInput);
  EXPECT_EQ(router.route(map, {2, 8, 1.5}, {50, 8, 1.5}).status, SearchStatus::kOutOfMap);
  GlobalRouter::Config c;
  c.max_expansions = 100;
  GlobalRouter small(c);
  const GlobalRouter::Result r = small.route(map, {2, 8, 1.5}, {22, 8, 1.5});
  EXPECT_EQ(r.status, SearchStatus::kBudgetExhausted);
  EXPECT_EQ(r.expansions, 101);
  std::string why;
  c = GlobalRouter::Config();
  c.heuristic_weight = 0.5;
  EXPECT_FALSE(c.validate(&why));
  EXPECT_NE(why.find("heuristic_weight"), std::string::npos);
  EXPECT_EQ(GlobalRouter(c).route(map, {2, 8, 1.5}, {22, 8, 1.5}).status, SearchStatus::kInvalidInput);
  c = GlobalRouter::Config();
  c.cell_voxels = 9;
  EXPECT_FALSE(c.validate(&why));
  // One router across maps of other sizes (its buffers are reused, reset by generation) answers as
  // a fresh one does.
  SyntheticScene small_scene(Eigen::Vector3d(8.0, 6.0, 3.0));
  small_scene.pillar(4.0, 3.0, 0.5);
  const EsdfMap& small_map = small_scene.finish();
  const GlobalRouter::Result a = router.route(map, {2, 8, 1.5}, {22, 8, 1.5});
  const GlobalRouter::Result s1 = router.route(small_map, {1, 3, 1.5}, {7, 3, 1.5});
  const GlobalRouter::Result b = router.route(map, {2, 8, 1.5}, {22, 8, 1.5});
  GlobalRouter fresh{GlobalRouter::Config()};
  const GlobalRouter::Result s2 = fresh.route(small_map, {1, 3, 1.5}, {7, 3, 1.5});
  ASSERT_EQ(a.status, SearchStatus::kSuccess);
  ASSERT_EQ(s1.status, SearchStatus::kSuccess);
  EXPECT_EQ(a.path, b.path);
  EXPECT_EQ(a.expansions, b.expansions);
  EXPECT_EQ(s1.path, s2.path);
  EXPECT_EQ(s1.expansions, s2.expansions);
}

}  // namespace
}  // namespace topo_planner

namespace topo_planner {
namespace {

// The way back of a mission across a wall: the window it came through (4 m aside of the straight
// line) is known free, the rest of the wall's face unseen. With unknown space weighed, the route
// goes back through the known window; without, straight through the unseen wall, which the vehicle
// then finds closed when it gets there (at 4-5 m/s the way back timed out, failing wall after wall).
// An unknown way much shorter than the known one is still taken.
TEST(GlobalRouter, AKnownWindowIsPreferredToAnUnknownShortcut) {
  auto scene = [](double seen_until_y) {
    SyntheticScene s(Eigen::Vector3d(24.0, 16.0, 3.0));
    s.fill([](const Eigen::Vector3d& p) {
      return p.x() >= 11.9 && p.x() <= 12.1 && !(std::abs(p.y() - 12.0) <= 0.6 && std::abs(p.z() - 1.5) <= 0.6);
    });
    // Unknown: both sides of the wall except a corridor to and through the window.
    s.fill([=](const Eigen::Vector3d& p) { return p.x() > 6.0 && p.x() < 18.0 && p.y() < seen_until_y; },
           VoxelState::kUnknown);
    return s;
  };
  const Eigen::Vector3d start(20, 8, 1.5), goal(2, 8, 1.5), window(12, 12, 1.5);
  auto crossesAtWindow = [&](const Path& path) {
    for (const Eigen::Vector3d& p : resamplePath(path, 0.05))
      if (std::abs(p.x() - 12.0) < 0.06) return std::abs(p.y() - 12.0) < 0.6;
    return false;
  };
  SyntheticScene s = scene(10.5);
  const EsdfMap& map = s.finish();
  GlobalRouter::Config c;
  c.unknown_weight = 0.0;
  GlobalRouter plain(c);
  const GlobalRouter::Result straight = plain.route(map, start, goal);
  ASSERT_EQ(straight.status, SearchStatus::kSuccess);
  EXPECT_FALSE(crossesAtWindow(straight.path)) << "unknown as good as known: through the unseen wall";
  c.unknown_weight = 1.0;
  GlobalRouter weighed(c);
  const GlobalRouter::Result known = weighed.route(map, start, goal);
  ASSERT_EQ(known.status, SearchStatus::kSuccess);
  EXPECT_TRUE(crossesAtWindow(known.path)) << "through the window seen on the way out";
  // The shortening keeps it there: no shortcut from the window's corridor through unknown space.
  EXPECT_LT(known.length_m, 1.25 * ((window - start).norm() + (goal - window).norm()));
  // An unknown way much shorter: the window far aside (a detour of over twice the way) is not taken.
  const Eigen::Vector3d near_start(14, 2, 1.5), near_goal(10, 2, 1.5);
  const GlobalRouter::Result shortcut = weighed.route(map, near_start, near_goal);
  ASSERT_EQ(shortcut.status, SearchStatus::kSuccess);
  EXPECT_FALSE(crossesAtWindow(shortcut.path));
  c.unknown_weight = -1.0;
  std::string why;
  EXPECT_FALSE(c.validate(&why));
}

}  // namespace
}  // namespace topo_planner
