#pragma once
// Conversions between the planner's core types and the closed loop's messages, in one place for the
// planner node and the trajectory server.

#include <ros/time.h>
#include <visualization_msgs/Marker.h>

#include <string>

#include "topo_planner/Bspline.h"
#include "topo_planner/PositionCommand.h"
#include "topo_replan/replan_fsm.h"
#include "topo_replan/setpoint_generator.h"

namespace topo_planner {

/// The message of a trajectory whose start_time_s is in ROS time seconds.
Bspline toMsg(const ExecTrajectory& trajectory, const std::string& frame_id);
/// The spline and start time of a message; false (with a reason) for an invalid one (too few or
/// non-finite control points, bad degree or knot span).
bool fromMsg(const Bspline& msg, UniformBspline* spline, double* start_time_s, std::string* why);

PositionCommand toMsg(const Setpoint& setpoint, const ros::Time& stamp, const std::string& frame_id);

/// A LINE_STRIP of the spline sampled every dt_s.
visualization_msgs::Marker lineStrip(const UniformBspline& spline, double dt_s, const std::string& frame_id,
                                     const std::string& ns, int id, double width_m, float r, float g, float b,
                                     float a = 1.0f);

}  // namespace topo_planner
