// The route check on its own (route_watch.h): a wall newly seen across the route ahead blocks it; a
// pillar on it, an obstacle already there when the route was searched, one behind the vehicle or
// beyond the check length do not.
#include "topo_planner/topo_replan/route_watch.h"

#include <gtest/gtest.h>

#include "topo_planner/plan_env/synthetic_scene.h"

namespace topo_planner {
namespace {

// A 30 x 12 x 3 m hall; the route runs straight along y = 6, z = 1.5 from x = 1 to x = 29.
const Path kRoute{{1.0, 6.0, 1.5}, {29.0, 6.0, 1.5}};

RouteWatch::Config config() {
  RouteWatch::Config c;
  c.min_z_m = 0.5;
  c.max_z_m = 2.5;
  return c;
}

TEST(RouteWatch, AWallNewlySeenAcrossTheRouteAheadBlocksIt) {
  SyntheticScene searched(Eigen::Vector3d(30.0, 12.0, 3.0));
  RouteWatch watch(config());
  watch.reset(kRoute, searched.finish());
  ASSERT_FALSE(watch.empty());
  // A full wall at x = 10 seen since.
  SyntheticScene now(Eigen::Vector3d(30.0, 12.0, 3.0));
  now.box(Eigen::Vector3d(10.0, 0.0, 0.0), Eigen::Vector3d(10.3, 12.0, 3.0));
  const EsdfMap& map = now.finish();
  const std::optional<RouteWatch::Blocked> blocked = watch.check(Eigen::Vector3d(2.0, 6.0, 1.5), map);
  ASSERT_TRUE(blocked);
  EXPECT_NEAR(blocked->where.x(), 9.85, 0.11);  // the first sample within the 0.2 m clearance
  EXPECT_NEAR(blocked->ahead_m, blocked->where.x() - 2.0, 0.11);
  EXPECT_LT(blocked->distance_m, 0.2);
  // Beyond the check length: not yet.
  RouteWatch::Config near = config();
  near.check_length_m = 6.0;
  RouteWatch short_watch(near);
  short_watch.reset(kRoute, searched.finish());
  EXPECT_FALSE(short_watch.check(Eigen::Vector3d(2.0, 6.0, 1.5), map));
  // Behind the vehicle (it found itself past the wall): nothing ahead.
  EXPECT_FALSE(watch.check(Eigen::Vector3d(12.0, 6.0, 1.5), map));
}

TEST(RouteWatch, WhatTheLocalPlannerCanPassDoesNotBlockIt) {
  SyntheticScene searched(Eigen::Vector3d(30.0, 12.0, 3.0));
  // A wall with a window on the route, there when the route was searched (through the window).
  searched.box(Eigen::Vector3d(20.0, 0.0, 0.0), Eigen::Vector3d(20.3, 12.0, 3.0));
  searched.fill([](const Eigen::Vector3d& p) { return std::abs(p.y() - 6.0) < 0.15 && std::abs(p.z() - 1.5) < 0.15; },
                VoxelState::kFree);
  RouteWatch watch(config());
  watch.reset(kRoute, searched.finish());
  // Since: a pillar on the route (a way past it beside), and the same wall.
  SyntheticScene now(Eigen::Vector3d(30.0, 12.0, 3.0));
  now.pillar(8.0, 6.0, 0.3);
  now.box(Eigen::Vector3d(20.0, 0.0, 0.0), Eigen::Vector3d(20.3, 12.0, 3.0));
  now.fill([](const Eigen::Vector3d& p) { return std::abs(p.y() - 6.0) < 0.15 && std::abs(p.z() - 1.5) < 0.15; },
           VoxelState::kFree);
  const EsdfMap& map = now.finish();
  EXPECT_FALSE(watch.check(Eigen::Vector3d(2.0, 6.0, 1.5), map));
  EXPECT_FALSE(watch.check(Eigen::Vector3d(12.0, 6.0, 1.5), map));  // the narrow window: as searched
  // The pillar grown into a wall with no way past within reach blocks it.
  SyntheticScene closed(Eigen::Vector3d(30.0, 12.0, 3.0));
  closed.box(Eigen::Vector3d(7.7, 0.0, 0.0), Eigen::Vector3d(8.3, 12.0, 3.0));
  RouteWatch fresh(config());
  fresh.reset(kRoute, searched.finish());
  EXPECT_TRUE(fresh.check(Eigen::Vector3d(2.0, 6.0, 1.5), closed.finish()));
}

}  // namespace
}  // namespace topo_planner
