// The mission's remedies on their own (mission_remedies.h): each row of its table, in order.
#include "topo_planner/topo_replan/mission_remedies.h"

#include <gtest/gtest.h>

namespace topo_planner {
namespace {

MissionRemedies::Config config() {
  MissionRemedies::Config c;  // 30 failures, re-route every 3, 3 back-offs, 5 holds for 2.5 s, 10 s stalls
  return c;
}

void fail(MissionRemedies* r, int n) {
  for (int i = 0; i < n; ++i) r->planFailed();
}

TEST(MissionRemedies, TheTimeLimitOfAMission) {
  MissionRemedies r(config());
  r.newMission(5.0, 10.0);
  EXPECT_EQ(r.missionLimit(), 60.0);
  r.newMission(5.0, 20.0);
  EXPECT_EQ(r.missionLimit(), 80.0);
  MissionRemedies::Config fixed = config();
  fixed.mission_timeout_s = 30.0;
  r.setConfig(fixed);
  r.newMission(5.0, 20.0);
  EXPECT_EQ(r.missionLimit(), 30.0);
  EXPECT_FALSE(r.noPlanForTheLimit(35.0));
  EXPECT_TRUE(r.noPlanForTheLimit(35.1));
  r.planSucceeded(20.0, true);  // a hold is no progress
  EXPECT_TRUE(r.noPlanForTheLimit(35.1));
  r.planSucceeded(20.0, false);
  EXPECT_FALSE(r.noPlanForTheLimit(35.1));
  r.shift(100.0);  // a time jump
  EXPECT_FALSE(r.noPlanForTheLimit(135.1));
  EXPECT_TRUE(r.noPlanForTheLimit(150.1));
}

TEST(MissionRemedies, ABlockedWayReroutesAtOnceThenEveryFewFailures) {
  MissionRemedies r(config());
  r.newMission(0.0, 10.0);
  r.planFailed();
  EXPECT_TRUE(r.rerouteAfterFailure(ReplanStatus::kNoPath));    // at once
  r.routeSearched();
  r.planFailed();
  EXPECT_FALSE(r.rerouteAfterFailure(ReplanStatus::kNoPath));   // once until a plan succeeds
  r.planFailed();
  EXPECT_FALSE(r.rerouteAfterFailure(ReplanStatus::kOptimizationFailed));
  r.planFailed();
  EXPECT_TRUE(r.rerouteAfterFailure(ReplanStatus::kOptimizationFailed));  // 3 since the last route
  r.planSucceeded(1.0, false);
  r.planFailed();
  EXPECT_TRUE(r.rerouteAfterFailure(ReplanStatus::kGoalInCollision));
  // New goals allow an immediate re-route again.
  r.planFailed();
  EXPECT_FALSE(r.rerouteAfterFailure(ReplanStatus::kNoPath));
  r.goalsGiven();
  EXPECT_TRUE(r.rerouteAfterFailure(ReplanStatus::kNoPath));
  // Without the global route, none.
  MissionRemedies::Config off = config();
  off.global_route = false;
  MissionRemedies straight(off);
  straight.planFailed();
  EXPECT_FALSE(straight.rerouteAfterFailure(ReplanStatus::kNoPath));
}

TEST(MissionRemedies, FailuresAtRestEscapeThenBackOffThenStall) {
  MissionRemedies r(config());
  r.newMission(0.0, 10.0);
  // Cannot start, at rest: escape, else back off.
  r.planFailed();
  MissionRemedies::AfterFailure a = r.afterFailure(1.0, ReplanStatus::kStartInCollision, true, true);
  EXPECT_FALSE(a.give_up);
  EXPECT_TRUE(a.escape);
  EXPECT_TRUE(a.backoff);
  // Moving (or a replan): no manoeuvre from a moving vehicle, no back-off but for first plans.
  a = r.afterFailure(1.0, ReplanStatus::kStartInCollision, true, false);
  EXPECT_FALSE(a.escape || a.backoff);
  a = r.afterFailure(1.0, ReplanStatus::kStartInCollision, false, true);
  EXPECT_TRUE(a.escape);
  EXPECT_FALSE(a.backoff);
  // Other failures at rest: a back-off after max_plan_failures of them, and the stall remedy then
  // while none is possible.
  fail(&r, 28);
  EXPECT_FALSE(r.afterFailure(1.0, ReplanStatus::kNoPath, true, true).backoff);
  EXPECT_FALSE(r.forceStallAfterFailure());
  r.planFailed();  // 30
  EXPECT_TRUE(r.afterFailure(1.0, ReplanStatus::kNoPath, true, true).backoff);
  EXPECT_TRUE(r.forceStallAfterFailure());
  r.planFailed();
  EXPECT_FALSE(r.forceStallAfterFailure());  // counted: the next after another 30
  fail(&r, 29);
  EXPECT_TRUE(r.forceStallAfterFailure());
  // No back-off left.
  for (int i = 0; i < 3; ++i) r.backedOff();
  EXPECT_FALSE(r.afterFailure(1.0, ReplanStatus::kStartInCollision, true, true).backoff);
  // A new start counts the failures anew.
  r.newStart();
  EXPECT_EQ(r.failures(), 0);
}

TEST(MissionRemedies, FirstPlansGiveUpAtTheTimeLimitOrWithoutARouteAfterTheirTries) {
  MissionRemedies r(config());
  r.newMission(0.0, 10.0);  // 60 s
  r.planFailed();
  EXPECT_FALSE(r.afterFailure(59.0, ReplanStatus::kNoPath, true, true).give_up);
  EXPECT_FALSE(r.afterFailure(61.0, ReplanStatus::kNoPath, false, true).give_up);  // a replan keeps its trajectory
  const MissionRemedies::AfterFailure a = r.afterFailure(61.0, ReplanStatus::kStartInCollision, true, true);
  ASSERT_TRUE(a.give_up);
  EXPECT_NE(a.give_up->find("time limit of 60 s"), std::string::npos) << *a.give_up;
  EXPECT_FALSE(a.escape || a.backoff);
  MissionRemedies::Config off = config();
  off.global_route = false;
  MissionRemedies straight(off);
  straight.newMission(0.0, 10.0);
  fail(&straight, 29);
  EXPECT_FALSE(straight.afterFailure(1.0, ReplanStatus::kNoPath, true, true).give_up);
  straight.planFailed();
  ASSERT_TRUE(straight.afterFailure(1.0, ReplanStatus::kNoPath, true, true).give_up);
  EXPECT_EQ(*straight.afterFailure(1.0, ReplanStatus::kNoPath, true, true).give_up, "no trajectory after 30 tries");
}

TEST(MissionRemedies, HoldsAtOnePlaceBackOffAfterTheirCountAndTime) {
  MissionRemedies r(config());
  r.newMission(0.0, 10.0);
  const Eigen::Vector3d here(1.0, 2.0, 1.0);
  for (int i = 0; i < 5; ++i) r.countLookHold(true, here + Eigen::Vector3d(0.05 * i, 0, 0), 10.0 + 0.05 * i);
  EXPECT_FALSE(r.lookHoldBackoffDue(10.5));  // 5 holds, but 0.5 s: the camera has not turned round
  EXPECT_TRUE(r.lookHoldBackoffDue(12.5));
  EXPECT_EQ(r.lookHoldPosition(), here);
  // A hold elsewhere starts over; so does a plan that is not a hold.
  r.countLookHold(true, here + Eigen::Vector3d(1.0, 0, 0), 12.6);
  EXPECT_FALSE(r.lookHoldBackoffDue(20.0));
  for (int i = 0; i < 5; ++i) r.countLookHold(true, here, 13.0);
  r.countLookHold(false, here, 13.1);
  EXPECT_FALSE(r.lookHoldBackoffDue(20.0));
  // A back-off resets the count; with none left, no more.
  for (int i = 0; i < 5; ++i) r.countLookHold(true, here, 13.0);
  ASSERT_TRUE(r.lookHoldBackoffDue(20.0));
  r.backedOff();
  EXPECT_FALSE(r.lookHoldBackoffDue(20.0));
  r.backedOff();
  r.backedOff();
  for (int i = 0; i < 5; ++i) r.countLookHold(true, here, 13.0);
  EXPECT_FALSE(r.lookHoldBackoffDue(20.0));
}

TEST(MissionRemedies, StallsRerouteThenBackOffInTurnAndGiveUpAtTheLimit) {
  MissionRemedies r(config());
  r.newMission(0.0, 10.0);  // 60 s
  r.referenceStarted(0.0);
  bool forced = false;
  using Stall = MissionRemedies::Stall;
  EXPECT_EQ(r.stall(9.0, false, false, &forced), Stall::kNone);
  EXPECT_EQ(r.stall(10.5, false, false, &forced), Stall::kRemedy);  // the first: a re-route
  EXPECT_FALSE(forced);
  EXPECT_FALSE(r.stallBacksOff());
  EXPECT_EQ(r.stall(15.0, false, false, &forced), Stall::kNone);    // the next after 20 s
  EXPECT_EQ(r.stall(20.5, true, false, &forced), Stall::kNone);     // not during a manoeuvre
  EXPECT_EQ(r.stall(20.5, false, true, &forced), Stall::kNone);     // nor with goals pending
  EXPECT_EQ(r.stall(20.5, false, false, &forced), Stall::kRemedy);  // the second: a back-off
  EXPECT_TRUE(r.stallBacksOff());
  // Moving: stop first; the back-off comes once stopped, and no stall is counted meanwhile.
  r.stopThenBackOff();
  EXPECT_EQ(r.stall(35.0, false, false, &forced), Stall::kNone);
  EXPECT_FALSE(r.backoffNowStopped(false));
  EXPECT_TRUE(r.backoffNowStopped(true));
  EXPECT_FALSE(r.backoffNowStopped(true));  // once
  // Progress starts the remedies over.
  r.progressMeasured(30.0);
  EXPECT_EQ(r.stall(9.0, false, false, &forced), Stall::kNone);
  EXPECT_EQ(r.stall(10.5, false, false, &forced), Stall::kRemedy);
  EXPECT_FALSE(r.stallBacksOff());
  // Failures at rest force one at once.
  fail(&r, 30);
  ASSERT_TRUE(r.forceStallAfterFailure());
  EXPECT_EQ(r.stall(11.0, false, false, &forced), Stall::kRemedy);
  EXPECT_TRUE(forced);
  // No progress for the mission's limit: give up.
  EXPECT_EQ(r.stall(61.0, false, false, &forced), Stall::kGiveUp);
}

}  // namespace
}  // namespace topo_planner
