// Tests of the flight monitor's ROS-free core: when goals count as reached or timed out, the
// statistics of a flight against closed-form or brute-force oracles (path length, time-averaged
// speed, replanning percentiles, collision counts), the trace downsampling, the map columns and
// the files. Every flight here is synthetic and driven by sample counts, never by the clock.

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <map>
#include <random>
#include <sstream>
#include <string>
#include <vector>

#include "topo_planner/plan_env/synthetic_scene.h"
#include "topo_planner/plan_env/timing.h"
#include "topo_planner/plan_manage/flight_monitor_core.h"

namespace topo_planner {
namespace {

constexpr double kDt = 0.005;  // 200 Hz odometry

OdometrySample sample(double t, const Eigen::Vector3d& p, const Eigen::Vector3d& v, double clearance = 1.0) {
  OdometrySample s;
  s.t_s = t;
  s.position_m = p;
  s.velocity_mps = v;
  s.clearance_m = clearance;
  return s;
}

std::vector<std::string> readLines(const std::string& path) {
  std::ifstream in(path);
  std::vector<std::string> lines;
  for (std::string l; std::getline(in, l);) lines.push_back(l);
  return lines;
}

TEST(FlightRecorder, GoalReachedOnlyWhenCloseAndSlow) {
  FlightRecorder::Config c;  // 0.5 m, 1 m/s
  FlightRecorder rec(c, {Eigen::Vector3d(10, 0, 1), Eigen::Vector3d(10, 10, 1)});
  FlightRecorder::Update u = rec.start(100.0);
  EXPECT_EQ(u.next_goal, 0);
  EXPECT_EQ(rec.activeGoal(), 0);

  // Far and slow: nothing.
  u = rec.addOdometry(sample(100.1, Eigen::Vector3d(5, 0, 1), Eigen::Vector3d(0.1, 0, 0)));
  EXPECT_EQ(u.goal_reached, -1);
  // Inside the tolerance but at 2 m/s (a pass): not an arrival.
  u = rec.addOdometry(sample(100.2, Eigen::Vector3d(9.8, 0, 1), Eigen::Vector3d(2, 0, 0)));
  EXPECT_EQ(u.goal_reached, -1);
  // Just outside the tolerance and stopped: not yet.
  u = rec.addOdometry(sample(100.3, Eigen::Vector3d(10, 0.51, 1), Eigen::Vector3d(0, 0, 0)));
  EXPECT_EQ(u.goal_reached, -1);
  // Close and slow: reached; the next goal becomes active at once.
  u = rec.addOdometry(sample(100.4, Eigen::Vector3d(10, 0.3, 1.2), Eigen::Vector3d(0.5, 0.5, 0)));
  EXPECT_EQ(u.goal_reached, 0);
  EXPECT_EQ(u.next_goal, 1);
  EXPECT_FALSE(u.finished);
  EXPECT_TRUE(rec.goals()[0].reached);
  EXPECT_DOUBLE_EQ(rec.goals()[0].reached_t_s, 100.4);
  EXPECT_DOUBLE_EQ(rec.goals()[1].sent_t_s, 100.4);

  u = rec.addOdometry(sample(120.0, Eigen::Vector3d(10, 10, 1), Eigen::Vector3d::Zero()));
  EXPECT_EQ(u.goal_reached, 1);
  EXPECT_EQ(u.next_goal, -1);
  EXPECT_TRUE(u.finished);
  EXPECT_EQ(rec.status(), FlightStatus::kSuccess);
  const FlightSummary s = rec.summary();
  EXPECT_TRUE(s.success);
  EXPECT_EQ(s.goals_reached, 2);
  EXPECT_EQ(s.goals_total, 2);
  EXPECT_NEAR(s.duration_s, 20.0, 1e-9);  // first goal sent to last goal reached

  // After the end nothing changes.
  u = rec.addOdometry(sample(121.0, Eigen::Vector3d(0, 0, 1), Eigen::Vector3d(3, 0, 0)));
  EXPECT_FALSE(u.finished);
  EXPECT_NEAR(rec.summary().duration_s, 20.0, 1e-9);
  EXPECT_NEAR(rec.summary().max_speed_mps, 2.0, 1e-12);
}

// Waypoints of one mission: the intermediate one counts when passed within 1 m at speed, the last
// only close and slow.
TEST(FlightRecorder, PassThroughWaypoints) {
  FlightRecorder::Config c;
  c.pass_through = true;
  FlightRecorder rec(c, {Eigen::Vector3d(3, 0, 1), Eigen::Vector3d(3, 10, 1)});
  rec.start(0.0);
  EXPECT_EQ(rec.addOdometry(sample(1.0, Eigen::Vector3d(1.9, 0, 1), Eigen::Vector3d(3, 0, 0))).goal_reached, -1);
  FlightRecorder::Update u = rec.addOdometry(sample(1.1, Eigen::Vector3d(2.2, 0.5, 1), Eigen::Vector3d(2, 2, 0)));
  EXPECT_EQ(u.goal_reached, 0);  // 0.94 m away at 2.8 m/s
  EXPECT_EQ(u.next_goal, 1);
  EXPECT_EQ(rec.addOdometry(sample(4.0, Eigen::Vector3d(3, 9.5, 1), Eigen::Vector3d(0, 2, 0))).goal_reached, -1);
  u = rec.addOdometry(sample(5.0, Eigen::Vector3d(3, 9.8, 1), Eigen::Vector3d(0, 0.2, 0)));
  EXPECT_EQ(u.goal_reached, 1);
  EXPECT_TRUE(u.finished);
}

TEST(FlightRecorder, ZeroSpeedLimitMeansAnySpeed) {
  FlightRecorder::Config c;
  c.goal_max_speed_mps = 0.0;
  FlightRecorder rec(c, {Eigen::Vector3d(1, 0, 0)});
  rec.start(0.0);
  const FlightRecorder::Update u = rec.addOdometry(sample(1.0, Eigen::Vector3d(1.2, 0, 0), Eigen::Vector3d(5, 0, 0)));
  EXPECT_EQ(u.goal_reached, 0);
  EXPECT_TRUE(u.finished);
}

TEST(FlightRecorder, TimeoutEndsTheFlight) {
  FlightRecorder::Config c;
  c.goal_timeout_s = 90.0;
  FlightRecorder rec(c, {Eigen::Vector3d(10, 0, 1), Eigen::Vector3d(-10, 0, 1), Eigen::Vector3d(0, 5, 1)});
  rec.start(0.0);
  // Goal 1 reached at t = 30, then goal 2 never: odometry keeps coming far away from it.
  EXPECT_EQ(rec.addOdometry(sample(30.0, Eigen::Vector3d(10, 0, 1), Eigen::Vector3d::Zero())).goal_reached, 0);
  FlightRecorder::Update u;
  int n = 0;
  for (double t = 30.0 + kDt; !u.finished && n < 100000; t += kDt, ++n)
    u = rec.addOdometry(sample(t, Eigen::Vector3d(5, 0, 1), Eigen::Vector3d::Zero()));
  EXPECT_TRUE(u.finished);
  EXPECT_EQ(u.goal_timed_out, 1);
  // The first sample past 30 + 90 s ends it.
  EXPECT_NEAR(rec.lastTime(), 120.0, 2 * kDt);
  EXPECT_EQ(rec.status(), FlightStatus::kGoalTimeout);
  const FlightSummary s = rec.summary();
  EXPECT_FALSE(s.success);
  EXPECT_EQ(s.goals_reached, 1);
  EXPECT_TRUE(rec.goals()[1].timed_out);
  EXPECT_FALSE(rec.goals()[2].sent);
  EXPECT_NEAR(rec.goals()[1].distance_m, 15.0, 1e-9);
  EXPECT_NE(s.message.find("goal 2/3 not reached"), std::string::npos) << s.message;
}

TEST(FlightRecorder, TimeoutWithoutOdometry) {
  FlightRecorder rec(FlightRecorder::Config(), {Eigen::Vector3d(10, 0, 1)});
  rec.start(5.0);
  EXPECT_FALSE(rec.checkTimeout(95.0).finished);  // exactly the limit: still allowed
  const FlightRecorder::Update u = rec.checkTimeout(95.1);
  EXPECT_TRUE(u.finished);
  EXPECT_EQ(u.goal_timed_out, 0);
  EXPECT_NEAR(rec.summary().duration_s, 90.1, 1e-9);
}

// Constant acceleration a from rest along x for T seconds: the path is a T^2 / 2 and the time
// average of the speed a T / 2; trapezoidal integration of a linear speed is exact.
TEST(FlightRecorder, PathLengthAndSpeedsMatchClosedForm) {
  const double a = 0.5, T = 10.0;
  FlightRecorder rec(FlightRecorder::Config(), {Eigen::Vector3d(100, 0, 1)});
  rec.start(0.0);
  const int steps = int(std::lround(T / kDt));
  for (int i = 0; i <= steps; ++i) {
    const double t = i * kDt;
    rec.addOdometry(sample(t, Eigen::Vector3d(0.5 * a * t * t, 0, 1), Eigen::Vector3d(a * t, 0, 0)));
  }
  const FlightSummary s = rec.summary();
  EXPECT_NEAR(s.path_length_m, 0.5 * a * T * T, 1e-9);
  EXPECT_NEAR(s.mean_speed_mps, 0.5 * a * T, 1e-9);
  EXPECT_NEAR(s.max_speed_mps, a * T, 1e-12);
  EXPECT_NEAR(s.duration_s, T, 1e-9);
  EXPECT_NEAR(rec.goals()[0].path_length_m, 0.5 * a * T * T, 1e-9);
  EXPECT_EQ(rec.status(), FlightStatus::kInProgress);
  EXPECT_EQ(s.message, "in progress");
}

// Under odometry noise the path and speeds come from the ground truth: a noisy estimate that zigzags
// 5 cm at 200 Hz around a straight 1 m/s flight doubled-and-more its length (757 m reported for about
// 127 m flown in a realistic-sensing flight).
TEST(FlightRecorder, PathAndSpeedsAreMeasuredOnTheGroundTruth) {
  FlightRecorder::Config c;
  c.speed.max_vel_mps = 2.0;
  FlightRecorder rec(c, {Eigen::Vector3d(100, 0, 1)});
  rec.start(0.0);
  std::mt19937 rng(3);
  std::normal_distribution<double> noise(0.0, 0.05);
  for (int i = 0; i <= 2000; ++i) {  // 10 s at 1 m/s
    const double t = i * kDt;
    const Eigen::Vector3d p(t, 0, 1), v(1, 0, 0);
    rec.addOdometry(sample(t, p + Eigen::Vector3d(noise(rng), noise(rng), 0), v + Eigen::Vector3d(noise(rng), 0, 0)));
    rec.addTruth(sample(t, p, v));
  }
  const FlightSummary s = rec.summary();
  EXPECT_TRUE(s.measured_on_truth);
  EXPECT_NEAR(s.path_length_m, 10.0, 1e-9);
  EXPECT_NEAR(rec.goals()[0].path_length_m, 10.0, 1e-9);
  EXPECT_NEAR(s.mean_speed_mps, 1.0, 1e-9);
  EXPECT_NEAR(s.max_speed_mps, 1.0, 1e-9);
  // The speed account counted the true speed: slow all along (1 m/s < 0.8 x 2 m/s), held (no setpoint).
  EXPECT_NEAR(s.speed.total_s, 10.0, 1e-9);
  EXPECT_NEAR(s.speed.slow_s[size_t(SlowCause::kHeld)], 10.0, 1e-9);
  EXPECT_EQ(s.fast_share, 0.0);
  // The odometry alone (no ground truth) would have measured the noise too.
  FlightRecorder odom_only(c, {Eigen::Vector3d(100, 0, 1)});
  odom_only.start(0.0);
  rng.seed(3);
  for (int i = 0; i <= 2000; ++i) {
    const double t = i * kDt;
    odom_only.addOdometry(sample(t, Eigen::Vector3d(t + noise(rng), noise(rng), 1), Eigen::Vector3d(1 + noise(rng), 0, 0)));
    noise(rng);
  }
  EXPECT_FALSE(odom_only.summary().measured_on_truth);
  EXPECT_GT(odom_only.summary().path_length_m, 50.0);
}

// The oracle's time per goal, and the flight's time over it for the goals reached.
TEST(FlightRecorder, TimeRatioOverTheOracle) {
  FlightRecorder rec(FlightRecorder::Config(), {Eigen::Vector3d(10, 0, 1), Eigen::Vector3d(0, 0, 1)});
  FlightOracle::Result oracle;
  oracle.ok = true;
  oracle.time_s = {4.0, 5.0};
  rec.setOracle(oracle);
  rec.start(0.0);
  EXPECT_TRUE(std::isnan(rec.summary().time_ratio));  // no goal reached yet
  rec.addOdometry(sample(6.0, Eigen::Vector3d(10, 0, 1), Eigen::Vector3d::Zero()));  // goal 1 in 6 s
  FlightSummary s = rec.summary();
  EXPECT_NEAR(s.oracle_time_s, 4.0, 1e-12);
  EXPECT_NEAR(s.reached_time_s, 6.0, 1e-12);
  EXPECT_NEAR(s.time_ratio, 1.5, 1e-12);
  rec.addOdometry(sample(16.0, Eigen::Vector3d(0, 0, 1), Eigen::Vector3d::Zero()));  // goal 2 in 10 s
  s = rec.summary();
  EXPECT_NEAR(s.time_ratio, 16.0 / 9.0, 1e-12);
  EXPECT_NE(formatReport(s, "x").find("1.78x"), std::string::npos) << formatReport(s, "x");
  // An oracle that does not match the goals is not taken.
  FlightRecorder other(FlightRecorder::Config(), {Eigen::Vector3d(10, 0, 1)});
  other.setOracle(oracle);
  other.start(0.0);
  other.addOdometry(sample(6.0, Eigen::Vector3d(10, 0, 1), Eigen::Vector3d::Zero()));
  EXPECT_TRUE(std::isnan(other.summary().time_ratio));
}

// A gap in the odometry (longer than max_sample_gap_s) is neither integrated nor a path jump.
TEST(FlightRecorder, GapsAndBadSamplesAreNotIntegrated) {
  FlightRecorder rec(FlightRecorder::Config(), {Eigen::Vector3d(100, 0, 1)});
  rec.start(0.0);
  rec.addOdometry(sample(0.0, Eigen::Vector3d(0, 0, 1), Eigen::Vector3d(1, 0, 0)));
  rec.addOdometry(sample(1.0, Eigen::Vector3d(1, 0, 1), Eigen::Vector3d(1, 0, 0)));
  rec.addOdometry(sample(5.0, Eigen::Vector3d(20, 0, 1), Eigen::Vector3d(1, 0, 0)));  // 4 s gap
  rec.addOdometry(sample(6.0, Eigen::Vector3d(21, 0, 1), Eigen::Vector3d(1, 0, 0)));
  rec.addOdometry(sample(7.0, Eigen::Vector3d(NAN, 0, 1), Eigen::Vector3d(1, 0, 0)));     // ignored
  rec.addOdometry(sample(8.0, Eigen::Vector3d(22, 0, 1), Eigen::Vector3d(INFINITY, 0, 0)));  // ignored
  rec.addOdometry(sample(5.5, Eigen::Vector3d(30, 0, 1), Eigen::Vector3d(9, 0, 0)));     // out of order
  const FlightSummary s = rec.summary();
  EXPECT_NEAR(s.path_length_m, 2.0, 1e-12);
  EXPECT_NEAR(s.mean_speed_mps, 1.0, 1e-12);
  EXPECT_NEAR(s.max_speed_mps, 1.0, 1e-12);
}

// Percentiles against a sorted copy (nearest rank), counts per goal, stall re-routes apart from the
// planning calls, and events outside the flight.
TEST(FlightRecorder, ReplanStatisticsMatchBruteForce) {
  FlightRecorder rec(FlightRecorder::Config(), {Eigen::Vector3d(10, 0, 1), Eigen::Vector3d(20, 0, 1)});
  ReplanRecord before;
  before.total_ms = 1e6;
  rec.addReplan(before);  // before the start: ignored
  rec.start(0.0);

  std::mt19937 rng(7);
  std::uniform_real_distribution<double> ms(0.5, 40.0);
  std::vector<double> all;
  int published[2] = {0, 0}, failed[2] = {0, 0}, stalls[2] = {0, 0};
  for (int i = 0; i < 137; ++i) {
    if (i == 60) rec.addOdometry(sample(10.0, Eigen::Vector3d(10, 0, 1), Eigen::Vector3d::Zero()));  // goal 1
    const int goal = i < 60 ? 0 : 1;
    ReplanRecord r;
    r.t_s = 0.1 * i;
    r.total_ms = ms(rng);
    r.published = i % 7 != 3;
    r.trajectory_id = r.published ? i : -1;
    if (i % 11 == 5) {  // a stall re-route: no planning call, its time not a planning time
      r.stall = true;
      r.published = false;
      r.trajectory_id = -1;
      r.total_ms = 0.0;
      ++stalls[goal];
    } else {
      (r.published ? published : failed)[goal] += 1;
      all.push_back(r.total_ms);
    }
    rec.addReplan(r);
  }
  ASSERT_EQ(rec.replans().size(), all.size() + size_t(stalls[0] + stalls[1]));
  EXPECT_EQ(rec.replans()[0].goal_index, 0);
  EXPECT_EQ(rec.replans().back().goal_index, 1);
  std::vector<double> sorted = all;
  std::sort(sorted.begin(), sorted.end());
  auto rank = [&](double q) { return sorted[size_t(std::lround(q * double(sorted.size() - 1)))]; };
  const FlightSummary s = rec.summary();
  EXPECT_DOUBLE_EQ(s.replan_ms_median, rank(0.5));
  EXPECT_DOUBLE_EQ(s.replan_ms_p95, rank(0.95));
  EXPECT_DOUBLE_EQ(s.replan_ms_max, sorted.back());
  EXPECT_EQ(s.replans, published[0] + published[1]);
  EXPECT_EQ(s.replan_failures, failed[0] + failed[1]);
  EXPECT_EQ(rec.goals()[0].replans, published[0]);
  EXPECT_EQ(rec.goals()[0].replan_failures, failed[0]);
  EXPECT_EQ(rec.goals()[1].replans, published[1]);
  EXPECT_EQ(rec.goals()[1].replan_failures, failed[1]);
  EXPECT_GT(stalls[0], 0);
  EXPECT_GT(stalls[1], 0);
  EXPECT_EQ(s.stalls, stalls[0] + stalls[1]);
  EXPECT_EQ(rec.goals()[0].stalls, stalls[0]);
  EXPECT_EQ(rec.goals()[1].stalls, stalls[1]);

  const size_t recorded = rec.replans().size();
  rec.addOdometry(sample(20.0, Eigen::Vector3d(20, 0, 1), Eigen::Vector3d::Zero()));  // the end
  ASSERT_TRUE(rec.finished());
  rec.addReplan(before);  // after the end: ignored
  EXPECT_EQ(rec.replans().size(), recorded);
}

TEST(FlightRecorder, NoReplansGiveZeroTimes) {
  FlightRecorder rec(FlightRecorder::Config(), {Eigen::Vector3d(10, 0, 1)});
  rec.start(0.0);
  const FlightSummary s = rec.summary();
  EXPECT_EQ(s.replan_ms_median, 0.0);
  EXPECT_EQ(s.replan_ms_p95, 0.0);
  EXPECT_TRUE(std::isnan(s.min_clearance_m));
}

// The simulator's counter: values before the start are the baseline; the largest value since,
// minus it, is the flight's count, attributed to the goal active when it grew.
TEST(FlightRecorder, SimulatorCollisionsCountFromTheBaseline) {
  FlightRecorder rec(FlightRecorder::Config(), {Eigen::Vector3d(10, 0, 1), Eigen::Vector3d(20, 0, 1)});
  rec.addSimCollisionCount(0.0, 1);
  rec.addSimCollisionCount(0.1, 2);  // baseline 2 (e.g. a previous flight of the same simulator)
  rec.start(1.0);
  rec.addSimCollisionCount(1.5, 2);  // the same contact, repeated
  rec.addSimCollisionCount(2.0, 3);
  rec.addSimCollisionCount(2.1, 3);
  rec.addOdometry(sample(3.0, Eigen::Vector3d(10, 0, 1), Eigen::Vector3d::Zero()));  // goal 1 reached
  rec.addSimCollisionCount(4.0, 5);
  rec.addSimCollisionCount(4.1, 4);  // out of order: the maximum stays
  FlightSummary s = rec.summary();
  EXPECT_EQ(s.sim_collisions, 3);
  EXPECT_EQ(s.collisions, 3);
  EXPECT_EQ(rec.goals()[0].sim_collisions, 1);
  EXPECT_EQ(rec.goals()[1].sim_collisions, 2);
  rec.addOdometry(sample(5.0, Eigen::Vector3d(20, 0, 1), Eigen::Vector3d::Zero()));
  EXPECT_EQ(rec.status(), FlightStatus::kCollision);
  EXPECT_FALSE(rec.summary().success);
  rec.addSimCollisionCount(6.0, 9);  // after the end: ignored
  EXPECT_EQ(rec.summary().sim_collisions, 3);

  // No message before the start: the simulator had counted none.
  FlightRecorder fresh(FlightRecorder::Config(), {Eigen::Vector3d(10, 0, 1)});
  fresh.start(0.0);
  fresh.addSimCollisionCount(1.0, 1);
  EXPECT_EQ(fresh.summary().sim_collisions, 1);
}

// The own check: a contact begins below collision_radius_m and ends above it plus the release
// margin, so a vehicle lingering at the threshold counts once.
TEST(FlightRecorder, ClearanceContactsWithHysteresis) {
  FlightRecorder::Config c;
  c.collision_radius_m = 0.2;
  c.contact_release_m = 0.05;
  FlightRecorder rec(c, {Eigen::Vector3d(100, 0, 1)});
  rec.start(0.0);
  const std::vector<double> clearances = {0.8, 0.5, 0.19, 0.12, 0.21, 0.19, 0.24, 0.3, 0.1, 0.4, NAN, 0.6};
  for (size_t i = 0; i < clearances.size(); ++i)
    rec.addOdometry(sample(0.01 * double(i), Eigen::Vector3d(double(i), 0, 1), Eigen::Vector3d::Zero(), clearances[i]));
  const FlightSummary s = rec.summary();
  EXPECT_EQ(s.clearance_contacts, 2);
  EXPECT_EQ(s.collisions, 2);
  EXPECT_EQ(rec.goals()[0].clearance_contacts, 2);
  EXPECT_DOUBLE_EQ(s.min_clearance_m, 0.1);
  EXPECT_DOUBLE_EQ(s.min_clearance_position_m.x(), 8.0);
  EXPECT_DOUBLE_EQ(rec.goals()[0].min_clearance_m, 0.1);
}

// 200 Hz in, 20 Hz rows out, each with the goal active then.
TEST(FlightRecorder, TraceIsDownsampled) {
  FlightRecorder::Config c;
  c.trace_period_s = 0.05;
  FlightRecorder rec(c, {Eigen::Vector3d(1, 0, 1), Eigen::Vector3d(50, 0, 1)});
  rec.start(3.0);
  for (int i = 0; i <= 400; ++i) {  // 2 s
    const double t = 3.0 + i * kDt;
    const double x = 0.5 * (t - 3.0);
    rec.addOdometry(sample(t, Eigen::Vector3d(x, 0, 1), Eigen::Vector3d(0.5, 0, 0)));
  }
  const std::vector<TraceRow>& rows = rec.trace();
  ASSERT_EQ(rows.size(), 41u);
  EXPECT_NEAR(rows.front().t_s, 0.0, 1e-12);
  for (size_t i = 1; i < rows.size(); ++i) EXPECT_NEAR(rows[i].t_s - rows[i - 1].t_s, 0.05, 1e-6);
  // The body comes within 0.5 m of goal 1 (x = 1) at x = 0.5, t = 1 s (row 20); later rows belong
  // to goal 2.
  EXPECT_EQ(rows[0].goal_index, 0);
  EXPECT_EQ(rows[19].goal_index, 0);
  EXPECT_EQ(rows[21].goal_index, 1);

  // Jittered stamps (+-0.4 ms) and a gap: still one row per 50 ms slot, and the grid restarts after
  // the gap.
  FlightRecorder jitter(c, {Eigen::Vector3d(100, 0, 1)});
  jitter.start(0.0);
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> noise(-4e-4, 4e-4);
  for (int i = 0; i <= 2000; ++i) {  // 10 s, with no samples in [4, 6) s
    const double t = i * kDt + (i > 0 ? noise(rng) : 0.0);
    if (t >= 4.0 && t < 6.0) continue;
    jitter.addOdometry(sample(t, Eigen::Vector3d(0, 0, 1), Eigen::Vector3d::Zero()));
  }
  const size_t n = jitter.trace().size();
  EXPECT_GE(n, 160u);  // 8 s of samples at 20 Hz
  EXPECT_LE(n, 162u);
  for (size_t i = 1; i < n; ++i) EXPECT_GE(jitter.trace()[i].t_s - jitter.trace()[i - 1].t_s, 0.045);
}

TEST(FlightRecorder, NoGoalsAndExternalEnds) {
  FlightRecorder none(FlightRecorder::Config(), {});
  EXPECT_TRUE(none.start(0.0).finished);
  EXPECT_EQ(none.status(), FlightStatus::kSuccess);

  FlightRecorder never(FlightRecorder::Config(), {Eigen::Vector3d(1, 0, 0)});
  never.finish(50.0, FlightStatus::kNoStart, "no map");
  EXPECT_EQ(never.status(), FlightStatus::kNoStart);
  EXPECT_FALSE(never.summary().success);
  EXPECT_EQ(never.summary().message, "no map");
  EXPECT_EQ(never.summary().duration_s, 0.0);
  EXPECT_FALSE(never.start(60.0).finished);  // too late to start
  EXPECT_FALSE(never.started());

  FlightRecorder cut(FlightRecorder::Config(), {Eigen::Vector3d(10, 0, 0)});
  cut.start(0.0);
  cut.addOdometry(sample(4.0, Eigen::Vector3d(1, 0, 0), Eigen::Vector3d::Zero()));
  cut.finish(4.5, FlightStatus::kInterrupted, "stopped");
  cut.finish(9.0, FlightStatus::kSuccess, "ignored");
  EXPECT_EQ(cut.status(), FlightStatus::kInterrupted);
  EXPECT_NEAR(cut.summary().duration_s, 4.5, 1e-12);
}

TEST(FlightRecorder, LinesAndReport) {
  FlightRecorder rec(FlightRecorder::Config(), {Eigen::Vector3d(15, 5, 1)});
  rec.start(10.0);
  rec.addOdometry(sample(30.0, Eigen::Vector3d(15, 5, 1), Eigen::Vector3d::Zero(), 0.42));
  const std::string line = formatGoalLine(rec.goals()[0], 1, rec.startTime(), 30.0);
  EXPECT_NE(line.find("goal 1/1 (15.0, 5.0, 1.0) reached at t=20.0 s after 20.0 s"), std::string::npos) << line;
  EXPECT_NE(line.find("min clearance 0.42 m"), std::string::npos) << line;
  const std::string report = formatReport(rec.summary(), "demo");
  EXPECT_NE(report.find("SUCCESS"), std::string::npos) << report;
  EXPECT_NE(report.find("goals reached        1/1"), std::string::npos) << report;
}

// Columns against a brute-force scan of the grid.
TEST(OccupiedColumns, HighestVoxelPerColumn) {
  SyntheticScene scene(Eigen::Vector3d(4, 4, 3), 0.1, Eigen::Vector3d(-2, -2, 0));
  scene.fill([](const Eigen::Vector3d& p) { return std::hypot(p.x() - 1.0, p.y()) <= 0.3 && p.z() < 2.0; });
  scene.box(Eigen::Vector3d(-1.5, -1.5, 0.5), Eigen::Vector3d(-0.5, -1.0, 1.2));
  scene.box(Eigen::Vector3d(-1.5, -1.5, 2.0), Eigen::Vector3d(-1.2, -1.2, 2.6));  // above part of the box
  const std::vector<Eigen::Vector3d> columns = occupiedColumns(*scene.occupancy);

  std::map<std::pair<int, int>, double> oracle;
  const GridGeometry& g = scene.occupancy->geometry();
  const VoxelBox w = g.windowBox();
  Eigen::Vector3i i;
  for (i.z() = w.min.z(); i.z() <= w.max.z(); ++i.z())
    for (i.y() = w.min.y(); i.y() <= w.max.y(); ++i.y())
      for (i.x() = w.min.x(); i.x() <= w.max.x(); ++i.x())
        if (scene.occupancy->isOccupied(i)) {
          double& top = oracle.emplace(std::make_pair(i.x(), i.y()), -1e9).first->second;
          top = std::max(top, (i.z() + 1) * 0.1);
        }
  ASSERT_EQ(columns.size(), oracle.size());
  for (const Eigen::Vector3d& c : columns) {
    const auto it = oracle.find({int(std::floor(c.x() / 0.1)), int(std::floor(c.y() / 0.1))});
    ASSERT_NE(it, oracle.end());
    EXPECT_NEAR(c.z(), it->second, 1e-9);
  }
  EXPECT_TRUE(std::is_sorted(columns.begin(), columns.end(), [](const Eigen::Vector3d& a, const Eigen::Vector3d& b) {
    return a.x() < b.x() - 1e-9 || (std::abs(a.x() - b.x()) < 1e-9 && a.y() < b.y());
  }));
}

TEST(FlightFiles, WrittenAndReadable) {
  const std::filesystem::path dir = std::filesystem::temp_directory_path() / "topo_planner_test_flight_files";
  std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir);
  const std::string stem = (dir / "f").string();

  FlightRecorder rec(FlightRecorder::Config(), {Eigen::Vector3d(2, 0, 1), Eigen::Vector3d(2, 2, 1)});
  rec.start(100.0);
  for (int i = 0; i <= 200; ++i)
    rec.addOdometry(sample(100.0 + i * kDt, Eigen::Vector3d(0.01 * i, 0, 1), Eigen::Vector3d(0.5, 0, 0), 0.7));
  ReplanRecord r;
  r.t_s = 100.5;
  r.trigger = "new_goal";
  r.status = "kNoPath, with a comma";
  r.fallback = "keep_current";
  r.message = "2 x in collision, \"quoted\"";
  r.total_ms = 3.25;
  rec.addReplan(r);
  std::string error;
  ASSERT_TRUE(writeTraceCsv(stem + ".csv", rec.trace(), &error)) << error;
  ASSERT_TRUE(writeReplanCsv(stem + "_events.csv", rec.replans(), rec.startTime(), &error)) << error;
  ASSERT_TRUE(writeMapCsv(stem + "_map.csv", {Eigen::Vector3d(1, 2, 3)}, &error)) << error;
  ReferenceRecord ref;
  ref.id = 0;
  ref.t_s = 0.25;
  ref.points_m = {Eigen::Vector3d(0, 0, 1), Eigen::Vector3d(1, 0, 1)};
  ASSERT_TRUE(writeReferenceCsv(stem + "_reference.csv", {ref}, &error)) << error;
  FlightReportInfo info;
  info.name = "f";
  info.start_m = Eigen::Vector3d(0, 0, 1);
  info.scenario["seed"] = "3";
  info.scenario["density"] = jsonString("medium");
  const FlightSummary s = rec.summary();
  ASSERT_TRUE(writeReportJson(stem + "_report.json", s, rec.goals(), rec.startTime(), info, &error)) << error;

  const auto trace = readLines(stem + ".csv");
  ASSERT_EQ(trace.size(), rec.trace().size() + 1);
  EXPECT_EQ(trace[0], "t,x,y,z,vx,vy,vz,speed,clearance_m,goal_index,cmd_speed,cmd_decel");
  EXPECT_NE(trace[1].find(",0,nan,nan"), std::string::npos) << trace[1];  // no setpoint yet
  EXPECT_EQ(trace[1].substr(0, 6), "0.000,");
  const auto events = readLines(stem + "_events.csv");
  ASSERT_EQ(events.size(), 2u);
  EXPECT_NE(events[1].find("0.500,"), std::string::npos) << events[1];
  EXPECT_NE(events[1].find(",\"kNoPath, with a comma\","), std::string::npos) << events[1];
  EXPECT_EQ(events[0].substr(events[0].rfind(',')), ",message");
  const std::string message_field = ",\"2 x in collision, \"\"quoted\"\"\"";  // quoted, quotes doubled
  ASSERT_GT(events[1].size(), message_field.size());
  EXPECT_EQ(events[1].substr(events[1].size() - message_field.size()), message_field) << events[1];
  EXPECT_EQ(readLines(stem + "_map.csv").size(), 2u);
  EXPECT_EQ(readLines(stem + "_reference.csv").size(), 3u);

  std::ifstream in(stem + "_report.json");
  const std::string json((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  EXPECT_NE(json.find("\"success\": false"), std::string::npos);
  EXPECT_NE(json.find("\"status\": \"kInProgress\""), std::string::npos);
  EXPECT_NE(json.find("\"seed\": 3"), std::string::npos);
  EXPECT_NE(json.find("\"density\": \"medium\""), std::string::npos);
  EXPECT_NE(json.find("\"reached_t_s\": null"), std::string::npos);  // goal 2 not reached
  EXPECT_NE(json.find("\"min_clearance_m\": 0.7"), std::string::npos);
  EXPECT_NE(json.find("\"collision_radius_m\": 0.15"), std::string::npos);

  EXPECT_FALSE(writeMapCsv((dir / "no" / "such" / "dir.csv").string(), {}, &error));
  EXPECT_NE(error.find("cannot write"), std::string::npos);
  std::filesystem::remove_all(dir);
}

// ---------------------------------------------------------------------------------------------
// Setpoints, time steps, goal re-sends, truth and faults

constexpr double kSetpointDt = 0.01;  // the trajectory server's 100 Hz

SetpointSample setpoint(double t, const Eigen::Vector3d& p, const Eigen::Vector3d& v,
                        const Eigen::Vector3d& a = Eigen::Vector3d::Zero()) {
  SetpointSample s;
  s.t_s = t;
  s.position_m = p;
  s.velocity_mps = v;
  s.acceleration_mps2 = a;
  return s;
}

// Braking from 3 m/s at 2.5 m/s^2 along x, sampled exactly: no jump; the worst deceleration is
// 2.5 m/s^2 from the field and from the finite differences (exact for a linear velocity).
TEST(SetpointWatch, SmoothBrakingHasNoJumpAndItsDeceleration) {
  SetpointWatch w;
  const double v0 = 3.0, a = 2.5;
  for (int i = 0; i * kSetpointDt <= v0 / a; ++i) {
    const double t = i * kSetpointDt;
    w.addSetpoint(setpoint(t, Eigen::Vector3d(v0 * t - 0.5 * a * t * t, 0, 1), Eigen::Vector3d(v0 - a * t, 0, 0),
                           Eigen::Vector3d(-a, 0, 0)));
  }
  EXPECT_EQ(w.stats().jumps, 0);
  EXPECT_EQ(w.stats().reanchorings, 0);
  EXPECT_NEAR(w.stats().max_decel_mps2, a, 1e-9);
  EXPECT_NEAR(w.stats().max_acc_mps2, a, 1e-9);
  EXPECT_EQ(w.stats().setpoints, int(std::floor(v0 / a / kSetpointDt + 1e-9)) + 1);
}

// A velocity step (cruise to a hold at the same position, the trajectory server's old snap) has a
// zero acceleration field: the finite difference over 0.05 s finds 3 / 0.05 = 60 m/s^2.
TEST(SetpointWatch, VelocityStepShowsInTheFiniteDifference) {
  SetpointWatch w;
  double x = 0.0;
  for (int i = 0; i < 100; ++i) {
    w.addSetpoint(setpoint(i * kSetpointDt, Eigen::Vector3d(x, 0, 1), Eigen::Vector3d(3, 0, 0)));
    x += 3.0 * kSetpointDt;
  }
  for (int i = 100; i < 120; ++i) w.addSetpoint(setpoint(i * kSetpointDt, Eigen::Vector3d(x, 0, 1), Eigen::Vector3d::Zero()));
  EXPECT_EQ(w.stats().jumps, 0);
  EXPECT_NEAR(w.stats().max_decel_mps2, 3.0 / 0.05, 1e-6);
  EXPECT_TRUE(w.stats().max_decel_from_difference);
  EXPECT_GE(w.stats().max_decel_t_s, 1.0 - 1e-9);  // found within 0.05 s of the step
  EXPECT_LE(w.stats().max_decel_t_s, 1.05 + 1e-9);
}

// A re-anchoring after an odometry blackout sets the command to the measured state, velocity
// included (3 m/s ahead to 0.8 m/s back: the vehicle held on its own meanwhile). Neither its position
// step nor its velocity step counts; the same velocity step without the re-anchoring is a
// deceleration of (3 + 0.8) / 0.05 m/s^2.
TEST(SetpointWatch, AReanchoringIsNeitherAJumpNorADeceleration) {
  for (const bool blackout : {true, false}) {
    SetpointWatch w;
    double x = 0.0;
    for (int i = 0; i < 100; ++i) {
      w.addSetpoint(setpoint(i * kSetpointDt, Eigen::Vector3d(x, 0, 1), Eigen::Vector3d(3, 0, 0)));
      x += 3.0 * kSetpointDt;
    }
    const Eigen::Vector3d measured(x - 0.7, 0, 1);
    if (blackout) w.addOdometryReturn(1.0 - kSetpointDt);
    w.setMeasuredPosition(measured);
    for (int i = 100; i < 120; ++i)
      w.addSetpoint(setpoint(i * kSetpointDt, measured + Eigen::Vector3d(-0.8 * (i - 100) * kSetpointDt, 0, 0),
                             Eigen::Vector3d(-0.8, 0, 0)));
    EXPECT_EQ(w.stats().reanchorings, blackout ? 1 : 0);
    EXPECT_EQ(w.stats().jumps, blackout ? 0 : 1);
    if (blackout)
      EXPECT_LT(w.stats().max_decel_mps2, 1e-9);
    else
      EXPECT_NEAR(w.stats().max_decel_mps2, 3.8 / 0.05, 1e-6);
  }
}

// Random streams with inserted steps, against the definition evaluated pair by pair.
TEST(SetpointWatch, JumpsMatchTheDefinitionOnRandomStreams) {
  std::mt19937 rng(11);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  std::bernoulli_distribution insert(0.02);
  for (int trial = 0; trial < 20; ++trial) {
    SetpointWatch w;
    std::vector<SetpointSample> stream;
    Eigen::Vector3d p(0, 0, 1), v(2, 0, 0);
    double t = 0.0;
    for (int i = 0; i < 1000; ++i) {
      t += kSetpointDt * (0.5 + 0.5 * std::abs(u(rng)));  // jittered intervals
      v += 0.05 * Eigen::Vector3d(u(rng), u(rng), 0.0);
      p += v * kSetpointDt;
      if (insert(rng)) p += Eigen::Vector3d(u(rng), u(rng), u(rng)) * 0.3;  // a step, maybe below the margin
      stream.push_back(setpoint(t, p, v));
    }
    int expected = 0;
    for (size_t i = 1; i < stream.size(); ++i) {
      const double allowed = std::max(stream[i - 1].velocity_mps.norm(), stream[i].velocity_mps.norm()) *
                                 (stream[i].t_s - stream[i - 1].t_s) +
                             0.05;
      if ((stream[i].position_m - stream[i - 1].position_m).norm() > allowed) ++expected;
    }
    for (const SetpointSample& s : stream) w.addSetpoint(s);
    EXPECT_EQ(w.stats().jumps, expected) << "trial " << trial;
    EXPECT_GT(expected, 0);
  }
}

// A step equal to an injected odometry jump, soon after it, re-anchors once; the same step again,
// a different one, or one after the window are jumps.
TEST(SetpointWatch, StepEqualToAnOdometryJumpIsAReanchoring) {
  SetpointWatch::Config c;  // 0.25 m tolerance, 2 s window
  SetpointWatch w(c);
  double t = 0.0;
  Eigen::Vector3d p(0, 0, 1);
  const Eigen::Vector3d v(1, 0, 0);
  auto cruise = [&](int n) {
    for (int i = 0; i < n; ++i) {
      t += kSetpointDt;
      p += v * kSetpointDt;
      w.addSetpoint(setpoint(t, p, v));
    }
  };
  auto stepBy = [&](const Eigen::Vector3d& d) {
    t += kSetpointDt;
    p += v * kSetpointDt + d;
    w.addSetpoint(setpoint(t, p, v));
  };
  cruise(10);
  w.addOdometryJump(t, Eigen::Vector3d(1.0, 0.0, 0.0));
  cruise(20);
  stepBy(Eigen::Vector3d(1.1, 0.05, 0.0));  // the jump plus tracking error: re-anchoring
  EXPECT_EQ(w.stats().reanchorings, 1);
  EXPECT_EQ(w.stats().jumps, 0);
  cruise(5);
  stepBy(Eigen::Vector3d(1.0, 0.0, 0.0));  // consumed: now a jump
  EXPECT_EQ(w.stats().jumps, 1);
  w.addOdometryJump(t, Eigen::Vector3d(0.0, 1.0, 0.0));
  cruise(5);
  stepBy(Eigen::Vector3d(0.0, -1.0, 0.0));  // the opposite way: a jump
  EXPECT_EQ(w.stats().jumps, 2);
  cruise(300);                             // 3 s: past the window
  stepBy(Eigen::Vector3d(0.0, 1.0, 0.0));
  EXPECT_EQ(w.stats().jumps, 3);
  EXPECT_EQ(w.stats().reanchorings, 1);
  ASSERT_EQ(w.stats().steps.size(), 4u);
  EXPECT_TRUE(w.stats().steps[0].reanchoring);
  EXPECT_FALSE(w.stats().steps[1].reanchoring);
  EXPECT_NEAR(w.stats().max_excess_m, 1.0 - 0.05, 1e-9);
}

// After an odometry blackout the vehicle (held by the flight controller) lags the commanded state
// that ran on: a step onto the measured position soon after odometry returned re-anchors; a step
// elsewhere, or one onto the measured position without a return, is a jump.
TEST(SetpointWatch, StepOntoTheMeasuredPositionAfterABlackoutIsAReanchoring) {
  SetpointWatch w;
  const Eigen::Vector3d hold(-11.5, 0.0, 1.2);
  w.setMeasuredPosition(hold);
  w.addSetpoint(setpoint(5.0, Eigen::Vector3d(-10.4, 0.2, 1.3), Eigen::Vector3d::Zero()));
  w.addSetpoint(setpoint(5.01, hold + Eigen::Vector3d(0.05, 0, 0), Eigen::Vector3d::Zero()));  // no return yet
  EXPECT_EQ(w.stats().jumps, 1);
  w.addSetpoint(setpoint(5.02, Eigen::Vector3d(-10.4, 0.2, 1.3), Eigen::Vector3d::Zero()));  // and back: a jump
  EXPECT_EQ(w.stats().jumps, 2);
  w.addOdometryReturn(5.03);
  w.addSetpoint(setpoint(5.5, Eigen::Vector3d(-9.0, 0.2, 1.3), Eigen::Vector3d::Zero()));  // elsewhere: a jump
  EXPECT_EQ(w.stats().jumps, 3);
  w.addSetpoint(setpoint(5.6, hold + Eigen::Vector3d(0.05, 0, 0), Eigen::Vector3d::Zero()));  // onto it
  EXPECT_EQ(w.stats().jumps, 3);
  EXPECT_EQ(w.stats().reanchorings, 1);
  w.addOdometryReturn(10.0);
  w.addSetpoint(setpoint(12.5, Eigen::Vector3d(-10.0, 0.2, 1.3), Eigen::Vector3d::Zero()));
  w.addSetpoint(setpoint(12.51, hold, Eigen::Vector3d::Zero()));  // past the 2 s window: a jump
  EXPECT_EQ(w.stats().jumps, 5);
}

// A setpoint older than the previous one (an uncorrected time step) gets only the margin and no
// finite difference across it.
TEST(SetpointWatch, TimeGoingBackIsANewStart) {
  SetpointWatch w;
  w.addSetpoint(setpoint(10.0, Eigen::Vector3d(0, 0, 1), Eigen::Vector3d(3, 0, 0)));
  w.addSetpoint(setpoint(10.1, Eigen::Vector3d(0.3, 0, 1), Eigen::Vector3d(3, 0, 0)));
  w.addSetpoint(setpoint(7.0, Eigen::Vector3d(0.33, 0, 1), Eigen::Vector3d(0, 0, 0)));  // 3 cm: no jump
  EXPECT_EQ(w.stats().jumps, 0);
  EXPECT_DOUBLE_EQ(w.stats().max_decel_mps2, 0.0);  // no difference across the step back
  w.addSetpoint(setpoint(6.0, Eigen::Vector3d(0.43, 0, 1), Eigen::Vector3d(0, 0, 0)));  // 10 cm: a jump
  EXPECT_EQ(w.stats().jumps, 1);
  EXPECT_NEAR(w.lastSpeed(), 0.0, 1e-12);
}

// A 200 Hz stream with a backward and a forward ROS time step: the corrected stamps go on at 5 ms.
TEST(TimeStepFilter, StepsAreAbsorbed) {
  TimeStepFilter f(0.5);
  double raw = 100.0, previous = NAN;
  for (int i = 0; i < 3000; ++i) {
    if (i == 1000) raw -= 3.0;
    if (i == 2000) raw += 5.0;
    const double t = f.addStreamStamp(raw);
    if (i > 0) {
      EXPECT_NEAR(t - previous, kDt, 1e-9) << "at " << i;
    }
    previous = t;
    raw += kDt;
  }
  EXPECT_EQ(f.steps(), 2);
  EXPECT_NEAR(f.correction(), 3.0 - 5.0, 1e-9);
  EXPECT_NEAR(f.correct(raw), previous + kDt, 1e-9);  // another topic's stamp, on the same flight time
  // A small reordering (below max_back_s) is not a step.
  TimeStepFilter g(0.5, 1e-3);
  g.addStreamStamp(1.0);
  g.addStreamStamp(0.9995);
  EXPECT_EQ(g.steps(), 0);
}

TEST(GoalResendPolicy, RestartsAndClearedFaults) {
  GoalResendPolicy p(1.0);
  EXPECT_FALSE(p.onHeartbeat(42, true, 0.0));  // the first session
  EXPECT_FALSE(p.onHeartbeat(42, true, 0.05));
  EXPECT_FALSE(p.due(10.0));
  EXPECT_TRUE(p.onHeartbeat(7, false, 10.0));  // restarted, inputs not fresh yet
  EXPECT_EQ(p.restarts(), 1);
  EXPECT_FALSE(p.due(10.5));                   // settling
  EXPECT_FALSE(p.due(11.5));                   // inputs still stale
  p.onHeartbeat(7, true, 11.6);
  EXPECT_TRUE(p.due(11.6));
  EXPECT_FALSE(p.due(11.7));  // once
  p.onFaultCleared(20.0);
  p.onFaultCleared(20.5);  // postpones
  EXPECT_FALSE(p.due(21.2));
  EXPECT_TRUE(p.due(21.5));
  EXPECT_FALSE(p.due(30.0));
  GoalResendPolicy no_heartbeat(0.5);  // without heartbeats the inputs count as fresh
  no_heartbeat.onFaultCleared(1.0);
  EXPECT_TRUE(no_heartbeat.due(1.5));
}

// Odometry without clearance (offset by a jump, or stopped) and the truth with it: the clearance,
// the contacts and the trace come from the truth; faults are recorded with the speeds of the moment.
TEST(FlightRecorder, TruthClearanceSetpointsAndFaults) {
  FlightRecorder rec(FlightRecorder::Config(), {Eigen::Vector3d(10, 0, 1)});
  rec.start(0.0);
  const double nan = std::numeric_limits<double>::quiet_NaN();
  for (int i = 0; i <= 200; ++i) {
    const double t = i * kDt;
    const Eigen::Vector3d p(1.0 * t, 0, 1);
    // The true clearance dips to 0.1 m (a contact) around t = 0.5 s.
    const double clearance = std::abs(t - 0.5) < 0.05 ? 0.1 : 0.5 + t;
    rec.addTruth(sample(t, p, Eigen::Vector3d(1, 0, 0), clearance));
    rec.addOdometry(sample(t, p + Eigen::Vector3d(1, 0, 0), Eigen::Vector3d(1, 0, 0), nan));
    if (i % 2 == 0) rec.addSetpoint(setpoint(t, p, Eigen::Vector3d(1, 0, 0)));
  }
  rec.addFault(0.5, "odom_blackout", "start", "odom_blackout start t=0.500 s until=1.000 s");
  rec.addFault(0.8, "odom_blackout", "end", "odom_blackout end t=0.800 s");
  rec.setCounters(1, 2, 0);
  const FlightSummary s = rec.summary();
  EXPECT_NEAR(s.min_clearance_m, 0.1, 1e-12);
  EXPECT_NEAR(s.min_clearance_position_m.x(), 0.46, 0.011);  // the true position, not the odometry's
  EXPECT_EQ(s.clearance_contacts, 1);
  EXPECT_EQ(s.collisions, 1);
  EXPECT_EQ(s.setpoints, 101);
  EXPECT_EQ(s.setpoint_jumps, 0);
  EXPECT_EQ(s.faults_injected, 1);  // the start, not the end
  EXPECT_EQ(s.planner_restarts, 1);
  EXPECT_EQ(s.goal_resends, 2);
  ASSERT_EQ(rec.faults().size(), 2u);
  EXPECT_NEAR(rec.faults()[0].commanded_speed_mps, 1.0, 1e-12);
  EXPECT_NEAR(rec.faults()[0].true_speed_mps, 1.0, 1e-12);
  EXPECT_EQ(rec.faults()[0].goal_index, 0);
  for (const TraceRow& r : rec.trace()) EXPECT_TRUE(std::isfinite(r.clearance_m));
  EXPECT_NEAR(rec.trace().back().commanded_speed_mps, 1.0, 1e-12);
  EXPECT_NEAR(rec.trace().back().commanded_decel_mps2, 0.0, 1e-12);

  FlightReportInfo info;
  info.name = "t";
  const std::string json = reportJson(s, rec.goals(), rec.startTime(), info, &rec);
  EXPECT_NE(json.find("\"setpoint_jumps\": 0"), std::string::npos);
  EXPECT_NE(json.find("\"planner_restarts\": 1"), std::string::npos);
  EXPECT_NE(json.find("\"kind\": \"odom_blackout\", \"phase\": \"start\""), std::string::npos) << json;
  EXPECT_NE(json.find("\"setpoint_steps\": []"), std::string::npos) << json;
  EXPECT_NE(formatReport(s, "t").find("0 jumps"), std::string::npos);
}

TEST(FlightFiles, JsonValues) {
  EXPECT_EQ(jsonString("a\"b\\c\nd\x01"), "\"a\\\"b\\\\c\\nd\\u0001\"");
  EXPECT_EQ(jsonNumber(NAN), "null");
  EXPECT_EQ(jsonNumber(INFINITY), "null");
  EXPECT_EQ(jsonNumber(0.1), "0.1");
  EXPECT_EQ(jsonNumber(-3.0), "-3");
}

}  // namespace
}  // namespace topo_planner
