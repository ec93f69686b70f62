// The setpoints in quadrotor_msgs/PositionCommand and mavros_msgs/PositionTarget (built when those
// packages are found; make test builds them from test/name_clash/ in its name-clash workspace):
// the public md5sums (so the topics connect to the real packages' subscribers), the fields, frames
// and flags, and a serialisation round trip.
#include <gtest/gtest.h>
#include <ros/serialization.h>

#include <vector>

#include "topo_planner/plan_manage/setpoint_messages.h"

namespace topo_planner {
namespace {

Setpoint sample(Setpoint::Mode mode) {
  Setpoint sp;
  sp.state.position = {1.0, -2.0, 1.5};
  sp.state.velocity = {0.5, 0.25, -0.125};
  sp.state.acceleration = {0.1, -0.2, 0.3};
  sp.state.jerk = {0.01, 0.02, 0.03};
  sp.yaw = 0.75;
  sp.yaw_rate = -0.25;
  sp.trajectory_id = 41;
  sp.planner_session = 7;
  sp.mode = mode;
  return sp;
}

template <typename Msg>
Msg roundTrip(const Msg& in) {
  std::vector<uint8_t> buffer(ros::serialization::serializationLength(in));
  ros::serialization::OStream out(buffer.data(), uint32_t(buffer.size()));
  ros::serialization::serialize(out, in);
  Msg back;
  ros::serialization::IStream is(buffer.data(), uint32_t(buffer.size()));
  ros::serialization::deserialize(is, back);
  return back;
}

#ifdef TOPO_PLANNER_HAVE_QUADROTOR_MSGS
TEST(SetpointMessages, QuadrotorPositionCommandHasThePublicLayout) {
  using Msg = quadrotor_msgs::PositionCommand;
  EXPECT_STREQ(ros::message_traits::DataType<Msg>::value(), "quadrotor_msgs/PositionCommand");
  EXPECT_STREQ(ros::message_traits::MD5Sum<Msg>::value(), "4712f0609ca29a79af79a35ca3e3967a");
  const ros::Time stamp(12.5);
  const Msg cmd = roundTrip(toQuadrotorCommand(sample(Setpoint::Mode::kTrajectory), stamp, "world"));
  EXPECT_EQ(cmd.header.stamp, stamp);
  EXPECT_EQ(cmd.header.frame_id, "world");
  EXPECT_DOUBLE_EQ(cmd.position.x, 1.0);
  EXPECT_DOUBLE_EQ(cmd.position.y, -2.0);
  EXPECT_DOUBLE_EQ(cmd.position.z, 1.5);
  EXPECT_DOUBLE_EQ(cmd.velocity.z, -0.125);
  EXPECT_DOUBLE_EQ(cmd.acceleration.y, -0.2);
  EXPECT_DOUBLE_EQ(cmd.yaw, 0.75);
  EXPECT_DOUBLE_EQ(cmd.yaw_dot, -0.25);
  for (int i = 0; i < 3; ++i) {
    EXPECT_EQ(cmd.kx[i], 0.0);
    EXPECT_EQ(cmd.kv[i], 0.0);
  }
  EXPECT_EQ(cmd.trajectory_id, 42u);  // counted from 1
  EXPECT_EQ(cmd.trajectory_flag, Msg::TRAJECTORY_STATUS_READY);
  // Stops are still on a trajectory; at rest after one it is completed; before the first, id 0.
  EXPECT_EQ(toQuadrotorCommand(sample(Setpoint::Mode::kWatchdogStop), stamp, "world").trajectory_flag,
            Msg::TRAJECTORY_STATUS_READY);
  EXPECT_EQ(toQuadrotorCommand(sample(Setpoint::Mode::kHold), stamp, "world").trajectory_flag,
            Msg::TRAJECTORY_STATUS_COMPLETED);
  Setpoint first = sample(Setpoint::Mode::kHoldBeforeFirst);
  first.trajectory_id = -1;
  const Msg hold = toQuadrotorCommand(first, stamp, "world");
  EXPECT_EQ(hold.trajectory_id, 0u);
  EXPECT_EQ(hold.trajectory_flag, Msg::TRAJECTORY_STATUS_READY);
}
#endif

#ifdef TOPO_PLANNER_HAVE_MAVROS_MSGS
TEST(SetpointMessages, MavrosPositionTargetHasThePublicLayout) {
  using Msg = mavros_msgs::PositionTarget;
  EXPECT_STREQ(ros::message_traits::DataType<Msg>::value(), "mavros_msgs/PositionTarget");
  EXPECT_STREQ(ros::message_traits::MD5Sum<Msg>::value(), "dedb0081aaf8cb20209737746bb49117");
  const ros::Time stamp(3.25);
  const Msg target = roundTrip(toPositionTarget(sample(Setpoint::Mode::kTrajectory), stamp, "world"));
  EXPECT_EQ(target.header.stamp, stamp);
  // ENU values in the local frame; MAVROS turns them into NED (FRAME_LOCAL_NED).
  EXPECT_EQ(target.coordinate_frame, Msg::FRAME_LOCAL_NED);
  EXPECT_EQ(target.type_mask, 0u);  // position, velocity, acceleration, yaw and yaw rate used
  EXPECT_DOUBLE_EQ(target.position.x, 1.0);
  EXPECT_DOUBLE_EQ(target.position.z, 1.5);
  EXPECT_DOUBLE_EQ(target.velocity.y, 0.25);
  EXPECT_DOUBLE_EQ(target.acceleration_or_force.z, 0.3);
  EXPECT_FLOAT_EQ(target.yaw, 0.75f);
  EXPECT_FLOAT_EQ(target.yaw_rate, -0.25f);
}
#endif

}  // namespace
}  // namespace topo_planner
