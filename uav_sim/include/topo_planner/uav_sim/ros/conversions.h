#pragma once
// Message conversions of the simulator nodes, at the edge between ROS and the ROS-free uav_sim core
// (STYLE.md: one conversions file). Every function checks its input and refuses bad messages with a
// reason instead of guessing; none throws.

#include <nav_msgs/Odometry.h>
#include <ros/time.h>
#include <sensor_msgs/PointCloud2.h>
#include <topo_planner/PositionCommand.h>

#include <Eigen/Geometry>
#include <string>
#include <vector>

#include "topo_planner/uav_sim/geometric_controller.h"
#include "topo_planner/uav_sim/quadrotor.h"

namespace topo_planner {

/// Points of a PointCloud2 with FLOAT32 x, y, z fields (host byte order). NaN points are kept (the
/// consumer counts and skips them). False with a reason for a cloud without those fields or with
/// less data than its header says.
bool cloudToPoints(const sensor_msgs::PointCloud2& msg, std::vector<Eigen::Vector3d>* points, std::string* why);

/// Unorganised FLOAT32 x, y, z cloud (height 1, dense).
void pointsToCloud(const std::vector<Eigen::Vector3d>& points, const std::string& frame_id, const ros::Time& stamp,
                   sensor_msgs::PointCloud2* msg);

/// Odometry -> vehicle state (position, orientation, world-frame velocity, body rates). The twist is
/// in the child (body) frame per nav_msgs, or in the world frame when twist_in_world (some VIOs).
/// False for NaN/inf values or a quaternion far from unit norm (within 1% is normalised).
bool odometryToState(const nav_msgs::Odometry& msg, bool twist_in_world, Quadrotor::State* state, std::string* why);

/// Vehicle state -> odometry: pose in frame_id, twist (linear and angular) in the body frame
/// child_frame_id. Covariances are left zero (unknown).
void stateToOdometry(const Quadrotor::State& state, const ros::Time& stamp, const std::string& frame_id,
                     const std::string& child_frame_id, nav_msgs::Odometry* msg);

/// PositionCommand message -> tracking reference; false when any value is NaN/inf.
bool trackingReferenceFromMsg(const topo_planner::PositionCommand& msg, TrackingReference* ref);

/// Heading of a body orientation: the yaw of its x axis about world z [rad].
double yawOf(const Eigen::Quaterniond& q);

}  // namespace topo_planner
