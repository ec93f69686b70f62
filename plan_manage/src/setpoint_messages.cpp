#include "topo_planner/plan_manage/setpoint_messages.h"

#include <type_traits>
#include <utility>

namespace topo_planner {
namespace {

[[maybe_unused]] void setVector(const Eigen::Vector3d& v, geometry_msgs::Vector3* m) {
  m->x = v.x();
  m->y = v.y();
  m->z = v.z();
}

[[maybe_unused]] void setPoint(const Eigen::Vector3d& v, geometry_msgs::Point* m) {
  m->x = v.x();
  m->y = v.y();
  m->z = v.z();
}

// The jerk field exists in EGO-Planner's quadrotor_msgs/PositionCommand, not in Fast-Planner's.
template <typename Msg, typename = void>
struct HasJerk : std::false_type {};
template <typename Msg>
struct HasJerk<Msg, std::void_t<decltype(std::declval<Msg&>().jerk)>> : std::true_type {};
template <typename Msg>
[[maybe_unused]] void setJerkIfPresent(const Eigen::Vector3d& jerk, Msg* msg) {
  if constexpr (HasJerk<Msg>::value) setVector(jerk, &msg->jerk);
}

}  // namespace

#ifdef TOPO_PLANNER_HAVE_QUADROTOR_MSGS
quadrotor_msgs::PositionCommand toQuadrotorCommand(const Setpoint& sp, const ros::Time& stamp,
                                                   const std::string& frame_id) {
  using Msg = quadrotor_msgs::PositionCommand;
  Msg cmd;
  cmd.header.stamp = stamp;
  cmd.header.frame_id = frame_id;
  setPoint(sp.state.position, &cmd.position);
  setVector(sp.state.velocity, &cmd.velocity);
  setVector(sp.state.acceleration, &cmd.acceleration);
  setJerkIfPresent(sp.state.jerk, &cmd);
  cmd.yaw = sp.yaw;
  cmd.yaw_dot = sp.yaw_rate;
  for (int i = 0; i < 3; ++i) cmd.kx[i] = cmd.kv[i] = 0.0;  // the controller's own gains
  cmd.trajectory_id = sp.trajectory_id >= 0 ? uint32_t(sp.trajectory_id + 1) : 0u;
  cmd.trajectory_flag = sp.mode == Setpoint::Mode::kHold ? Msg::TRAJECTORY_STATUS_COMPLETED : Msg::TRAJECTORY_STATUS_READY;
  return cmd;
}
#endif

#ifdef TOPO_PLANNER_HAVE_MAVROS_MSGS
mavros_msgs::PositionTarget toPositionTarget(const Setpoint& sp, const ros::Time& stamp, const std::string& frame_id) {
  mavros_msgs::PositionTarget target;
  target.header.stamp = stamp;
  target.header.frame_id = frame_id;
  target.coordinate_frame = mavros_msgs::PositionTarget::FRAME_LOCAL_NED;  // ENU values: MAVROS converts
  target.type_mask = 0;  // position, velocity, acceleration, yaw and yaw rate all used
  setPoint(sp.state.position, &target.position);
  setVector(sp.state.velocity, &target.velocity);
  setVector(sp.state.acceleration, &target.acceleration_or_force);
  target.yaw = float(sp.yaw);
  target.yaw_rate = float(sp.yaw_rate);
  return target;
}
#endif

}  // namespace topo_planner
