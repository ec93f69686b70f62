// The link to the trajectory server on its own (server_link.h): which setpoints it takes, when the
// server follows, diverges or holds, the timing re-synchronisation, and the re-anchoring.
#include "topo_planner/topo_replan/server_link.h"

#include <gtest/gtest.h>

namespace topo_planner {
namespace {

// A 4 m straight rest-to-rest trajectory along x from t0 (about 2 s long), with an id.
ExecTrajectory line(int64_t id, double t0) {
  ExecTrajectory traj;
  traj.id = id;
  traj.start_time_s = t0;
  traj.spline = UniformBspline::straightLine(Eigen::Vector3d(0, 0, 1), Eigen::Vector3d(4, 0, 1), 22, 3, 0.1);
  traj.brake_start_s = traj.endTime();
  return traj;
}

ServerSetpoint on(const ExecTrajectory& traj, double stamp) {
  ServerSetpoint sp;
  sp.stamp_s = stamp;
  sp.mode = ServerSetpoint::Mode::kTrajectory;
  sp.own_session = true;
  sp.trajectory_id = traj.id;
  const double tau = stamp - traj.start_time_s;
  sp.position = traj.spline.evaluate(tau);
  sp.velocity = traj.spline.derivative().evaluate(tau);
  return sp;
}

std::function<FlatState(double)> commandedOn(const ExecTrajectory& traj) {
  return [traj](double t) {
    const double tau = std::clamp(t - traj.start_time_s, 0.0, traj.spline.duration());
    FlatState s;
    s.position = traj.spline.evaluate(tau);
    s.velocity = traj.spline.derivative().evaluate(tau);
    return s;
  };
}

using Kind = ServerLink::Verdict::Kind;

TEST(ServerLink, TakesOnlyValidSetpointsInOrder) {
  ServerLink link{ServerLink::Config()};
  const ExecTrajectory traj = line(1, 10.0);
  EXPECT_TRUE(link.set(on(traj, 11.0)));
  EXPECT_FALSE(link.set(on(traj, 10.9)));  // out of order
  ServerSetpoint future = on(traj, 11.5);
  future.arrival_s = 11.1;  // stamped 0.4 s ahead of its arrival
  EXPECT_FALSE(link.set(future));
  ServerSetpoint bad = on(traj, 11.2);
  bad.position.x() = NAN;
  EXPECT_FALSE(link.set(bad));
  EXPECT_EQ(link.latest()->stamp_s, 11.0);
  EXPECT_TRUE(link.freshAt(11.2));
  EXPECT_FALSE(link.freshAt(11.3));
  // Nothing fresh: nothing to judge.
  EXPECT_EQ(link.judge(12.0, &traj, nullptr, commandedOn(traj)).kind, Kind::kFollows);
}

TEST(ServerLink, FollowingItKeepsTheTimingInStep) {
  ServerLink link{ServerLink::Config()};
  const ExecTrajectory traj = line(1, 10.0);
  ASSERT_TRUE(link.set(on(traj, 11.0)));
  ServerLink::Verdict v = link.judge(11.0, &traj, nullptr, commandedOn(traj));
  EXPECT_EQ(v.kind, Kind::kFollows);
  EXPECT_EQ(v.resync_s, 0.0);
  // The server is where the trajectory was 0.12 s earlier (its clock stepped by another amount).
  ServerSetpoint late = on(traj, 10.88);
  late.stamp_s = 11.1;
  ASSERT_TRUE(link.set(late));
  v = link.judge(11.1, &traj, nullptr, commandedOn(traj));
  EXPECT_EQ(v.kind, Kind::kFollows);
  EXPECT_NEAR(v.resync_s, -0.22, 0.001);
  EXPECT_EQ(link.resyncs(), 1);
}

TEST(ServerLink, AServerThatStopsOrFollowsAnotherTrajectoryDiverges) {
  ServerLink link{ServerLink::Config()};
  const ExecTrajectory previous = line(1, 10.0), current = line(2, 11.0);
  // Before the current one has settled (start + grace), the server may still be on the previous one.
  ASSERT_TRUE(link.set(on(previous, 11.1)));
  EXPECT_EQ(link.judge(11.1, &current, &previous, commandedOn(current)).kind, Kind::kFollows);
  // Settled, still on the previous one: not what is commanded.
  ASSERT_TRUE(link.set(on(previous, 11.2)));
  ServerLink::Verdict v = link.judge(11.2, &current, &previous, commandedOn(current));
  EXPECT_EQ(v.kind, Kind::kDiverged);
  EXPECT_TRUE(v.first_report);
  EXPECT_NE(v.why.find("did not command"), std::string::npos) << v.why;
  // A stop of its own: still diverged, said once.
  ServerSetpoint stopping = on(current, 11.3);
  stopping.mode = ServerSetpoint::Mode::kStopping;
  ASSERT_TRUE(link.set(stopping));
  v = link.judge(11.3, &current, &previous, commandedOn(current));
  EXPECT_EQ(v.kind, Kind::kDiverged);
  EXPECT_FALSE(v.first_report);
  // Following again ends the episode: the next divergence is said again.
  ASSERT_TRUE(link.set(on(current, 11.4)));
  EXPECT_EQ(link.judge(11.4, &current, &previous, commandedOn(current)).kind, Kind::kFollows);
  ServerSetpoint other = on(current, 11.5);
  other.own_session = false;
  ASSERT_TRUE(link.set(other));
  v = link.judge(11.5, &current, &previous, commandedOn(current));
  EXPECT_EQ(v.kind, Kind::kDiverged);
  EXPECT_TRUE(v.first_report);
}

TEST(ServerLink, AHoldOfItsOwnIsTakenOnceAsTheCommandedState) {
  ServerLink link{ServerLink::Config()};
  const ExecTrajectory traj = line(1, 10.0);
  // Holding where the commanded trajectory ended (at rest there): that is following.
  ServerSetpoint hold;
  hold.stamp_s = 13.0;
  hold.mode = ServerSetpoint::Mode::kHold;
  hold.position = traj.spline.evaluate(traj.spline.duration());
  ASSERT_TRUE(link.set(hold));
  EXPECT_EQ(link.judge(13.0, &traj, nullptr, commandedOn(traj)).kind, Kind::kFollows);
  // Holding while the trajectory moves: the commanded state is the server's hold.
  hold.stamp_s = 13.1;
  hold.position = traj.spline.evaluate(0.5);
  ExecTrajectory later = line(2, 12.5);
  ASSERT_TRUE(link.set(hold));
  const ServerLink::Verdict v = link.judge(13.1, &later, &traj, commandedOn(later));
  ASSERT_EQ(v.kind, Kind::kHolds);
  EXPECT_NE(v.why.find("moves"), std::string::npos) << v.why;
  EXPECT_EQ(v.hold, hold.position);
  // Re-anchored there: the same setpoint (stamped before) is not judged again.
  link.anchored(13.1);
  EXPECT_EQ(link.judge(13.1, &later, &traj, commandedOn(later)).kind, Kind::kFollows);
  // Before the first trajectory of a (restarted) planner, where it holds.
  EXPECT_TRUE(link.holdAt(13.5));
  EXPECT_FALSE(link.holdAt(15.0));
}

TEST(ServerLink, ATimeJumpShiftsTheStampsOfTheOldClock) {
  ServerLink link{ServerLink::Config()};
  const ExecTrajectory traj = line(1, 10.0);
  ASSERT_TRUE(link.set(on(traj, 11.0)));
  link.anchored(10.5);
  InputMonitor::TimeJump jump;
  jump.shift_s = 100.0;
  jump.old_clock_s = 11.0;
  jump.new_clock_s = 111.05;
  link.shift(jump);
  EXPECT_EQ(link.latest()->stamp_s, 111.0);
  EXPECT_TRUE(link.freshAt(111.05));
  // The anchoring moved too: a setpoint stamped after the old anchoring is still new.
  ServerSetpoint stopping = on(traj, 111.0);
  stopping.stamp_s = 111.1;
  stopping.mode = ServerSetpoint::Mode::kStopping;
  ASSERT_TRUE(link.set(stopping));
  EXPECT_EQ(link.judge(111.1, &traj, nullptr, commandedOn(traj)).kind, Kind::kDiverged);
}

}  // namespace
}  // namespace topo_planner
