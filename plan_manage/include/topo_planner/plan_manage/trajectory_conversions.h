#pragma once
// Conversions between the planner's core types and the closed loop's messages, in one place for the
// planner node and the trajectory server.

#include <geometry_msgs/PoseStamped.h>
#include <nav_msgs/Path.h>
#include <ros/time.h>
#include <visualization_msgs/Marker.h>

#include <cstdint>
#include <optional>
#include <string>

#include "topo_planner/Bspline.h"
#include "topo_planner/PositionCommand.h"
#include "topo_planner/topo_replan/replan_fsm.h"
#include "topo_planner/topo_replan/setpoint_generator.h"

namespace topo_planner {

/// The message of a trajectory whose start_time_s is in ROS time seconds, from the planner process
/// `planner_session` (a number drawn when it starts: ordering across restarts), with its heading
/// target when it has one.
Bspline toMsg(const ExecTrajectory& trajectory, const std::string& frame_id, uint64_t planner_session);

/// What the trajectory server takes from a Bspline message.
struct ReceivedTrajectory {
  uint64_t planner_session = 0;
  int64_t id = -1;
  double start_time_s = 0.0;  ///< [s, ROS time]
  UniformBspline spline;
  std::optional<Eigen::Vector3d> heading_target;  ///< set when has_heading_target [m, world]
  bool reanchor = false;                          ///< deliberately starts away from the setpoint
  uint8_t kind = Bspline::KIND_PLAN;              ///< plan, braking or manoeuvre (an unknown kind: plan)
  /// Where the committed stop begins (the known-space commitment) [s, ROS time]; not before the start.
  double brake_start_s = 0.0;
};
/// The content of a message; false (with a reason) for an invalid one (too few or non-finite
/// control points, bad degree or knot span, a non-finite heading target).
bool fromMsg(const Bspline& msg, ReceivedTrajectory* out, std::string* why);

/// Most waypoints a nav_msgs/Path goal may hold.
constexpr size_t kMaxWaypoints = 1000;
/// A received B-spline's knot span [s] and coordinates [m] lie within these bounds (fromMsg):
/// beyond them its derivatives (differences of control points over powers of the knot span)
/// overflow; the planner sends knot spans of tenths of a second and points within its map.
constexpr double kMinKnotSpanS = 1e-3;
constexpr double kMaxKnotSpanS = 10.0;
constexpr double kMaxCoordinateM = 1e5;

/// The goal of a 2-D navigation goal (rviz): its x, y at `goal_height_m`. False (with a reason) when
/// its header names a frame other than `frame_id` (an empty frame_id in the message is taken as
/// `frame_id`); the values are checked by the FSM (ReplanFsm::setGoals refuses NaN/inf).
bool goalFromMsg(const geometry_msgs::PoseStamped& msg, const std::string& frame_id, double goal_height_m,
                 Eigen::Vector3d* goal, std::string* why);
/// The waypoints of a path, in order. False (with a reason) for another frame or more than
/// kMaxWaypoints poses.
bool goalsFromMsg(const nav_msgs::Path& msg, const std::string& frame_id, std::vector<Eigen::Vector3d>* goals,
                  std::string* why);

PositionCommand toMsg(const Setpoint& setpoint, const ros::Time& stamp, const std::string& frame_id);

/// A LINE_STRIP of the spline sampled every dt_s.
visualization_msgs::Marker lineStrip(const UniformBspline& spline, double dt_s, const std::string& frame_id,
                                     const std::string& ns, int id, double width_m, float r, float g, float b,
                                     float a = 1.0f);

}  // namespace topo_planner
