#include "topo_planner/plan_manage/traj_server.h"

#include <geometry_msgs/PoseStamped.h>
#include <geometry_msgs/TwistStamped.h>

#include <cmath>

#include "topo_planner/plan_manage/setpoint_messages.h"
#include "topo_planner/plan_manage/trajectory_conversions.h"
#include "topo_planner/uav_sim/ros/param_reader.h"

namespace topo_planner {

TrajServer::TrajServer(const ros::NodeHandle& nh, const Config& config)
    : nh_(nh), config_(config), generator_(config.generator) {
  bspline_sub_ = nh_.subscribe("bspline", 10, &TrajServer::bsplineCallback, this, ros::TransportHints().tcpNoDelay());
  heartbeat_sub_ =
      nh_.subscribe("heartbeat", 10, &TrajServer::heartbeatCallback, this, ros::TransportHints().tcpNoDelay());
  odom_sub_ = nh_.subscribe("odometry", 1, &TrajServer::odomCallback, this);
  cmd_pub_ = nh_.advertise<PositionCommand>("position_cmd", 10);
  pose_pub_ = nh_.advertise<geometry_msgs::PoseStamped>("setpoint_pose", 10);
  twist_pub_ = nh_.advertise<geometry_msgs::TwistStamped>("setpoint_twist", 10);
#ifdef TOPO_PLANNER_HAVE_QUADROTOR_MSGS
  quadrotor_pub_ = nh_.advertise<quadrotor_msgs::PositionCommand>("quadrotor_cmd", 10);
#endif
#ifdef TOPO_PLANNER_HAVE_MAVROS_MSGS
  mavros_pub_ = nh_.advertise<mavros_msgs::PositionTarget>("mavros_setpoint", 10);
#endif
  timer_ = nh_.createTimer(ros::Duration(1.0 / config_.rate_hz), &TrajServer::timerCallback, this);
}

void TrajServer::bsplineCallback(const BsplineConstPtr& msg) {
  ReceivedTrajectory r;
  std::string why;
  if (!msg->header.frame_id.empty() && msg->header.frame_id != config_.frame_id) {
    ROS_WARN_THROTTLE(1.0, "traj_server: B-spline in frame '%s' ignored (expected '%s')", msg->header.frame_id.c_str(),
                      config_.frame_id.c_str());
    return;
  }
  if (!fromMsg(*msg, &r, &why)) {
    ROS_WARN_THROTTLE(1.0, "traj_server: invalid B-spline %ld ignored: %s", long(msg->trajectory_id), why.c_str());
    return;
  }
  std::lock_guard<std::mutex> lock(mutex_);
  const int64_t sessions = generator_.stats().session_changes;
  if (!generator_.add(r.planner_session, r.id, r.start_time_s, r.spline, r.heading_target, r.reanchor)) {
    ROS_WARN_THROTTLE(1.0, "traj_server: B-spline %ld of planner session %lu ignored (not newer than the last one)",
                      long(r.id), (unsigned long)r.planner_session);
  } else if (generator_.stats().session_changes > sessions) {
    ROS_WARN("traj_server: trajectory %ld from a new planner session %lu (planner restarted): accepted", long(r.id),
             (unsigned long)r.planner_session);
  }
}

void TrajServer::heartbeatCallback(const PlannerHeartbeatConstPtr& msg) {
  // Liveness is the arrival (ROS time now, the time base of the samples), not the sender's stamp;
  // but a heartbeat in another frame or stamped further than the watchdog's timeout from now is no
  // planner's of this clock (a stale or forged one must not keep the watchdog from stopping).
  const double now = ros::Time::now().toSec();
  const double lag = now - msg->header.stamp.toSec();
  if ((!msg->header.frame_id.empty() && msg->header.frame_id != config_.frame_id) || !std::isfinite(lag) ||
      std::abs(lag) > config_.generator.heartbeat_timeout_s) {
    ROS_WARN_THROTTLE(5.0, "traj_server: heartbeat ignored (frame '%s', stamped %.3f s from now)",
                      msg->header.frame_id.c_str(), lag);
    return;
  }
  std::lock_guard<std::mutex> lock(mutex_);
  generator_.noteHeartbeat(now);
  if (have_heartbeat_ && msg->planner_session != heartbeat_session_)
    ROS_INFO_THROTTLE(1.0, "traj_server: planner heartbeat from a new session %lu (planner restarted)",
                      (unsigned long)msg->planner_session);
  heartbeat_session_ = msg->planner_session;
  have_heartbeat_ = true;
}

void TrajServer::odomCallback(const nav_msgs::OdometryConstPtr& msg) {
  if (!msg->header.frame_id.empty() && msg->header.frame_id != config_.frame_id) {
    ROS_WARN_THROTTLE(5.0, "traj_server: odometry in frame '%s' ignored (expected '%s')", msg->header.frame_id.c_str(),
                      config_.frame_id.c_str());
    return;
  }
  const auto& q = msg->pose.pose.orientation;
  const auto& p = msg->pose.pose.position;
  const double yaw = std::atan2(2.0 * (q.w * q.z + q.x * q.y), 1.0 - 2.0 * (q.y * q.y + q.z * q.z));
  const Eigen::Vector3d position(p.x, p.y, p.z);
  if (!std::isfinite(yaw) || !position.allFinite()) return;
  std::lock_guard<std::mutex> lock(mutex_);
  // Needed until the first trajectory starts (initial yaw, hold pose); not afterwards.
  if (generator_.started()) {
    odom_sub_.shutdown();
    return;
  }
  generator_.setVehiclePose(position, yaw);
}

void TrajServer::logEvents(const SetpointGenerator::Stats& before, const SetpointGenerator::Stats& after,
                           const Setpoint& sp) const {
  const auto& g = config_.generator;
  if (after.backward_time_jumps + after.forward_time_jumps > before.backward_time_jumps + before.forward_time_jumps)
    ROS_WARN_THROTTLE(1.0,
                      "traj_server: ROS time jumped %s by %.3f s: trajectories shifted so the setpoint goes on where "
                      "it was (%ld backward, %ld forward jumps so far)",
                      after.backward_time_jumps > before.backward_time_jumps ? "backwards" : "forwards",
                      std::abs(after.last_time_jump_s), long(after.backward_time_jumps), long(after.forward_time_jumps));
  if (after.watchdog_stops > before.watchdog_stops)
    ROS_WARN_THROTTLE(1.0,
                      "traj_server: watchdog: no planner heartbeat or trajectory for %.2f s (limit %.2f s) while "
                      "moving at %.2f m/s: stopping along trajectory %ld's path at %.1f m/s^2, then holding "
                      "(%ld queued dropped)",
                      after.last_input_age_s, g.heartbeat_timeout_s, after.last_stop_speed_mps, long(sp.trajectory_id),
                      g.stop_acc_mps2, long(after.dropped_on_watchdog - before.dropped_on_watchdog));
  if (after.discontinuous_refused > before.discontinuous_refused)
    ROS_WARN_THROTTLE(1.0,
                      "traj_server: trajectory %ld refused at its take-over: it starts %.2f m and %.2f m/s from "
                      "the commanded state (limits %.2f m, %.2f m/s); a moving vehicle stops along its current "
                      "path, and the planner replans from the hold (%ld refused so far)",
                      long(after.last_refused_id), after.last_takeover_gap_m, after.last_takeover_velocity_gap_mps,
                      g.max_takeover_gap_m, g.max_takeover_velocity_gap_mps, long(after.discontinuous_refused));
  if (after.end_stops > before.end_stops)
    ROS_WARN_THROTTLE(1.0,
                      "traj_server: trajectory %ld ended moving at %.2f m/s with no successor: stopping straight on at "
                      "%.1f m/s^2, then holding",
                      long(sp.trajectory_id), after.last_stop_speed_mps, g.stop_acc_mps2);
}

void TrajServer::timerCallback(const ros::TimerEvent&) {
  const ros::Time now = ros::Time::now();
  Setpoint sp;
  SetpointGenerator::Stats before, after;
  bool ok = false;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    before = generator_.stats();
    ok = generator_.sample(now.toSec(), &sp);
    after = generator_.stats();
  }
  logEvents(before, after, sp);
  if (!ok) return;
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
#ifdef TOPO_PLANNER_HAVE_QUADROTOR_MSGS
  quadrotor_pub_.publish(toQuadrotorCommand(sp, now, config_.frame_id));
#endif
#ifdef TOPO_PLANNER_HAVE_MAVROS_MSGS
  mavros_pub_.publish(toPositionTarget(sp, now, config_.frame_id));
#endif
}

bool readTrajServerParams(const ros::NodeHandle& nh, TrajServer::Config* config) {
  TrajServer::Config& c = *config;
  SetpointGenerator::Config& g = c.generator;
  ParamReader r(nh);
  r.read("frame_id", c.frame_id);
  r.read("rate_hz", c.rate_hz);
  r.read("max_yaw_rate_radps", g.max_yaw_rate_radps);
  r.read("yaw_lookahead_s", g.lookahead_s);
  r.read("yaw_min_displacement_m", g.min_displacement_m);
  r.read("heartbeat_timeout_s", g.heartbeat_timeout_s);
  r.read("stop_acc_mps2", g.stop_acc_mps2);
  r.read("stop_jerk_mps3", g.stop_jerk_mps3);
  r.read("max_time_step_s", g.max_time_step_s);
  r.read("hold_before_first_trajectory", g.hold_before_first_trajectory);
  r.read("max_takeover_gap_m", g.max_takeover_gap_m);
  r.read("max_takeover_velocity_gap_mps", g.max_takeover_velocity_gap_mps);
  std::string why, range;
  if (c.frame_id.empty()) range += "frame_id must not be empty; ";
  if (!(c.rate_hz > 0.0 && c.rate_hz <= 1000.0)) {
    range += "rate_hz must be in (0, 1000]; ";
  } else {
    g.nominal_period_s = 1.0 / c.rate_hz;
    if (!g.validate(&why)) range += why + "; ";
  }
  if (!range.empty()) range.resize(range.size() - 2);
  return r.finish("traj_server", range);
}

}  // namespace topo_planner
