#include "plan_manage/traj_server.h"

#include <geometry_msgs/PoseStamped.h>
#include <geometry_msgs/TwistStamped.h>

#include <cmath>

#include "plan_manage/trajectory_conversions.h"
#include "uav_sim/ros/param_reader.h"

namespace topo_planner {

TrajServer::TrajServer(const ros::NodeHandle& nh, const Config& config)
    : nh_(nh), config_(config), generator_(config.generator) {
  bspline_sub_ = nh_.subscribe("bspline", 10, &TrajServer::bsplineCallback, this, ros::TransportHints().tcpNoDelay());
  odom_sub_ = nh_.subscribe("odometry", 1, &TrajServer::odomCallback, this);
  cmd_pub_ = nh_.advertise<PositionCommand>("position_cmd", 10);
  pose_pub_ = nh_.advertise<geometry_msgs::PoseStamped>("setpoint_pose", 10);
  twist_pub_ = nh_.advertise<geometry_msgs::TwistStamped>("setpoint_twist", 10);
  timer_ = nh_.createTimer(ros::Duration(1.0 / config_.rate_hz), &TrajServer::timerCallback, this);
}

void TrajServer::bsplineCallback(const BsplineConstPtr& msg) {
  UniformBspline spline;
  double start = 0.0;
  std::string why;
  if (!msg->header.frame_id.empty() && msg->header.frame_id != config_.frame_id) {
    ROS_WARN_THROTTLE(1.0, "traj_server: B-spline in frame '%s' ignored (expected '%s')", msg->header.frame_id.c_str(),
                      config_.frame_id.c_str());
    return;
  }
  if (!fromMsg(*msg, &spline, &start, &why)) {
    ROS_WARN_THROTTLE(1.0, "traj_server: invalid B-spline %ld ignored: %s", long(msg->trajectory_id), why.c_str());
    return;
  }
  std::lock_guard<std::mutex> lock(mutex_);
  if (!generator_.add(msg->trajectory_id, start, spline))
    ROS_WARN_THROTTLE(1.0, "traj_server: B-spline %ld ignored (not newer than the last one)", long(msg->trajectory_id));
}

void TrajServer::odomCallback(const nav_msgs::OdometryConstPtr& msg) {
  std::lock_guard<std::mutex> lock(mutex_);
  if (have_yaw_) return;
  const auto& q = msg->pose.pose.orientation;
  const double yaw = std::atan2(2.0 * (q.w * q.z + q.x * q.y), 1.0 - 2.0 * (q.y * q.y + q.z * q.z));
  if (!std::isfinite(yaw)) return;
  generator_.setYaw(yaw);
  have_yaw_ = true;
  odom_sub_.shutdown();
}

void TrajServer::timerCallback(const ros::TimerEvent&) {
  const ros::Time now = ros::Time::now();
  Setpoint sp;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    if (!generator_.sample(now.toSec(), &sp)) return;
  }
  cmd_pub_.publish(toMsg(sp, now, config_.frame_id));
  geometry_msgs::PoseStamped pose;
  pose.header.stamp = now;
  pose.header.frame_id = config_.frame_id;
  pose.pose.position.x = sp.state.position.x();
  pose.pose.position.y = sp.state.position.y();
  pose.pose.position.z = sp.state.position.z();
  pose.pose.orientation.z = std::sin(0.5 * sp.yaw);
  pose.pose.orientation.w = std::cos(0.5 * sp.yaw);
  pose_pub_.publish(pose);
  geometry_msgs::TwistStamped twist;
  twist.header = pose.header;
  twist.twist.linear.x = sp.state.velocity.x();
  twist.twist.linear.y = sp.state.velocity.y();
  twist.twist.linear.z = sp.state.velocity.z();
  twist.twist.angular.z = sp.yaw_rate;
  twist_pub_.publish(twist);
}

bool readTrajServerParams(const ros::NodeHandle& nh, TrajServer::Config* config) {
  TrajServer::Config& c = *config;
  ParamReader r(nh);
  r.read("frame_id", c.frame_id);
  r.read("rate_hz", c.rate_hz);
  r.read("max_yaw_rate_radps", c.generator.max_yaw_rate_radps);
  r.read("yaw_lookahead_s", c.generator.lookahead_s);
  r.read("yaw_min_displacement_m", c.generator.min_displacement_m);
  std::string why, range;
  if (!(c.rate_hz > 0.0 && c.rate_hz <= 1000.0)) range += "rate_hz must be in (0, 1000]; ";
  if (!c.generator.validate(&why)) range += why + "; ";
  return r.finish("traj_server", range);
}

}  // namespace topo_planner
