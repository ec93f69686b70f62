// MissionProgress: the distance left along a mission's way, and when it last shrank.
#include <gtest/gtest.h>

#include "topo_planner/topo_replan/mission_progress.h"

namespace topo_planner {
namespace {

TEST(MissionProgress, GainsAlongAStraightWayAndNotWhileHovering) {
  MissionProgress m;
  m.reset({{0, 0, 1}, {10, 0, 1}}, 0.0, {0, 0, 1}, false);
  EXPECT_NEAR(m.remaining(), 10.0, 1e-9);
  for (int k = 1; k <= 40; ++k) m.update(0.1 * k, {0.1 * k, 0.0, 1.0});  // 1 m/s for 4 s
  EXPECT_NEAR(m.remaining(), 6.0, 1e-9);
  const double gain = m.lastGain();  // a gain is more than 0.5 m: every 0.6 m at 0.1 m steps
  EXPECT_NEAR(gain, 3.6, 1e-6);
  for (int k = 41; k <= 200; ++k) m.update(0.1 * k, {4.0, 0.05 * std::sin(k), 1.0});  // hovering
  EXPECT_EQ(m.lastGain(), gain);
  EXPECT_NEAR(m.sinceGain(20.0), 20.0 - gain, 1e-9);
}

// A vehicle that shuttles back and forth (every plan succeeds, each short) gains once, not each time.
TEST(MissionProgress, ShuttlingIsNoProgress) {
  MissionProgress m;
  m.reset({{0, 0, 1}, {20, 0, 1}}, 0.0, {0, 0, 1}, false);
  double t = 0.0;
  for (int cycle = 0; cycle < 10; ++cycle)
    for (int k = 0; k < 40; ++k) {
      t += 0.1;
      const double x = 5.0 + 1.0 * std::sin(0.157 * k);  // between 4 and 6 m
      m.update(t, {x, 0.3, 1.0});
    }
  EXPECT_LT(m.lastGain(), 5.0);  // gains while it first reached 6 m, none after
  EXPECT_GT(m.sinceGain(t), 35.0);
  EXPECT_NEAR(m.best(), 14.0, 0.6);
}

// A way that doubles back (to a window far aside and back behind the wall): the projection stays on
// the stretch the vehicle flies, and is not short-cut to the stretch behind the wall 0.4 m away.
TEST(MissionProgress, AWayThatDoublesBackIsNotShortCut) {
  const Path way{{0, 0, 1}, {0, 8, 1}, {1, 8, 1}, {1, 0, 1}, {6, 0, 1}};  // length 8 + 1 + 8 + 5 = 22
  MissionProgress m;
  m.reset(way, 0.0, {0, 0, 1}, false);
  EXPECT_NEAR(m.remaining(), 22.0, 1e-9);
  EXPECT_LT((m.ahead(8.5) - Eigen::Vector3d(0.5, 8, 1)).norm(), 1e-9);
  EXPECT_LT((m.ahead(100.0) - Eigen::Vector3d(6, 0, 1)).norm(), 1e-9);
  // Up the first leg: the return leg is 1 m beside it, the distance left shrinks by what is flown
  // (up to 2 m before the corner, where the second leg is as near).
  for (int k = 1; k <= 30; ++k) {
    m.update(0.1 * k, {0.4, 0.2 * k, 1.0});
    ASSERT_NEAR(m.remaining(), 22.0 - 0.2 * k + 0.4, 1e-9) << k;
  }
  // At the start, 0.6 m from the first leg and 0.4 m from the return leg: on the first leg (a global
  // nearest point would leave 6.4 m).
  m.reset(way, 5.0, {0.6, 1.0, 1.0}, true);
  EXPECT_NEAR(m.remaining(), 21.6, 1e-9);
}

// A new way for the same mission (a re-route) re-bases the measure and keeps the clock; a new
// mission restarts it; a shift moves it (time jump, inputs stale).
TEST(MissionProgress, ReBasingKeepsTheClockOfTheMission) {
  MissionProgress m;
  m.reset({{0, 0, 1}, {10, 0, 1}}, 0.0, {0, 0, 1}, false);
  m.update(1.0, {2, 0, 1});
  EXPECT_NEAR(m.lastGain(), 1.0, 1e-9);
  // Re-routed at 6 s on a longer way (a wall found): 14 m left, no gain, the clock goes on.
  m.reset({{2, 0, 1}, {2, 6, 1}, {10, 6, 1}, {10, 0, 1}}, 6.0, {2, 0, 1}, true);
  EXPECT_NEAR(m.remaining(), 20.0, 1e-9);
  EXPECT_NEAR(m.lastGain(), 1.0, 1e-9);
  m.update(7.0, {2, 0.3, 1});  // 0.3 m along the new way: less than the gain
  EXPECT_NEAR(m.lastGain(), 1.0, 1e-9);
  m.update(8.0, {2, 1.0, 1});
  EXPECT_NEAR(m.lastGain(), 8.0, 1e-9);
  m.shift(2.5);
  EXPECT_NEAR(m.lastGain(), 10.5, 1e-9);
  m.reset({{2, 1, 1}, {3, 1, 1}}, 20.0, {2, 1, 1}, false);
  EXPECT_NEAR(m.lastGain(), 20.0, 1e-9);
  m.clear();
  EXPECT_FALSE(m.active());
  EXPECT_TRUE(std::isnan(m.update(21.0, {2.5, 1, 1})));
  EXPECT_EQ(m.sinceGain(30.0), 0.0);
}

TEST(MissionProgress, RefusesNonFiniteInput) {
  MissionProgress m;
  m.reset({{NAN, 0, 1}}, 0.0, {0, 0, 1}, false);
  EXPECT_FALSE(m.active());
  m.reset({{0, 0, 1}, {NAN, 0, 1}, {4, 0, 1}}, 0.0, {0, 0, 1}, false);  // the bad point is dropped
  ASSERT_TRUE(m.active());
  EXPECT_NEAR(m.remaining(), 4.0, 1e-9);
  EXPECT_TRUE(std::isnan(m.update(1.0, {INFINITY, 0, 1})));
  EXPECT_TRUE(std::isnan(m.update(NAN, {1, 0, 1})));
  EXPECT_NEAR(m.remaining(), 4.0, 1e-9);
  EXPECT_NEAR(m.lastGain(), 0.0, 1e-9);
  m.update(1.0, {1, 0, 1});
  EXPECT_NEAR(m.remaining(), 3.0, 1e-9);
}

}  // namespace
}  // namespace topo_planner
