#pragma once
// Setpoints in the messages existing drone stacks read, each built when its message package is
// found at configure time (neither is in Debian 12; CMake defines TOPO_PLANNER_HAVE_QUADROTOR_MSGS
// and TOPO_PLANNER_HAVE_MAVROS_MSGS):
//   quadrotor_msgs/PositionCommand  Fast-Planner's and EGO-Planner's controllers (so3 control,
//                                   px4ctrl). World frame, ENU (z up), as the planner's setpoints.
//                                   kx and kv are zero (the controller keeps its own gains); jerk is
//                                   set when the message has the field (EGO's layout).
//   mavros_msgs/PositionTarget      PX4 or ArduPilot through MAVROS (`setpoint_raw/local`). The
//                                   values are ROS ENU in the local frame, and coordinate_frame is
//                                   FRAME_LOCAL_NED: MAVROS converts ENU to NED itself. Position,
//                                   velocity, acceleration (not force), yaw and yaw rate all used
//                                   (type_mask 0). yaw is ENU (0 = east, counter-clockwise).
// Both carry only what the controller needs; topo_planner/PositionCommand keeps the planner's own
// fields (trajectory mode, planner session).

#include <ros/time.h>

#include <string>

#include "topo_planner/topo_replan/setpoint_generator.h"

#ifdef TOPO_PLANNER_HAVE_QUADROTOR_MSGS
#include <quadrotor_msgs/PositionCommand.h>
#endif
#ifdef TOPO_PLANNER_HAVE_MAVROS_MSGS
#include <mavros_msgs/PositionTarget.h>
#endif

namespace topo_planner {

#ifdef TOPO_PLANNER_HAVE_QUADROTOR_MSGS
/// trajectory_id is the planner's id + 1 (the message counts from 1; 0 before the first
/// trajectory); trajectory_flag is TRAJECTORY_STATUS_READY while on or stopping from a trajectory
/// and holding before the first, TRAJECTORY_STATUS_COMPLETED when at rest after one.
quadrotor_msgs::PositionCommand toQuadrotorCommand(const Setpoint& setpoint, const ros::Time& stamp,
                                                   const std::string& frame_id);
#endif

#ifdef TOPO_PLANNER_HAVE_MAVROS_MSGS
mavros_msgs::PositionTarget toPositionTarget(const Setpoint& setpoint, const ros::Time& stamp,
                                             const std::string& frame_id);
#endif

}  // namespace topo_planner
