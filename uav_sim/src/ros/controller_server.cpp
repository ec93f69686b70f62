#include "topo_planner/uav_sim/ros/controller_server.h"

#include <topo_planner/RotorCommand.h>

#include <algorithm>
#include <cmath>
#include <sstream>

#include "topo_planner/uav_sim/ros/conversions.h"
#include "topo_planner/uav_sim/ros/param_reader.h"

namespace topo_planner {

bool ControllerServer::Config::validate(std::string* why) const {
  std::ostringstream err;
  std::string core;
  if (!gains.validate(&core)) err << core << "; ";
  if (!vehicle.validate(&core)) err << "vehicle: " << core << "; ";
  if (!(std::isfinite(command_timeout_s) && command_timeout_s > 0.0 && command_timeout_s <= 3600.0))
    err << "command_timeout_s must be in (0, 3600]; ";
  if (!(std::isfinite(max_odom_interval_s) && max_odom_interval_s > 0.0 && max_odom_interval_s <= 3600.0))
    err << "max_odom_interval_s must be in (0, 3600]; ";
  const std::string s = err.str();
  if (why) *why = s.empty() ? "" : s.substr(0, s.size() - 2);
  return s.empty();
}

bool readControllerParams(const ros::NodeHandle& pnh, ControllerServer::Config* config) {
  ControllerServer::Config& c = *config;
  ParamReader r(pnh);
  r.readVector3("position_gain", c.gains.position_gain);
  r.readVector3("velocity_gain", c.gains.velocity_gain);
  r.readVector3("attitude_gain", c.gains.attitude_gain);
  r.readVector3("rate_gain", c.gains.rate_gain);
  r.read("max_tilt_rad", c.gains.max_tilt_rad);
  r.read("min_thrust_ratio", c.gains.min_thrust_ratio);
  r.read("max_thrust_ratio", c.gains.max_thrust_ratio);
  r.read("command_timeout_s", c.command_timeout_s);
  r.read("max_odom_interval_s", c.max_odom_interval_s);
  r.read("odom_twist_in_world", c.odom_twist_in_world);
  readVehicleParams(r, &c.vehicle);
  std::string range;
  c.validate(&range);
  return r.finish("geometric_controller", range);
}

ControllerServer::ControllerServer(const ros::NodeHandle& nh, const Config& config)
    : nh_(nh), config_(config), controller_(config.gains, config.vehicle) {}

std::unique_ptr<ControllerServer> ControllerServer::create(const ros::NodeHandle& nh, const Config& config,
                                                           std::string* error) {
  std::string why;
  if (!config.validate(&why)) {
    if (error) *error = "invalid config: " + why;
    return nullptr;
  }
  std::unique_ptr<ControllerServer> s(new ControllerServer(nh, config));
  s->rotor_pub_ = s->nh_.advertise<topo_planner::RotorCommand>("controller/rotor_command", 10);
  // No delay on the loop: small messages, sent at once. Odometry queue 1: when behind, answer the
  // newest state, not a backlog.
  s->command_sub_ = s->nh_.subscribe("planning/position_cmd", 10, &ControllerServer::commandCallback, s.get(),
                                     ros::TransportHints().tcpNoDelay());
  s->odom_sub_ =
      s->nh_.subscribe("odom", 1, &ControllerServer::odomCallback, s.get(), ros::TransportHints().tcpNoDelay());
  return s;
}

void ControllerServer::commandCallback(const topo_planner::PositionCommandConstPtr& msg) {
  TrackingReference ref;
  if (!trackingReferenceFromMsg(*msg, &ref)) {
    ROS_WARN_THROTTLE(1.0, "geometric_controller: refusing a position command with NaN/inf; keeping the last one");
    return;
  }
  const double offset = (msg->header.stamp - ros::Time::now()).toSec();
  if ((!msg->header.frame_id.empty() && !world_frame_.empty() && msg->header.frame_id != world_frame_) ||
      (!msg->header.stamp.isZero() && std::abs(offset) > kMaxStampOffsetS)) {
    ROS_WARN_THROTTLE(1.0, "geometric_controller: refusing a position command in frame '%s' stamped %.3f s from now; "
                      "keeping the last one", msg->header.frame_id.c_str(), offset);
    return;
  }
  if (holding_) ROS_INFO("geometric_controller: position commands are back");
  holding_ = false;
  reference_ = ref;
  have_reference_ = have_command_ = true;
  command_time_ = ros::Time::now();
  if (commands_++ == 0)
    ROS_INFO("geometric_controller: first position command (%.2f %.2f %.2f)", ref.position.x(), ref.position.y(),
             ref.position.z());
}

void ControllerServer::odomCallback(const nav_msgs::OdometryConstPtr& msg) {
  Quadrotor::State state;
  std::string why;
  if (!odometryToState(*msg, config_.odom_twist_in_world, &state, &why)) {
    ROS_WARN_THROTTLE(1.0, "geometric_controller: refusing odometry: %s", why.c_str());
    return;
  }
  const ros::Time now = ros::Time::now();
  if (msg->header.stamp.isZero() || std::abs((msg->header.stamp - now).toSec()) > kMaxStampOffsetS) {
    ROS_WARN_THROTTLE(1.0, "geometric_controller: refusing odometry stamped %.3f s from now",
                      (msg->header.stamp - now).toSec());
    return;
  }
  if (world_frame_.empty()) world_frame_ = msg->header.frame_id;
  if (!last_odom_stamp_.isZero() && have_command_) {
    const double interval = (msg->header.stamp - last_odom_stamp_).toSec();
    if (interval < 0.0 || interval > config_.max_odom_interval_s) {
      // A ROS time step (or an odometry gap): keep the command's age as it was at the last odometry.
      const double age = std::max(0.0, (last_odom_stamp_ - command_time_).toSec());
      command_time_ = now.toSec() > age ? now - ros::Duration(age) : ros::Time(0, 1);
      ROS_WARN_THROTTLE(1.0, "geometric_controller: odometry stamps moved by %.3f s: a time step or a gap; command "
                        "age kept at %.2f s", interval, age);
    }
  }
  last_odom_stamp_ = msg->header.stamp;
  if (!have_reference_) {  // start: hover where the vehicle is
    reference_ = TrackingReference();
    reference_.position = state.position;
    reference_.yaw = yawOf(state.orientation);
    have_reference_ = true;
    ROS_INFO("geometric_controller: hovering at (%.2f %.2f %.2f) until the first position command", state.position.x(),
             state.position.y(), state.position.z());
  } else if (have_command_ && !holding_ && (now - command_time_).toSec() > config_.command_timeout_s) {
    const double yaw = reference_.yaw;
    reference_ = TrackingReference();
    reference_.position = state.position;
    reference_.yaw = yaw;
    holding_ = true;
    ROS_WARN("geometric_controller: no position command for %.2f s: hovering at (%.2f %.2f %.2f)",
             config_.command_timeout_s, state.position.x(), state.position.y(), state.position.z());
  }
  const GeometricController::Output out = controller_.compute(state, reference_);
  topo_planner::RotorCommand cmd;
  cmd.header.stamp = msg->header.stamp;  // the odometry this command answers (lockstep)
  cmd.header.frame_id = msg->child_frame_id;
  for (int i = 0; i < 4; ++i) cmd.rotor_speed_radps[i] = out.rotor_speed[i];
  cmd.thrust_n = out.thrust;
  cmd.moment_nm.x = out.moment.x();
  cmd.moment_nm.y = out.moment.y();
  cmd.moment_nm.z = out.moment.z();
  cmd.saturated = out.saturated;
  rotor_pub_.publish(cmd);
}

}  // namespace topo_planner
