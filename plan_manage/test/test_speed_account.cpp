#include "topo_planner/plan_manage/speed_account.h"

#include <gtest/gtest.h>

namespace topo_planner {
namespace {

// A straight trajectory along x at constant speed v from x0 for duration_s (a uniform cubic B-spline
// with evenly spaced control points moves at exactly (spacing / knot span) in its interior; the
// padding control points before and after make [0, duration] interior).
UniformBspline constantSpeed(double x0, double v, double duration_s) {
  const double h = 0.1;
  const int segments = int(duration_s / h + 0.5);
  Eigen::MatrixX3d q(segments + 3, 3);
  for (int i = 0; i < q.rows(); ++i) q.row(i) << x0 + v * h * (i - 1), 0.0, 1.0;
  return UniformBspline(q, 3, h);
}

SpeedAccount::Trajectory plan(int64_t id, double start, double v, double duration, double brake_start = 1e9) {
  SpeedAccount::Trajectory t;
  t.session = 7;
  t.id = id;
  t.start_s = start;
  t.brake_start_s = std::min(brake_start, start + duration);
  t.spline = constantSpeed(0.0, v, duration);
  return t;
}

SpeedAccount::Setpoint on(int64_t id, const Eigen::Vector3d& v, const Eigen::Vector3d& a = Eigen::Vector3d::Zero()) {
  SpeedAccount::Setpoint s;
  s.mode = SpeedAccount::Mode::kTrajectory;
  s.session = 7;
  s.trajectory_id = id;
  s.velocity = v;
  s.acceleration = a;
  return s;
}

SlowCause classify(const SpeedAccount& account, double t, double speed) {
  bool fast = true;
  const SlowCause cause = account.classify(t, speed, &fast);
  EXPECT_FALSE(fast) << "t " << t << " speed " << speed;
  return cause;
}

TEST(SpeedAccount, TheSplineHelperMovesAtItsSpeed) {
  const UniformBspline s = constantSpeed(0.0, 2.0, 3.0);
  EXPECT_NEAR(s.duration(), 3.0, 1e-9);
  EXPECT_NEAR(s.derivative().evaluate(1.3).norm(), 2.0, 1e-9);
}

TEST(SpeedAccount, EachCauseIsNamedByWhatWasCommanded) {
  SpeedAccount::Config c;
  c.max_vel_mps = 3.0;  // fast at 2.4 m/s and above
  c.max_acc_mps2 = 2.5; // the limits at 1.5 m/s^2
  SpeedAccount a(c);
  bool fast = false;
  // Nothing commanded yet, or the server holds: held.
  EXPECT_EQ(classify(a, 0.0, 0.0), SlowCause::kHeld);
  SpeedAccount::Setpoint hold;
  a.setSetpoint(hold);
  EXPECT_EQ(classify(a, 0.0, 0.0), SlowCause::kHeld);
  // Fast is fast, whatever is commanded.
  a.classify(0.0, 2.5, &fast);
  EXPECT_TRUE(fast);

  // A plan at 1.5 m/s, steady: its timing.
  a.addTrajectory(plan(1, 0.0, 1.5, 10.0));
  a.setSetpoint(on(1, Eigen::Vector3d(1.5, 0, 0)));
  EXPECT_EQ(classify(a, 2.0, 1.5), SlowCause::kTiming);
  // Accelerating along the way, or turning, at 1.5 m/s^2 or more: the limits.
  a.setSetpoint(on(1, Eigen::Vector3d(1.5, 0, 0), Eigen::Vector3d(1.6, 0, 0)));
  EXPECT_EQ(classify(a, 2.0, 1.5), SlowCause::kLimits);
  a.setSetpoint(on(1, Eigen::Vector3d(1.5, 0, 0), Eigen::Vector3d(-1.6, 0, 0)));
  EXPECT_EQ(classify(a, 2.0, 1.5), SlowCause::kLimits);
  a.setSetpoint(on(1, Eigen::Vector3d(1.5, 0, 0), Eigen::Vector3d(0.2, 1.6, 0)));
  EXPECT_EQ(classify(a, 2.0, 1.5), SlowCause::kLimits);
  a.setSetpoint(on(1, Eigen::Vector3d(1.5, 0, 0), Eigen::Vector3d(1.0, 1.0, 0)));
  EXPECT_EQ(classify(a, 2.0, 1.5), SlowCause::kTiming);
  // Commanded fast, flown slow: tracking.
  a.setSetpoint(on(1, Eigen::Vector3d(2.6, 0, 0)));
  EXPECT_EQ(classify(a, 2.0, 2.0), SlowCause::kTracking);
  // A command at rest on a plan: held.
  a.setSetpoint(on(1, Eigen::Vector3d(0.05, 0, 0), Eigen::Vector3d(0.1, 0, 0)));
  EXPECT_EQ(classify(a, 2.0, 0.05), SlowCause::kHeld);
  // ... but at rest and accelerating away, at the limits.
  a.setSetpoint(on(1, Eigen::Vector3d(0.05, 0, 0), Eigen::Vector3d(2.0, 0, 0)));
  EXPECT_EQ(classify(a, 2.0, 0.05), SlowCause::kLimits);

  // The server's own stop, an emergency braking, a manoeuvre.
  SpeedAccount::Setpoint stopping = on(1, Eigen::Vector3d(1.0, 0, 0));
  stopping.mode = SpeedAccount::Mode::kStopping;
  a.setSetpoint(stopping);
  EXPECT_EQ(classify(a, 2.0, 1.0), SlowCause::kBraking);
  SpeedAccount::Trajectory brake = plan(2, 3.0, 1.0, 1.0);
  brake.kind = SpeedAccount::TrajectoryKind::kBraking;
  a.addTrajectory(brake);
  a.setSetpoint(on(2, Eigen::Vector3d(1.0, 0, 0)));
  EXPECT_EQ(classify(a, 3.5, 1.0), SlowCause::kBraking);
  SpeedAccount::Trajectory escape = plan(3, 5.0, 0.4, 2.0);
  escape.kind = SpeedAccount::TrajectoryKind::kManoeuvre;
  a.addTrajectory(escape);
  a.setSetpoint(on(3, Eigen::Vector3d(0.4, 0, 0)));
  EXPECT_EQ(classify(a, 5.5, 0.4), SlowCause::kHeld);
}

TEST(SpeedAccount, PastTheBrakePointOfACutPlanIsTheCommitment) {
  SpeedAccount a;
  a.addTrajectory(plan(1, 10.0, 1.5, 4.0, /*brake_start=*/12.0));
  a.setSetpoint(on(1, Eigen::Vector3d(1.5, 0, 0)));
  EXPECT_EQ(classify(a, 11.0, 1.5), SlowCause::kTiming);
  a.setSetpoint(on(1, Eigen::Vector3d(1.0, 0, 0), Eigen::Vector3d(-2.5, 0, 0)));
  EXPECT_EQ(classify(a, 12.5, 1.0), SlowCause::kCommitment);
  // Its end, at rest: still the commitment (waiting to see further), not a hold of its own.
  a.setSetpoint(on(1, Eigen::Vector3d::Zero()));
  EXPECT_EQ(classify(a, 14.5, 0.0), SlowCause::kCommitment);
  // A plan taking over from that committed stop: what it starts from was lost to the commitment,
  // for the takeover window; then its own pace.
  a.addTrajectory(plan(3, 13.0, 1.0, 4.0));
  a.setSetpoint(on(3, Eigen::Vector3d(1.2, 0, 0), Eigen::Vector3d(2.0, 0, 0)));
  EXPECT_EQ(classify(a, 13.5, 1.2), SlowCause::kCommitment);
  EXPECT_EQ(classify(a, 14.5, 1.2), SlowCause::kLimits);
  // A plan that was not cut has no brake point: its end at rest is a hold.
  a.addTrajectory(plan(2, 20.0, 1.5, 4.0));
  a.setSetpoint(on(2, Eigen::Vector3d::Zero()));
  EXPECT_EQ(classify(a, 24.5, 0.0), SlowCause::kHeld);
}

TEST(SpeedAccount, ASlowerPlanTakingOverIsTheTakeover) {
  SpeedAccount a;
  a.addTrajectory(plan(1, 0.0, 2.0, 5.0));
  a.addTrajectory(plan(2, 1.0, 1.2, 5.0));
  a.setSetpoint(on(2, Eigen::Vector3d(1.2, 0, 0)));
  EXPECT_EQ(classify(a, 1.5, 1.2), SlowCause::kTakeover);
  // After the window, the new plan's own timing.
  EXPECT_EQ(classify(a, 2.5, 1.2), SlowCause::kTiming);
  // Not when the plan replaced was braking then (cut at 1.2 s): the take-over kept it going.
  SpeedAccount b;
  b.addTrajectory(plan(1, 0.0, 2.0, 5.0, /*brake_start=*/1.2));
  b.addTrajectory(plan(2, 1.0, 1.2, 5.0));
  b.setSetpoint(on(2, Eigen::Vector3d(1.2, 0, 0)));
  EXPECT_EQ(classify(b, 1.5, 1.2), SlowCause::kTiming);
  // Nor when the new plan is as fast.
  SpeedAccount c;
  c.addTrajectory(plan(1, 0.0, 1.3, 5.0));
  c.addTrajectory(plan(2, 1.0, 1.25, 5.0));
  c.setSetpoint(on(2, Eigen::Vector3d(1.25, 0, 0)));
  EXPECT_EQ(classify(c, 1.5, 1.25), SlowCause::kTiming);
}

TEST(SpeedAccount, IntegratesIntervalsAndSkipsGaps) {
  SpeedAccount::Config c;
  c.max_gap_s = 0.5;
  SpeedAccount a(c);
  a.addTrajectory(plan(1, 0.0, 1.5, 100.0));
  a.setSetpoint(on(1, Eigen::Vector3d(1.5, 0, 0)));
  for (int k = 0; k <= 100; ++k) a.addSpeed(0.01 * k, 1.5);  // 1 s slow: timing
  a.setSetpoint(on(1, Eigen::Vector3d(2.6, 0, 0)));
  for (int k = 1; k <= 100; ++k) a.addSpeed(1.0 + 0.01 * k, 2.6);  // 1 s fast
  a.addSpeed(3.0, 2.6);       // a gap of 1 s: not counted
  a.addSpeed(2.5, 2.6);       // out of order: ignored
  a.addSpeed(3.01, NAN);      // not finite: ignored
  a.addSpeed(3.02, 2.6);
  // Each interval goes by the speed at its start and the setpoint in force: [1.0, 1.01] began slow
  // under a fast command (tracking).
  const SpeedAccount::Totals& t = a.totals();
  EXPECT_NEAR(t.total_s, 2.02, 1e-9);
  EXPECT_NEAR(t.fast_s, 1.01, 1e-9);
  EXPECT_NEAR(t.slow_s[size_t(SlowCause::kTiming)], 1.0, 1e-9);
  EXPECT_NEAR(t.slow_s[size_t(SlowCause::kTracking)], 0.01, 1e-9);
  EXPECT_NEAR(t.slow(), 1.01, 1e-9);
  EXPECT_NEAR(t.share(SlowCause::kTiming), 1.0 / 1.01, 1e-9);
  EXPECT_EQ(t.share(SlowCause::kHeld), 0.0);
}

TEST(SpeedAccount, RefusesBadConfigAndInput) {
  SpeedAccount::Config c;
  std::string why;
  EXPECT_TRUE(c.validate(&why)) << why;
  c.fast_fraction = 1.5;
  c.max_vel_mps = NAN;
  EXPECT_FALSE(c.validate(&why));
  EXPECT_NE(why.find("fast_fraction"), std::string::npos);
  EXPECT_NE(why.find("max_vel_mps"), std::string::npos);
  SpeedAccount a;
  a.setSetpoint(on(1, Eigen::Vector3d(NAN, 0, 0)));  // ignored: nothing commanded yet
  EXPECT_EQ(classify(a, 0.0, 0.0), SlowCause::kHeld);
  SpeedAccount::Trajectory bad = plan(1, NAN, 1.0, 1.0);
  a.addTrajectory(bad);  // ignored
  a.setSetpoint(on(1, Eigen::Vector3d(1.0, 0, 0)));
  EXPECT_EQ(classify(a, 0.5, 1.0), SlowCause::kTiming);  // classified from the command alone
  for (int i = 0; i < 200; ++i) a.addTrajectory(plan(i, i, 1.0, 1.0));  // bounded memory
  EXPECT_EQ(classify(a, 199.5, 1.0), SlowCause::kTiming);
}

}  // namespace
}  // namespace topo_planner
