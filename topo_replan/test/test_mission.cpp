// The mission on its own (mission.h): goals checked on the map, waypoints passed, the reference
// along the route found for its goals, a goal proved unreachable (refused when new, the mission's
// end when its own), a route search overtaken by a stop, a wall newly seen across the route ahead,
// and the stall rule: a re-route, then a back-off, then the give-up, each marking a zone ahead.
#include "topo_planner/topo_replan/mission.h"

#include <gtest/gtest.h>

#include "topo_planner/plan_env/synthetic_scene.h"

namespace topo_planner {
namespace {

// A 30 x 12 x 3 m hall; the vehicle hovers at its west end, the goals lie east.
const Eigen::Vector3d kSize(30.0, 12.0, 3.0);
const Eigen::Vector3d kStart(2.0, 6.0, 1.5);
const Eigen::Vector3d kGoal(27.0, 6.0, 1.5);

Mission::Config config() {
  Mission::Config c;
  c.route.min_z_m = 0.5;
  c.route.max_z_m = 2.5;
  return c;
}

// A full wall across the hall at x (10 cm thick), with an opening 2 m wide at y = 2 when `door`.
void wall(SyntheticScene* scene, double x, bool door) {
  scene->box(Eigen::Vector3d(x, 0.0, 0.0), Eigen::Vector3d(x + 0.1, 12.0, 3.0));
  if (door)
    scene->fill([x](const Eigen::Vector3d& p) { return p.x() >= x - 0.05 && p.x() <= x + 0.2 && std::abs(p.y() - 2.0) < 1.0; },
                VoxelState::kFree);
}

// Searches and applies the route for what the mission asks next, from `from`.
Mission::RouteOutcome route(Mission* mission, const EsdfMap& map, const Eigen::Vector3d& from, std::string* text) {
  std::optional<Mission::RouteSearch> search = mission->prepareRouteSearch(map);
  if (!search) return Mission::RouteOutcome::kOvertaken;
  search->start = from;
  return mission->applyRoute(*search, mission->searchRoute(map, *search), map, text);
}

TEST(Mission, GoalsAreCheckedOnTheMap) {
  SyntheticScene scene(kSize);
  scene.pillar(15.0, 6.0, 0.5);
  const EsdfMap& map = scene.finish();
  Mission mission(config());
  std::string why;
  EXPECT_EQ(mission.check({kGoal}, map, &why), GoalStatus::kAccepted);
  EXPECT_EQ(mission.check({kGoal, Eigen::Vector3d(15.0, 6.0, 1.5)}, map, &why), GoalStatus::kGoalInObstacle);
  EXPECT_NE(why.find("goal 1"), std::string::npos) << why;
  EXPECT_EQ(mission.check({Eigen::Vector3d(45.0, 6.0, 1.5)}, map, &why), GoalStatus::kGoalOutOfMap);
  // Taken up by start(): a goal in the pillar is refused there too, and changes nothing.
  mission.give({Eigen::Vector3d(15.0, 6.0, 1.5)});
  EXPECT_TRUE(mission.pending());
  const Mission::Started s = mission.start(0.0, FlatState::atRest(kStart), map, ReferenceConfig());
  EXPECT_FALSE(s.ok);
  EXPECT_FALSE(s.goals_valid);
  EXPECT_EQ(mission.status(), GoalStatus::kGoalInObstacle);
  EXPECT_FALSE(mission.pending());
  EXPECT_TRUE(mission.empty());
}

TEST(Mission, WaypointsArePassedAndTheLastGoalEndsIt) {
  SyntheticScene scene(kSize);
  const EsdfMap& map = scene.finish();
  Mission::Config c = config();
  c.global_route = false;
  Mission mission(c);
  const std::vector<Eigen::Vector3d> goals{{10.0, 6.0, 1.5}, {20.0, 6.0, 1.5}, kGoal};
  mission.give(goals);
  const Mission::Started s = mission.start(0.0, FlatState::atRest(kStart), map, ReferenceConfig());
  ASSERT_TRUE(s.ok) << s.summary;
  EXPECT_EQ(s.summary, "new reference, 3 goal(s)");
  EXPECT_EQ(mission.remaining().size(), 3u);
  // The local goal stays before the first waypoint's pass.
  const double pass = mission.localGoalLimit(0.0);
  ASSERT_TRUE(std::isfinite(pass));
  EXPECT_LT((mission.reference().position(pass) - goals[0]).norm(), c.waypoint_reached_radius_m + 1e-6);
  mission.passWaypoints(Eigen::Vector3d(9.5, 6.0, 1.5));
  EXPECT_EQ(mission.remaining(), (std::vector<Eigen::Vector3d>{goals[1], kGoal}));
  mission.passWaypoints(Eigen::Vector3d(20.0, 6.2, 1.5));
  mission.passWaypoints(kGoal);  // the last goal is not passed, it is reached
  EXPECT_EQ(mission.remaining(), std::vector<Eigen::Vector3d>{kGoal});
  EXPECT_FALSE(std::isfinite(mission.localGoalLimit(0.0)));  // no waypoint left before the goal
  EXPECT_FALSE(mission.atLastGoal(Eigen::Vector3d(26.0, 6.0, 1.5)));
  EXPECT_TRUE(mission.atLastGoal(Eigen::Vector3d(27.2, 6.0, 1.5)));
  mission.reached();
  EXPECT_TRUE(mission.empty());
  EXPECT_TRUE(mission.remaining().empty());
}

TEST(Mission, TheReferenceFollowsTheRouteFoundForItsGoals) {
  SyntheticScene scene(kSize);
  wall(&scene, 15.0, true);
  const EsdfMap& map = scene.finish();
  Mission mission(config());
  mission.give({kGoal});
  std::string text;
  ASSERT_EQ(route(&mission, map, kStart, &text), Mission::RouteOutcome::kFound) << text;
  EXPECT_NE(text.find("global route"), std::string::npos) << text;
  ASSERT_GE(mission.route().size(), 3u);  // round the wall, through the door
  const Mission::Started s = mission.start(0.0, FlatState::atRest(kStart), map, ReferenceConfig());
  ASSERT_TRUE(s.ok) << s.summary;
  EXPECT_NE(s.summary.find("along the global route"), std::string::npos) << s.summary;
  // The reference goes through the door, not through the wall.
  const PolynomialTrajectory& ref = mission.reference();
  double y_at_wall = NAN;
  for (double t = 0.0; t <= ref.duration(); t += 0.01)
    if (std::abs(ref.position(t).x() - 15.05) < 0.05) y_at_wall = ref.position(t).y();
  EXPECT_NEAR(y_at_wall, 2.0, 0.9);
  // Fresh for the goals left: no new search until it is marked stale.
  EXPECT_FALSE(mission.prepareRouteSearch(map));
  mission.markRouteStale();
  EXPECT_TRUE(mission.prepareRouteSearch(map));
}

TEST(Mission, AGoalWalledOffIsRefusedWhenNewAndEndsTheMissionWhenItsOwn) {
  SyntheticScene open(kSize);
  const EsdfMap& open_map = open.finish();
  SyntheticScene closed(kSize);
  wall(&closed, 15.0, false);
  const EsdfMap& closed_map = closed.finish();
  Mission mission(config());
  mission.give({kGoal});
  std::string text;
  ASSERT_EQ(route(&mission, open_map, kStart, &text), Mission::RouteOutcome::kFound) << text;
  ASSERT_TRUE(mission.start(0.0, FlatState::atRest(kStart), open_map, ReferenceConfig()).ok);
  // New goals behind the wall: refused; the mission flown goes on.
  mission.give({Eigen::Vector3d(27.0, 3.0, 1.5)});
  EXPECT_EQ(route(&mission, closed_map, kStart, &text), Mission::RouteOutcome::kRefused);
  EXPECT_NE(text.find("goal refused: kUnreachable"), std::string::npos) << text;
  EXPECT_EQ(mission.status(), GoalStatus::kUnreachable);
  EXPECT_FALSE(mission.pending());
  EXPECT_EQ(mission.remaining(), std::vector<Eigen::Vector3d>{kGoal});
  // Its own goal, re-routed after the wall was seen: the mission ends.
  mission.pendRemaining(true);
  EXPECT_TRUE(mission.rerouting());
  EXPECT_EQ(route(&mission, closed_map, kStart, &text), Mission::RouteOutcome::kUnreachable);
  EXPECT_NE(text.find("unreachable in the known map"), std::string::npos) << text;
  mission.end(GoalStatus::kUnreachable, closed_map);
  EXPECT_TRUE(mission.empty());
  EXPECT_FALSE(mission.pending());
  EXPECT_TRUE(mission.route().empty());
  EXPECT_EQ(mission.status(), GoalStatus::kUnreachable);
}

TEST(Mission, ASearchOvertakenByAStopIsDropped) {
  SyntheticScene scene(kSize);
  const EsdfMap& map = scene.finish();
  Mission mission(config());
  mission.give({kGoal});
  std::optional<Mission::RouteSearch> search = mission.prepareRouteSearch(map);
  ASSERT_TRUE(search);
  search->start = kStart;
  Mission::RouteFound found = mission.searchRoute(map, *search);
  ASSERT_EQ(found.status, SearchStatus::kSuccess);
  mission.invalidateRoute();  // a stop while it searched
  std::string text;
  EXPECT_EQ(mission.applyRoute(*search, std::move(found), map, &text), Mission::RouteOutcome::kOvertaken);
  EXPECT_TRUE(mission.route().empty());
  EXPECT_TRUE(mission.prepareRouteSearch(map));  // asked again
}

TEST(Mission, AWallNewlySeenAcrossTheRouteAheadReRoutesTheMission) {
  SyntheticScene searched(kSize);
  const EsdfMap& searched_map = searched.finish();
  SyntheticScene now(kSize);
  wall(&now, 15.0, true);
  const EsdfMap& map = now.finish();
  Mission mission(config());
  mission.give({kGoal});
  std::string text;
  ASSERT_EQ(route(&mission, searched_map, kStart, &text), Mission::RouteOutcome::kFound) << text;
  ASSERT_TRUE(mission.start(0.0, FlatState::atRest(kStart), searched_map, ReferenceConfig()).ok);
  EXPECT_FALSE(mission.routeBlocked(1.0, Eigen::Vector3d(4.0, 6.0, 1.5), searched_map, &text));
  // Checked at most every route_check_interval_s.
  EXPECT_FALSE(mission.routeBlocked(1.2, Eigen::Vector3d(5.0, 6.0, 1.5), map, &text));
  ASSERT_TRUE(mission.routeBlocked(1.6, Eigen::Vector3d(5.0, 6.0, 1.5), map, &text));
  EXPECT_NE(text.find("the route is blocked"), std::string::npos) << text;
  EXPECT_TRUE(mission.pending());
  EXPECT_TRUE(mission.rerouting());
  EXPECT_EQ(mission.takeRerouteReason(), text);
  EXPECT_EQ(mission.takeRerouteReason(), "");  // said once
  // The re-route goes through the door; the re-routed reference says so.
  ASSERT_EQ(route(&mission, map, Eigen::Vector3d(5.0, 6.0, 1.5), &text), Mission::RouteOutcome::kFound) << text;
  const Mission::Started s = mission.start(2.0, FlatState::atRest(Eigen::Vector3d(5.0, 6.0, 1.5)), map, ReferenceConfig());
  ASSERT_TRUE(s.ok) << s.summary;
  EXPECT_EQ(s.summary.rfind("re-routed reference", 0), 0u) << s.summary;
}

TEST(Mission, StallsReRouteThenBackOffThenGiveUpEachMarkingAZoneAhead) {
  SyntheticScene scene(kSize);
  const EsdfMap& map = scene.finish();
  Mission::Config c = config();
  c.mission_timeout_s = 45.0;
  Mission mission(c);
  mission.give({kGoal});
  std::string text;
  ASSERT_EQ(route(&mission, map, kStart, &text), Mission::RouteOutcome::kFound) << text;
  ASSERT_TRUE(mission.start(0.0, FlatState::atRest(kStart), map, ReferenceConfig()).ok);
  // Hovering at the start: no stall before progress_timeout_s, nor while a manoeuvre is under way.
  EXPECT_EQ(mission.checkProgress(5.0, kStart, false, false).kind, Mission::Stall::Kind::kNone);
  EXPECT_EQ(mission.checkProgress(11.0, kStart, false, true).kind, Mission::Stall::Kind::kNone);
  Mission::Stall stall = mission.checkProgress(11.0, kStart, false, false);
  ASSERT_EQ(stall.kind, Mission::Stall::Kind::kRemedy);
  EXPECT_FALSE(stall.backs_off);  // the first: a re-route
  EXPECT_NE(stall.why.find("no progress towards the goal for 11 s"), std::string::npos) << stall.why;
  ASSERT_EQ(mission.stallZones().size(), 1u);
  EXPECT_GT(mission.stallZones()[0].center.x(), kStart.x() + 1.0);  // ahead along the way
  EXPECT_TRUE(mission.prepareRouteSearch(map));                      // the route is stale
  // The second stall (after twice the timeout): a back-off; the vehicle stops first, then backs off
  // once at rest.
  EXPECT_EQ(mission.checkProgress(15.0, kStart, false, false).kind, Mission::Stall::Kind::kNone);
  stall = mission.checkProgress(21.0, kStart, false, false);
  ASSERT_EQ(stall.kind, Mission::Stall::Kind::kRemedy);
  EXPECT_TRUE(stall.backs_off);
  EXPECT_EQ(mission.stallZones().size(), 2u);
  mission.remedies().stopThenBackOff();
  EXPECT_EQ(mission.checkProgress(22.0, kStart, false, false).kind, Mission::Stall::Kind::kNone);  // still moving
  EXPECT_EQ(mission.checkProgress(23.0, kStart, true, false).kind, Mission::Stall::Kind::kBackOffNow);
  // Stale inputs for 30 s pause the clock: no give-up for them.
  mission.pauseProgress(53.0);
  EXPECT_NE(mission.checkProgress(53.5, kStart, false, false).kind, Mission::Stall::Kind::kGiveUp);
  // No progress for the mission's time limit: given up.
  stall = mission.checkProgress(76.0, kStart, false, false);
  ASSERT_EQ(stall.kind, Mission::Stall::Kind::kGiveUp);
  EXPECT_NE(stall.why.find("time limit of 45 s"), std::string::npos) << stall.why;
  // Progress (flying on along the way) starts the remedies over.
  Mission going(c);
  going.give({kGoal});
  ASSERT_TRUE(going.start(0.0, FlatState::atRest(kStart), map, ReferenceConfig()).ok);
  for (double t = 1.0; t <= 20.0; t += 1.0)
    EXPECT_EQ(going.checkProgress(t, kStart + Eigen::Vector3d(t, 0.0, 0.0), false, false).kind,
              Mission::Stall::Kind::kNone);
}

TEST(Mission, TheZonesStalledAtAreCappedAndForgottenAfterAJump) {
  SyntheticScene scene(kSize);
  const EsdfMap& map = scene.finish();
  Mission mission(config());
  mission.give({kGoal});
  ASSERT_TRUE(mission.start(0.0, FlatState::atRest(kStart), map, ReferenceConfig()).ok);
  for (size_t i = 0; i < Mission::kMaxStallZones + 8; ++i) mission.stalledAtHold();
  EXPECT_EQ(mission.stallZones().size(), Mission::kMaxStallZones);
  // They stay for later missions ...
  mission.give({kStart});
  ASSERT_TRUE(mission.start(1.0, FlatState::atRest(kGoal), map, ReferenceConfig()).ok);
  EXPECT_EQ(mission.stallZones().size(), Mission::kMaxStallZones);
  // ... but not across an odometry jump (an old frame).
  mission.forgetStallZones();
  EXPECT_TRUE(mission.stallZones().empty());
}

}  // namespace
}  // namespace topo_planner
