// The trajectory server's core: take-over at the start time, hold at the end, the yaw policy, and
// the failure behaviour of issue 11: ordering across planner restarts, the watchdog's smooth stop,
// the end stop, time jumps, the heading target and the hold before the first trajectory.
// Simulated time only: every test samples at 100 Hz on its own clock.
#include <gtest/gtest.h>

#include <cmath>
#include <vector>

#include "topo_planner/topo_replan/setpoint_generator.h"

namespace topo_planner {
namespace {

using Mode = Setpoint::Mode;

constexpr double kDt = 0.01;  // the command period of the tests [s]
// Stated margin of the deceleration check: |dv|/dt over one period may exceed stop_acc_mps2 by
// this much [m/s^2] (the stop itself stays within stop_acc_mps2 up to rounding).
constexpr double kAccMargin = 0.05;

UniformBspline line(const Eigen::Vector3d& a, const Eigen::Vector3d& b) {
  return UniformBspline::straightLine(a, b, 12, 3, 0.5);
}

// A cubic at constant velocity v from p0 for duration_s (ends moving).
UniformBspline constantVelocity(const Eigen::Vector3d& p0, const Eigen::Vector3d& v, double duration_s) {
  const double h = 0.1;
  const int n = int(std::lround(duration_s / h)) + 3;
  Eigen::MatrixX3d q(n, 3);
  for (int i = 0; i < n; ++i) q.row(i) = (p0 + (i - 1) * h * v).transpose();
  return UniformBspline(q, 3, h);
}

// A cubic along a circle of radius r about c (counter-clockwise from angle 0) at about speed_mps.
UniformBspline arc(const Eigen::Vector3d& c, double r, double speed_mps, double duration_s) {
  const double h = 0.1, dtheta = speed_mps * h / r;
  const int n = int(std::lround(duration_s / h)) + 3;
  Eigen::MatrixX3d q(n, 3);
  for (int i = 0; i < n; ++i) {
    const double th = (i - 1) * dtheta;
    q.row(i) = (c + r * Eigen::Vector3d(std::cos(th), std::sin(th), 0.0)).transpose();
  }
  return UniformBspline(q, 3, h);
}

// A cubic cruising at 3 m/s along +x from p0 for cruise_s, then braking at 5 m/s^2 to rest.
UniformBspline cruiseThenBrake(const Eigen::Vector3d& p0, double cruise_s) {
  const double h = 0.1;
  std::vector<double> v(size_t(std::lround(cruise_s / h)) + 2, 3.0);
  for (double s = 2.5; s > 0.0; s -= 0.5) v.push_back(s);
  v.insert(v.end(), {0.0, 0.0, 0.0});
  Eigen::MatrixX3d q(v.size() + 1, 3);
  q.row(0) = (p0 - 3.0 * h * Eigen::Vector3d::UnitX()).transpose();
  for (size_t i = 0; i < v.size(); ++i) q.row(Eigen::Index(i) + 1) = q.row(Eigen::Index(i)) + v[i] * h * Eigen::RowVector3d::UnitX();
  return UniformBspline(q, 3, h);
}

// A cubic braking along +x from p0 at speed v0 with constant deceleration acc to rest.
UniformBspline brakeAlongX(const Eigen::Vector3d& p0, double v0, double acc) {
  const double h = 0.05;
  std::vector<Eigen::Vector3d> pts;
  for (double s = 0.0; s <= v0 / acc + 1e-9; s += h) pts.push_back(p0 + Eigen::Vector3d(v0 * s - 0.5 * acc * s * s, 0, 0));
  UniformBspline brake;
  EXPECT_TRUE(UniformBspline::fitToPoints(pts, h, Eigen::Vector3d(v0, 0, 0), Eigen::Vector3d(-acc, 0, 0),
                                          Eigen::Vector3d::Zero(), Eigen::Vector3d::Zero(), 3, &brake));
  return brake;
}

// A cubic accelerating along +x from rest at p0 at acc for duration_s.
UniformBspline accelerateAlongX(const Eigen::Vector3d& p0, double acc, double duration_s) {
  const double h = 0.05;
  std::vector<Eigen::Vector3d> pts;
  for (double s = 0.0; s <= duration_s + 1e-9; s += h) pts.push_back(p0 + Eigen::Vector3d(0.5 * acc * s * s, 0, 0));
  UniformBspline ramp;
  EXPECT_TRUE(UniformBspline::fitToPoints(pts, h, Eigen::Vector3d::Zero(), Eigen::Vector3d(acc, 0, 0),
                                          Eigen::Vector3d(acc * duration_s, 0, 0), Eigen::Vector3d(acc, 0, 0), 3,
                                          &ramp));
  return ramp;
}

bool stopping(Mode m) { return m == Mode::kEndStop || m == Mode::kWatchdogStop; }

// n samples every kDt from *t, each after a heartbeat (the planner alive); *t ends past the last,
// *sp is the last and sps gets each.
void sampleWithHeartbeats(SetpointGenerator* gen, int n, double* t, Setpoint* sp, std::vector<Setpoint>* sps) {
  for (int k = 0; k < n; ++k, *t += kDt) {
    gen->noteHeartbeat(*t);
    ASSERT_TRUE(gen->sample(*t, sp));
    sps->push_back(*sp);
  }
}

// Setpoints sampled every kDt never jump: each position step is within the speed times the period
// (+ 1 mm); once stopping or holding, each velocity step is within stop_acc (+ kAccMargin) times the
// period and (when jerk_mps3 > 0) each acceleration step within jerk_mps3 times the period.
void expectSmooth(const std::vector<Setpoint>& sps, double stop_acc_mps2, double jerk_mps3) {
  for (size_t k = 1; k < sps.size(); ++k) {
    const Setpoint &a = sps[k - 1], &b = sps[k];
    const double v = std::max(a.state.velocity.norm(), b.state.velocity.norm());
    ASSERT_LE((b.state.position - a.state.position).norm(), v * kDt + 1e-3) << "sample " << k;
    if (stopping(b.mode) || b.mode == Mode::kHold) {
      ASSERT_LE((b.state.velocity - a.state.velocity).norm() / kDt, stop_acc_mps2 + kAccMargin) << "sample " << k;
      if (jerk_mps3 > 0.0) {
        ASSERT_LE((b.state.acceleration - a.state.acceleration).norm(), jerk_mps3 * kDt + 1e-6) << "sample " << k;
      }
    }
  }
}

// --- Take-over, hold, yaw (the behaviour before issue 11) ---

TEST(SetpointGenerator, NothingBeforeTheFirstTrajectoryStarts) {
  SetpointGenerator::Config config;
  config.max_time_step_s = 1.0;  // this test samples every 0.5 s: not time jumps
  SetpointGenerator gen(config);
  Setpoint sp;
  EXPECT_FALSE(gen.sample(0.0, &sp));
  ASSERT_TRUE(gen.add(0, 0, 1.0, line({0, 0, 1}, {5, 0, 1})));
  EXPECT_FALSE(gen.sample(0.5, &sp));
  EXPECT_TRUE(gen.sample(1.0, &sp));
  EXPECT_EQ(sp.trajectory_id, 0);
  EXPECT_EQ(sp.mode, Mode::kTrajectory);
  EXPECT_LT((sp.state.position - Eigen::Vector3d(0, 0, 1)).norm(), 1e-9);
}

TEST(SetpointGenerator, RefusesStaleOrInvalidTrajectories) {
  SetpointGenerator gen{SetpointGenerator::Config()};
  ASSERT_TRUE(gen.add(0, 3, 0.0, line({0, 0, 1}, {5, 0, 1})));
  EXPECT_FALSE(gen.add(0, 3, 1.0, line({0, 0, 1}, {5, 0, 1})));  // not newer
  EXPECT_FALSE(gen.add(0, 4, NAN, line({0, 0, 1}, {5, 0, 1})));
  Eigen::MatrixX3d bad = line({0, 0, 1}, {5, 0, 1}).controlPoints();
  bad(2, 0) = NAN;
  EXPECT_FALSE(gen.add(0, 5, 1.0, UniformBspline(bad, 3, 0.5)));
  EXPECT_FALSE(gen.add(0, 6, 1.0, line({0, 0, 1}, {5, 0, 1}), Eigen::Vector3d(NAN, 0, 0)));
  EXPECT_EQ(gen.stats().refused, 4);
}

TEST(SetpointGenerator, TakesOverAtTheStartTimeAndHoldsTheEnd) {
  SetpointGenerator::Config config;
  config.max_takeover_velocity_gap_mps = 1e9;  // a turn on the spot (continuity: section 5)
  SetpointGenerator gen(config);
  const UniformBspline a = line({0, 0, 1}, {5, 0, 1});
  ASSERT_TRUE(gen.add(0, 0, 0.0, a));
  // The second starts at t = 2 from where the first is then, heading to y = 3.
  const Eigen::Vector3d p2 = a.evaluate(2.0);
  ASSERT_TRUE(gen.add(0, 1, 2.0, line(p2, p2 + Eigen::Vector3d(0, 3, 0))));
  // A live planner (heartbeats), sampled at the command rate (a single step from t = 2 to t = 100
  // would be a time jump).
  Setpoint sp;
  auto sample = [&](double t) {
    gen.noteHeartbeat(t);
    return gen.sample(t, &sp);
  };
  for (int k = 0; k < 199; ++k) ASSERT_TRUE(sample(k * kDt));
  ASSERT_TRUE(sample(1.99));
  EXPECT_EQ(sp.trajectory_id, 0);
  ASSERT_TRUE(sample(2.0));
  EXPECT_EQ(sp.trajectory_id, 1);
  EXPECT_LT((sp.state.position - p2).norm(), 1e-9);
  for (int k = 201; k <= 1000; ++k) ASSERT_TRUE(sample(k * kDt));
  EXPECT_EQ(sp.mode, Mode::kHold);
  EXPECT_LT((sp.state.position - (p2 + Eigen::Vector3d(0, 3, 0))).norm(), 1e-9);
  EXPECT_EQ(sp.state.velocity.norm(), 0.0);
  EXPECT_EQ(gen.stats().end_stops, 0);  // it ended at rest
}

TEST(SetpointGenerator, YawFollowsTheDirectionOfTravelAtALimitedRate) {
  SetpointGenerator::Config config;
  config.max_yaw_rate_radps = 1.0;
  SetpointGenerator gen(config);
  gen.setYaw(0.0);
  ASSERT_TRUE(gen.add(0, 0, 0.0, line({0, 0, 1}, {0, 6, 1})));  // along +y: yaw pi/2
  Setpoint sp;
  double previous = 0.0, max_rate = 0.0;
  for (int k = 0; k <= 300; ++k) {
    gen.noteHeartbeat(k * 0.01);  // a live planner
    ASSERT_TRUE(gen.sample(k * 0.01, &sp));
    max_rate = std::max(max_rate, std::abs(sp.yaw - previous) / 0.01);
    previous = sp.yaw;
  }
  EXPECT_LE(max_rate, 1.0 + 1e-9);
  EXPECT_NEAR(sp.yaw, M_PI / 2, 1e-6);  // reached after pi/2 s
  EXPECT_NEAR(sp.yaw_rate, 0.0, 1e-9);
}

TEST(SetpointGenerator, YawTakesTheShortWayRound) {
  SetpointGenerator::Config config;
  config.max_yaw_rate_radps = 10.0;
  SetpointGenerator gen(config);
  gen.setYaw(3.0);  // near +pi; travel along -x -0.1 y: yaw near -pi
  ASSERT_TRUE(gen.add(0, 0, 0.0, line({0, 0, 1}, {-6, -0.6, 1})));
  Setpoint sp;
  ASSERT_TRUE(gen.sample(0.0, &sp));
  ASSERT_TRUE(gen.sample(0.01, &sp));
  EXPECT_GT(sp.yaw_rate, 0.0);  // increasing through pi, not turning back through 0
}

TEST(SetpointGenerator, ConfigValidation) {
  std::string why;
  EXPECT_TRUE(SetpointGenerator::Config().validate(&why)) << why;
  SetpointGenerator::Config c;
  c.heartbeat_timeout_s = 0.0;
  EXPECT_FALSE(c.validate(&why));
  c = SetpointGenerator::Config();
  c.stop_jerk_mps3 = -1.0;
  EXPECT_FALSE(c.validate(&why));
  c = SetpointGenerator::Config();
  c.max_time_step_s = c.nominal_period_s;  // every step would be a jump
  EXPECT_FALSE(c.validate(&why));
}

// --- 1. Ordering that survives a planner restart ---

TEST(SetpointGenerator, AcceptsARestartedPlannersTrajectories) {
  SetpointGenerator::Config config;
  config.max_takeover_gap_m = config.max_takeover_velocity_gap_mps = 1e9;  // ordering only (continuity: section 5)
  SetpointGenerator gen(config);
  const UniformBspline a = line({0, 0, 1}, {5, 0, 1});
  ASSERT_TRUE(gen.add(7, 41, 0.0, a));
  EXPECT_FALSE(gen.add(7, 40, 0.5, a));  // older id, same session: refused as before
  Setpoint sp;
  for (int k = 0; k <= 100; ++k) ASSERT_TRUE(gen.sample(k * kDt, &sp));
  // The planner restarts: new session, ids from 0 again.
  const Eigen::Vector3d p = a.evaluate(1.195);
  const UniformBspline b = line(p, p + Eigen::Vector3d(0, 2, 0));
  ASSERT_TRUE(gen.add(9, 0, 1.195, b));
  for (int k = 101; k <= 130; ++k) ASSERT_TRUE(gen.sample(k * kDt, &sp));
  EXPECT_EQ(sp.trajectory_id, 0);
  EXPECT_LT((sp.state.position - b.evaluate(1.30 - 1.195)).norm(), 1e-9);
  EXPECT_FALSE(gen.add(9, 0, 1.5, a));  // within the new session the order holds again
  EXPECT_TRUE(gen.add(9, 1, 1.5, line(p, p + Eigen::Vector3d(0, 2, 0))));
  EXPECT_EQ(gen.stats().session_changes, 1);
}

// --- 2. Watchdog and end stop ---

struct Flight {
  std::vector<Setpoint> sps;
  std::vector<double> t;
};

// Samples from t0 to t1 at kDt, calling noteHeartbeat(t) before each sample while t < heartbeat_until.
Flight fly(SetpointGenerator* gen, double t0, double t1, double heartbeat_until) {
  Flight f;
  for (int k = 0; t0 + k * kDt <= t1 + 1e-9; ++k) {
    const double t = t0 + k * kDt;
    if (t < heartbeat_until && k % 5 == 0) gen->noteHeartbeat(t);  // 20 Hz
    Setpoint sp;
    EXPECT_TRUE(gen->sample(t, &sp));
    f.sps.push_back(sp);
    f.t.push_back(t);
  }
  return f;
}

int firstIndexOf(const Flight& f, Mode mode) {
  for (size_t k = 0; k < f.sps.size(); ++k)
    if (f.sps[k].mode == mode) return int(k);
  return -1;
}

TEST(SetpointGenerator, HeartbeatsKeepTheTrajectory) {
  SetpointGenerator gen{SetpointGenerator::Config()};
  const UniformBspline a = constantVelocity({0, 0, 1}, {3, 0, 0}, 10.0);
  ASSERT_TRUE(gen.add(1, 0, 0.0, a));
  const Flight f = fly(&gen, 0.0, 6.0, 100.0);
  EXPECT_EQ(gen.stats().watchdog_stops, 0);
  EXPECT_EQ(f.sps.back().mode, Mode::kTrajectory);
  EXPECT_LT((f.sps.back().state.position - a.evaluate(6.0)).norm(), 1e-6);
}

TEST(SetpointGenerator, WatchdogStopsSmoothlyWithoutHeartbeat) {
  SetpointGenerator::Config config;
  config.heartbeat_timeout_s = 0.505;  // not a multiple of the period: no rounding tie
  SetpointGenerator gen(config);
  const UniformBspline a = constantVelocity({0, 0, 1}, {3, 0, 0}, 10.0);
  ASSERT_TRUE(gen.add(1, 0, 0.0, a));
  ASSERT_TRUE(gen.add(1, 1, 4.0, constantVelocity(a.evaluate(4.0), {3, 0, 0}, 5.0)));  // queued
  const Flight f = fly(&gen, 0.0, 6.0, 2.0);  // the planner goes silent after t = 2
  const int k_stop = firstIndexOf(f, Mode::kWatchdogStop);
  ASSERT_GE(k_stop, 0) << "no watchdog stop";
  // The last heartbeat was at 1.95 s: the stop begins at the first sample where it is older.
  EXPECT_NEAR(f.t[size_t(k_stop)], 2.46, 1e-9);
  EXPECT_EQ(gen.stats().watchdog_stops, 1);
  EXPECT_EQ(gen.stats().dropped_on_watchdog, 1);  // the silent planner's queued trajectory
  expectSmooth(f.sps, config.stop_acc_mps2, config.stop_jerk_mps3);
  const Setpoint& last = f.sps.back();
  EXPECT_EQ(last.mode, Mode::kHold);
  EXPECT_EQ(last.trajectory_id, 0);
  EXPECT_EQ(last.state.velocity.norm(), 0.0);
  // Stopping distance of the S-curve from 3 m/s at a0 = 0: v^2 / 2A + v A / 2J.
  const double v = 3.0, A = config.stop_acc_mps2, J = config.stop_jerk_mps3;
  const Eigen::Vector3d p_stop = f.sps[size_t(k_stop) - 1].state.position + 3.0 * kDt * Eigen::Vector3d::UnitX();
  EXPECT_NEAR(last.state.position.x(), p_stop.x() + v * v / (2 * A) + v * A / (2 * J), 1e-3);
  EXPECT_NEAR(last.state.position.y(), 0.0, 1e-9);
  // The stop uses the full deceleration, not less.
  double max_dec = 0.0;
  for (size_t k = 1; k < f.sps.size(); ++k)
    max_dec = std::max(max_dec, (f.sps[k - 1].state.velocity - f.sps[k].state.velocity).norm() / kDt);
  EXPECT_GT(max_dec, A - 0.01);
}

TEST(SetpointGenerator, WatchdogStopWhileAcceleratingRampsTheAcceleration) {
  SetpointGenerator::Config config;
  SetpointGenerator gen(config);
  const UniformBspline a = UniformBspline::straightLine({0, 0, 1}, {10, 0, 1}, 16, 3, 0.7);
  ASSERT_LT(a.maxAcceleration(), config.stop_acc_mps2);
  ASSERT_TRUE(gen.add(1, 0, 0.0, a));  // only the trajectory's arrival: silent from t = 0
  const Flight f = fly(&gen, 0.0, 4.0, 0.0);
  const int k_stop = firstIndexOf(f, Mode::kWatchdogStop);
  ASSERT_GE(k_stop, 0);
  EXPECT_GT(f.sps[size_t(k_stop) - 1].state.acceleration.x(), 0.5);  // it was speeding up
  expectSmooth(f.sps, config.stop_acc_mps2, config.stop_jerk_mps3);
  EXPECT_EQ(f.sps.back().mode, Mode::kHold);
  EXPECT_LT(f.sps.back().state.position.x(), 3.0);
}

TEST(SetpointGenerator, WatchdogStopFollowsACurvedPath) {
  SetpointGenerator::Config config;
  SetpointGenerator gen(config);
  const Eigen::Vector3d c(0, 0, 1);
  const UniformBspline a = arc(c, 4.0, 2.5, 8.0);
  ASSERT_TRUE(gen.add(1, 0, 0.0, a));
  const Flight f = fly(&gen, 0.0, 4.0, 1.0);
  ASSERT_GE(firstIndexOf(f, Mode::kWatchdogStop), 0);
  EXPECT_EQ(f.sps.back().mode, Mode::kHold);
  // Every stop setpoint lies on the trajectory's path (dense samples 1 mm apart at most).
  std::vector<Eigen::Vector3d> path;
  for (double tau = 0.0; tau <= a.duration(); tau += 0.0004) path.push_back(a.evaluate(tau));
  for (size_t k = 1; k < f.sps.size(); ++k) {
    const Setpoint& sp = f.sps[k];
    if (sp.mode == Mode::kTrajectory) continue;
    double d = 1e9;
    for (const Eigen::Vector3d& p : path) d = std::min(d, (p - sp.state.position).norm());
    ASSERT_LT(d, 2e-3) << "sample " << k;
    // Tangential deceleration (the speed's change) within the limit; positions continuous.
    const double dspeed = f.sps[k - 1].state.velocity.norm() - sp.state.velocity.norm();
    ASSERT_LE(std::abs(dspeed) / kDt, config.stop_acc_mps2 + kAccMargin) << "sample " << k;
    const double v = std::max(sp.state.velocity.norm(), f.sps[k - 1].state.velocity.norm());
    ASSERT_LE((sp.state.position - f.sps[k - 1].state.position).norm(), v * kDt + 1e-3) << "sample " << k;
  }
}

TEST(SetpointGenerator, WatchdogFollowsATrajectoryThatAlreadyStops) {
  // Silent as the trajectory starts braking (at 5 m/s^2) to rest: its own stop is shorter than the
  // watchdog's would be, so it is followed to its end point.
  SetpointGenerator gen{SetpointGenerator::Config()};
  const UniformBspline a = cruiseThenBrake({0, 0, 1}, 2.0);
  ASSERT_TRUE(gen.add(1, 0, 0.0, a));
  const Flight f = fly(&gen, 0.0, a.duration() + 1.0, 1.6);
  const int k_stop = firstIndexOf(f, Mode::kWatchdogStop);
  ASSERT_GE(k_stop, 0);
  for (size_t k = size_t(k_stop); k < f.sps.size(); ++k) {
    if (f.sps[k].mode != Mode::kWatchdogStop) break;
    EXPECT_LT((f.sps[k].state.position - a.evaluate(f.t[k])).norm(), 1e-9);
  }
  EXPECT_EQ(f.sps.back().mode, Mode::kHold);
  EXPECT_LT((f.sps.back().state.position - a.evaluate(a.duration())).norm(), 1e-9);
  EXPECT_EQ(gen.stats().watchdog_stops, 1);
}

TEST(SetpointGenerator, EndStopContinuesStraightAndSmoothly) {
  // A curved trajectory that ends moving at 2.5 m/s, with a fresh heartbeat throughout.
  SetpointGenerator::Config config;
  SetpointGenerator gen(config);
  const UniformBspline a = arc({0, 0, 1}, 4.0, 2.5, 2.0);
  ASSERT_TRUE(gen.add(1, 0, 0.0, a));
  const Flight f = fly(&gen, 0.0, 4.0, 100.0);
  const int k_end = firstIndexOf(f, Mode::kEndStop);
  ASSERT_GE(k_end, 0) << "snapped to a hold at the end";
  EXPECT_EQ(gen.stats().end_stops, 1);
  EXPECT_EQ(gen.stats().watchdog_stops, 0);
  EXPECT_EQ(f.sps.back().mode, Mode::kHold);
  // Straight on along the end direction (the path ends), position and speed continuous.
  const Eigen::Vector3d p_end = a.evaluate(a.duration());
  const Eigen::Vector3d dir = a.derivative().evaluate(a.duration()).normalized();
  for (size_t k = size_t(k_end); k < f.sps.size(); ++k) {
    const Eigen::Vector3d d = f.sps[k].state.position - p_end;
    ASSERT_LT((d - d.dot(dir) * dir).norm(), 1e-9);
    ASSERT_GE(d.dot(dir), 0.0);
  }
  for (size_t k = 1; k < f.sps.size(); ++k) {
    const Setpoint &p = f.sps[k - 1], &q = f.sps[k];
    const double v = std::max(p.state.velocity.norm(), q.state.velocity.norm());
    ASSERT_LE((q.state.position - p.state.position).norm(), v * kDt + 1e-3) << "sample " << k;
    if (q.mode != Mode::kTrajectory) {
      ASSERT_LE(std::abs(p.state.velocity.norm() - q.state.velocity.norm()) / kDt, config.stop_acc_mps2 + kAccMargin);
    }
  }
  // A straight one: the whole stop within the deceleration and jerk limits.
  SetpointGenerator gen2(config);
  ASSERT_TRUE(gen2.add(1, 0, 0.0, constantVelocity({0, 0, 1}, {0, -3, 0}, 2.0)));
  const Flight f2 = fly(&gen2, 0.0, 4.0, 100.0);
  expectSmooth(f2.sps, config.stop_acc_mps2, config.stop_jerk_mps3);
  EXPECT_EQ(gen2.stats().end_stops, 1);
  EXPECT_NEAR(f2.sps.back().state.position.y(), -6.0 - (9.0 / 5.0 + 3.0 * 2.5 / 20.0), 1e-6);
}

// A live planner's trajectory (session, id) from the hold point p, sideways, taking over at t_start:
// sampled until t_end, it is followed without a step.
void resumeFromHold(SetpointGenerator* gen, const Eigen::Vector3d& p, uint64_t session, int64_t id, double t_start,
                    double t_end) {
  ASSERT_TRUE(gen->add(session, id, t_start, line(p, p + Eigen::Vector3d(0, 4, 0))));
  const Flight f = fly(gen, t_start - 0.09, t_end, 100.0);
  EXPECT_EQ(f.sps.back().mode, Mode::kTrajectory);
  EXPECT_EQ(f.sps.back().trajectory_id, id);
  expectSmooth(f.sps, 2.5, 0.0);
}

TEST(SetpointGenerator, NewTrajectoryTakesOverAfterAWatchdogStop) {
  SetpointGenerator gen{SetpointGenerator::Config()};
  ASSERT_TRUE(gen.add(1, 0, 0.0, constantVelocity({0, 0, 1}, {3, 0, 0}, 10.0)));
  Flight f = fly(&gen, 0.0, 3.0, 0.5);
  ASSERT_EQ(f.sps.back().mode, Mode::kHold);
  // The planner is back (a restart): a new trajectory from the hold point.
  resumeFromHold(&gen, f.sps.back().state.position, 2, 0, 3.1, 5.0);
  EXPECT_EQ(gen.stats().watchdog_stops, 1);
}

// --- 3. Time jumps ---

// Flies a 3 m/s trajectory to t = 2, then ROS time jumps by `jump` s (heartbeats every sample in
// both time bases, the first one of the new base before the jump is sampled); checks that the
// setpoint goes on where it was, then that a trajectory in the new time base takes over.
void flyThroughATimeJump(double jump, int64_t expected_backward, int64_t expected_forward) {
  SetpointGenerator gen{SetpointGenerator::Config()};
  const UniformBspline a = constantVelocity({0, 0, 1}, {3, 0, 0}, 10.0);
  ASSERT_TRUE(gen.add(1, 0, 0.0, a));
  std::vector<Setpoint> sps;
  Setpoint sp;
  double t = 0.0, flown = 0.0;  // flown: time along the trajectory
  for (int k = 0; k <= 300; ++k) {
    if (k == 200) t += jump;
    gen.noteHeartbeat(t);
    ASSERT_TRUE(gen.sample(t, &sp));
    sps.push_back(sp);
    ASSERT_EQ(sp.mode, Mode::kTrajectory) << "sample " << k;
    ASSERT_LT((sp.state.position - a.evaluate(flown)).norm(), 1e-6) << "sample " << k;
    t += kDt;
    flown += kDt;
  }
  expectSmooth(sps, 2.5, 0.0);
  EXPECT_EQ(gen.stats().backward_time_jumps, expected_backward);
  EXPECT_EQ(gen.stats().forward_time_jumps, expected_forward);
  EXPECT_EQ(gen.stats().watchdog_stops, 0);
  // The planner replans in the new time base from the current state.
  const double start = t + 0.1;
  const Eigen::Vector3d p = a.evaluate(flown + 0.1);
  ASSERT_TRUE(gen.add(1, 1, start, constantVelocity(p, {3, 0, 0}, 2.0)));
  for (int k = 0; k < 20; ++k, t += kDt) {
    gen.noteHeartbeat(t);
    ASSERT_TRUE(gen.sample(t, &sp));
  }
  EXPECT_EQ(sp.trajectory_id, 1);
  EXPECT_LT((sp.state.position - (p + 3.0 * (t - kDt - start) * Eigen::Vector3d::UnitX())).norm(), 1e-6);
}

TEST(SetpointGenerator, TimeJumpBackwardsKeepsTheSetpoint) { flyThroughATimeJump(-1000.0, 1, 0); }
TEST(SetpointGenerator, SmallTimeStepBackwardsKeepsTheSetpoint) { flyThroughATimeJump(-0.05, 1, 0); }
TEST(SetpointGenerator, TimeJumpForwardsKeepsTheSetpoint) { flyThroughATimeJump(1000.0, 0, 1); }

TEST(SetpointGenerator, WatchdogCountsElapsedTimeAcrossATimeJump) {
  // The planner goes silent at the jump: the stop comes heartbeat_timeout_s of elapsed time after
  // its last heartbeat, not at once (forward) nor never (backward).
  for (const double jump : {1000.0, -1000.0}) {
    SetpointGenerator::Config config;
    config.heartbeat_timeout_s = 0.505;  // not a multiple of the period: no rounding tie
    SetpointGenerator gen(config);
    ASSERT_TRUE(gen.add(1, 0, 0.0, constantVelocity({0, 0, 1}, {3, 0, 0}, 10.0)));
    Setpoint sp;
    double t = 0.0;
    int k_stop = -1;
    for (int k = 0; k <= 300 && k_stop < 0; ++k, t += kDt) {
      if (k == 100) t += jump;
      if (k < 100) gen.noteHeartbeat(t);
      ASSERT_TRUE(gen.sample(t, &sp));
      if (sp.mode == Mode::kWatchdogStop) k_stop = k;
    }
    EXPECT_EQ(k_stop, 99 + 51) << "jump " << jump;  // last heartbeat at sample 99
  }
}

// A stall of the sampling shorter than max_time_step_s (a loaded computer) is not a time jump: the
// setpoint goes on in time, as the planner's clock does (the planner only shifts beyond its own
// threshold, equal by default), so the planner's next trajectory, taking over during the stall on a
// curve, still joins and is not refused.
TEST(SetpointGenerator, AStallIsFlownOnInTimeNotShifted) {
  SetpointGenerator gen{SetpointGenerator::Config()};
  const UniformBspline a = arc({0, 0, 1}, 3.0, 3.0, 10.0);  // 3 m/s on a 3 m radius: 3 m/s^2 centripetal
  ASSERT_TRUE(gen.add(1, 0, 0.0, a));
  Setpoint sp;
  for (int k = 0; k <= 100; ++k) {
    gen.noteHeartbeat(k * kDt);
    ASSERT_TRUE(gen.sample(k * kDt, &sp));
  }
  // The planner's trajectory from the state on `a` at 1.2 s (its takeover time), straight on.
  const UniformBspline av = a.derivative();
  ASSERT_TRUE(gen.add(1, 1, 1.2, constantVelocity(a.evaluate(1.2), av.evaluate(1.2), 2.0)));
  const double t = 1.0 + 0.4;  // 0.4 s without a sample
  gen.noteHeartbeat(t);
  ASSERT_TRUE(gen.sample(t, &sp));
  EXPECT_EQ(gen.stats().forward_time_jumps, 0);
  EXPECT_EQ(gen.stats().discontinuous_refused, 0);
  EXPECT_EQ(sp.trajectory_id, 1);
  EXPECT_LT((sp.state.position - (a.evaluate(1.2) + 0.2 * av.evaluate(1.2))).norm(), 1e-6);
}

// An emergency brake starts at the planner's "now" and reaches the server 80 ms later: judged at its
// start time against the trajectory it replaces, it takes over (judged against the setpoint of the
// moment it would have been refused: 0.4 m/s of velocity difference by then).
TEST(SetpointGenerator, ALateBrakeIsJudgedAtItsStartTime) {
  SetpointGenerator gen{SetpointGenerator::Config()};
  const UniformBspline a = constantVelocity({0, 0, 1}, {3, 0, 0}, 10.0);
  ASSERT_TRUE(gen.add(1, 0, 0.0, a));
  Setpoint sp;
  double t = 0.0;
  for (; t < 1.075; t += kDt) {
    gen.noteHeartbeat(t);
    ASSERT_TRUE(gen.sample(t, &sp));
  }
  // Braking at 5 m/s^2 from (a at 1.0).
  ASSERT_TRUE(gen.add(1, 1, 1.0, brakeAlongX(a.evaluate(1.0), 3.0, 5.0)));
  gen.noteHeartbeat(t);
  ASSERT_TRUE(gen.sample(t, &sp));
  EXPECT_EQ(sp.trajectory_id, 1);
  EXPECT_EQ(gen.stats().discontinuous_refused, 0);
}

// A trajectory from rest that arrives late starts from the commanded state at its start time, but
// has moved on by then: taken over, the setpoint would step by half its acceleration times the
// delay squared (8.4 cm at 2 m/s^2, 0.29 s after the start at the last sample; seen under a
// sanitizer's load after a ROS time step). Refused: the hold goes on. One 0.1 s late steps by
// 1 cm and takes over.
TEST(SetpointGenerator, ALateTakeoverIsJudgedOnTheStepItMakesNow) {
  SetpointGenerator gen{SetpointGenerator::Config()};
  const Eigen::Vector3d p(1, 2, 1);
  ASSERT_TRUE(gen.add(1, 0, 0.0, line(p, p)));
  std::vector<Setpoint> sps;
  Setpoint sp;
  double t = 0.0;
  auto run = [&](int n) { sampleWithHeartbeats(&gen, n, &t, &sp, &sps); };
  run(100);
  ASSERT_TRUE(gen.add(1, 1, t - 0.3, accelerateAlongX(p, 2.0, 2.0)));
  run(10);
  EXPECT_EQ(sp.trajectory_id, 0);
  EXPECT_EQ(gen.stats().discontinuous_refused, 1);
  EXPECT_NEAR(gen.stats().last_takeover_gap_m, 0.084, 0.003);
  EXPECT_LT((sp.state.position - p).norm(), 1e-9);
  expectSmooth(sps, 2.5, 10.0);
  const size_t k = sps.size();  // the take-over sample
  ASSERT_TRUE(gen.add(1, 2, t - 0.1, accelerateAlongX(p, 2.0, 2.0)));
  run(10);
  EXPECT_EQ(sp.trajectory_id, 2);
  EXPECT_EQ(gen.stats().discontinuous_refused, 1);
  const double step = (sps[k].state.position - sps[k - 1].state.position).norm();
  EXPECT_NEAR(step, 0.01, 0.002);
  EXPECT_LE(step, gen.config().max_takeover_gap_m + sps[k].state.velocity.norm() * kDt);
}

// --- 5. Continuity at the take-over ---

// A trajectory that does not start from the state commanded at its start time (a planner that missed
// a watchdog stop, or planned from odometry) is refused at its take-over, and the server stops
// smoothly along its current path (the planner replaced that trajectory: nobody checks it now). A
// trajectory from the commanded state takes over (here from the stop); so does a re-anchoring one.
TEST(SetpointGenerator, RefusesATakeoverThatWouldStepTheSetpoint) {
  SetpointGenerator gen{SetpointGenerator::Config()};
  const UniformBspline a = constantVelocity({0, 0, 1}, {3, 0, 0}, 10.0);
  ASSERT_TRUE(gen.add(1, 0, 0.0, a));
  std::vector<Setpoint> sps;
  Setpoint sp;
  double t = 0.0;
  auto run = [&](int n) { sampleWithHeartbeats(&gen, n, &t, &sp, &sps); };
  run(100);
  // 0.3 m beside the setpoint: refused, and the server stops along a's path.
  ASSERT_TRUE(gen.add(1, 1, 1.05, constantVelocity(a.evaluate(1.05) + Eigen::Vector3d(0, 0.3, 0), {3, 0, 0}, 2.0)));
  run(20);
  EXPECT_EQ(sp.trajectory_id, 0);
  EXPECT_EQ(sp.mode, Mode::kWatchdogStop);
  EXPECT_EQ(gen.stats().discontinuous_refused, 1);
  EXPECT_EQ(gen.stats().refusal_stops, 1);
  EXPECT_EQ(gen.stats().last_refused_id, 1);
  EXPECT_NEAR(gen.stats().last_takeover_gap_m, 0.3, 0.01);
  EXPECT_LT(std::abs(sp.state.position.y()), 1e-9);  // on a's path
  expectSmooth(sps, 2.5, 10.0);
  // From the commanded (stopping) state of the last sample, on at its velocity: taken over.
  const double t_last = t - kDt;
  ASSERT_TRUE(gen.add(1, 2, t_last, constantVelocity(sp.state.position, sp.state.velocity, 2.0)));
  run(10);
  EXPECT_EQ(sp.trajectory_id, 2);
  EXPECT_EQ(sp.mode, Mode::kTrajectory);
  // Right position, velocity stepping by 1 m/s: refused too (a second stop).
  const Eigen::Vector3d v = sp.state.velocity;
  ASSERT_TRUE(gen.add(1, 3, t - kDt, constantVelocity(sp.state.position, v - Eigen::Vector3d(1, 0, 0), 2.0)));
  run(10);
  EXPECT_EQ(sp.trajectory_id, 2);
  EXPECT_EQ(gen.stats().discontinuous_refused, 2);
  EXPECT_EQ(gen.stats().refusal_stops, 2);
  // A re-anchoring one 0.5 m away: taken over (the step is the odometry's).
  const Eigen::Vector3d measured = sp.state.position + Eigen::Vector3d(0, 0.5, 0);
  ASSERT_TRUE(gen.add(1, 4, t, line(measured, measured), std::nullopt, /*reanchor=*/true));
  run(2);
  EXPECT_EQ(sp.trajectory_id, 4);
  EXPECT_LT((sp.state.position - measured).norm(), 1e-9);
  EXPECT_EQ(gen.stats().discontinuous_refused, 2);
}

// The planner brakes from the trajectory it still flies while its next plan waits for its take-over;
// the brake reaches the server after that plan took over there. Judged on the trajectory the plan
// replaced (what was commanded at the brake's start), it is accepted. (Judged on the plan clamped to
// its start it was refused, 0.13 m off, and a max_vel 4 flight collided.)
TEST(SetpointGenerator, ABrakeStartingBeforeTheCurrentTakeoverIsJudgedOnWhatItReplaced) {
  SetpointGenerator gen{SetpointGenerator::Config()};
  const UniformBspline a = constantVelocity({0, 0, 1}, {3, 0, 0}, 10.0);
  ASSERT_TRUE(gen.add(1, 0, 0.0, a));
  ASSERT_TRUE(gen.add(1, 1, 1.0, constantVelocity(a.evaluate(1.0), {3, 0, 0}, 3.0)));
  Setpoint sp;
  double t = 0.0;
  for (; t < 1.025; t += kDt) {
    gen.noteHeartbeat(t);
    ASSERT_TRUE(gen.sample(t, &sp));
  }
  ASSERT_EQ(sp.trajectory_id, 1);
  // The brake from a's state at 0.95 s, at 5 m/s^2.
  ASSERT_TRUE(gen.add(1, 2, 0.95, brakeAlongX(a.evaluate(0.95), 3.0, 5.0)));
  gen.noteHeartbeat(t);
  ASSERT_TRUE(gen.sample(t, &sp));
  EXPECT_EQ(sp.trajectory_id, 2);
  EXPECT_EQ(gen.stats().discontinuous_refused, 0);
}

// After a watchdog stop, the silent planner's trajectory from where it believes the vehicle is (on
// its own trajectory, not on the stop) is refused; one from the server's hold takes over.
TEST(SetpointGenerator, AfterAWatchdogStopOnlyATrajectoryFromTheHoldTakesOver) {
  SetpointGenerator gen{SetpointGenerator::Config()};
  const UniformBspline a = constantVelocity({0, 0, 1}, {3, 0, 0}, 10.0);
  ASSERT_TRUE(gen.add(1, 0, 0.0, a));
  Flight f = fly(&gen, 0.0, 3.0, 0.5);
  ASSERT_EQ(f.sps.back().mode, Mode::kHold);
  ASSERT_TRUE(gen.add(1, 1, 3.1, constantVelocity(a.evaluate(3.1), {3, 0, 0}, 2.0)));
  Flight g = fly(&gen, 3.01, 3.3, 100.0);
  EXPECT_EQ(g.sps.back().mode, Mode::kHold);
  EXPECT_EQ(gen.stats().discontinuous_refused, 1);
  resumeFromHold(&gen, g.sps.back().state.position, 1, 2, 3.4, 4.0);
}

// --- 4. Heading target ---

double finalYaw(const std::optional<Eigen::Vector3d>& target) {
  SetpointGenerator::Config config;
  SetpointGenerator gen(config);
  gen.setYaw(0.0);
  EXPECT_TRUE(gen.add(1, 0, 0.0, line({0, 0, 1}, {3, 0, 1}), target));  // stops at (3, 0, 1)
  const Flight f = fly(&gen, 0.0, 8.0, 100.0);
  for (size_t k = 1; k < f.sps.size(); ++k)
    EXPECT_LE(std::abs(std::remainder(f.sps[k].yaw - f.sps[k - 1].yaw, 2 * M_PI)),
              config.max_yaw_rate_radps * kDt + 1e-9);
  EXPECT_EQ(f.sps.back().mode, Mode::kHold);
  return f.sps.back().yaw;
}

TEST(SetpointGenerator, HoldingTurnsTowardsTheHeadingTarget) {
  EXPECT_NEAR(finalYaw(std::nullopt), 0.0, 1e-6);                   // no target: held
  EXPECT_NEAR(finalYaw(Eigen::Vector3d(3, 5, 1)), M_PI / 2, 1e-6);   // looks where it plans to go
  EXPECT_NEAR(finalYaw(Eigen::Vector3d(3, -4, 9)), -M_PI / 2, 1e-6);
  EXPECT_NEAR(finalYaw(Eigen::Vector3d(3, 0, 5)), 0.0, 1e-6);        // above the end: held
}

TEST(SetpointGenerator, HeadingTargetDoesNotOverrideTheDirectionOfTravel) {
  SetpointGenerator gen{SetpointGenerator::Config()};
  gen.setYaw(0.0);
  ASSERT_TRUE(gen.add(1, 0, 0.0, constantVelocity({0, 0, 1}, {3, 0, 0}, 5.0), Eigen::Vector3d(0, 20, 1)));
  const Flight f = fly(&gen, 0.0, 3.0, 100.0);
  for (const Setpoint& sp : f.sps) ASSERT_NEAR(sp.yaw, 0.0, 1e-12);
}

// --- 5. Hold before the first trajectory ---

TEST(SetpointGenerator, HoldsTheVehiclePoseBeforeTheFirstTrajectory) {
  SetpointGenerator::Config config;
  config.hold_before_first_trajectory = true;
  SetpointGenerator gen(config);
  Setpoint sp;
  EXPECT_FALSE(gen.sample(0.0, &sp));  // no pose yet
  gen.setVehiclePose({1, 2, 3}, 0.7);
  ASSERT_TRUE(gen.sample(0.01, &sp));
  EXPECT_EQ(sp.mode, Mode::kHoldBeforeFirst);
  EXPECT_EQ(sp.trajectory_id, -1);
  EXPECT_LT((sp.state.position - Eigen::Vector3d(1, 2, 3)).norm(), 1e-12);
  EXPECT_EQ(sp.state.velocity.norm(), 0.0);
  EXPECT_NEAR(sp.yaw, 0.7, 1e-12);
  gen.setVehiclePose({1.01, 2, 3}, 0.8);  // follows the pose
  ASSERT_TRUE(gen.sample(0.02, &sp));
  EXPECT_NEAR(sp.state.position.x(), 1.01, 1e-12);
  EXPECT_NEAR(sp.yaw, 0.8, 1e-12);
  ASSERT_TRUE(gen.add(1, 0, 0.1, line({1.01, 2, 3}, {1.01, 2, 5})));
  for (double t = 0.03; t < 0.095; t += kDt) ASSERT_TRUE(gen.sample(t, &sp));
  EXPECT_EQ(sp.mode, Mode::kHoldBeforeFirst);
  ASSERT_TRUE(gen.sample(0.1, &sp));
  EXPECT_EQ(sp.mode, Mode::kTrajectory);
  EXPECT_NEAR(sp.yaw, 0.8, 1e-12);  // the yaw goes on from the vehicle's
  gen.setVehiclePose({9, 9, 9}, 0.0);  // ignored once flying
  ASSERT_TRUE(gen.sample(0.11, &sp));
  EXPECT_LT((sp.state.position - Eigen::Vector3d(1.01, 2, 3)).norm(), 0.01);
  // Without the option nothing is sent before the first trajectory (the controller holds).
  SetpointGenerator off{SetpointGenerator::Config()};
  off.setVehiclePose({1, 2, 3}, 0.7);
  EXPECT_FALSE(off.sample(0.0, &sp));
}

}  // namespace
}  // namespace topo_planner
