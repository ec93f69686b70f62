#include "topo_planner/plan_manage/trajectory_conversions.h"

#include <algorithm>
#include <cmath>

namespace topo_planner {

Bspline toMsg(const ExecTrajectory& trajectory, const std::string& frame_id, uint64_t planner_session) {
  Bspline msg;
  msg.header.frame_id = frame_id;
  msg.header.stamp = ros::Time(std::max(0.0, trajectory.start_time_s));
  msg.planner_session = planner_session;
  msg.trajectory_id = trajectory.id;
  msg.start_time = msg.header.stamp;
  msg.order = trajectory.spline.degree();
  msg.knot_span_s = trajectory.spline.knotSpan();
  const Eigen::MatrixX3d& q = trajectory.spline.controlPoints();
  msg.control_points.resize(size_t(q.rows()));
  for (int i = 0; i < q.rows(); ++i) {
    msg.control_points[size_t(i)].x = q(i, 0);
    msg.control_points[size_t(i)].y = q(i, 1);
    msg.control_points[size_t(i)].z = q(i, 2);
  }
  msg.has_heading_target = trajectory.has_heading_target;
  if (trajectory.has_heading_target) {
    msg.heading_target.x = trajectory.heading_target.x();
    msg.heading_target.y = trajectory.heading_target.y();
    msg.heading_target.z = trajectory.heading_target.z();
  }
  msg.reanchor = trajectory.reanchor;
  msg.kind = trajectory.braking ? Bspline::KIND_BRAKING : trajectory.escape ? Bspline::KIND_MANOEUVRE : Bspline::KIND_PLAN;
  msg.brake_start = ros::Time(std::max(0.0, std::min(trajectory.brake_start_s, trajectory.endTime())));
  return msg;
}

bool fromMsg(const Bspline& msg, ReceivedTrajectory* out, std::string* why) {
  if (msg.control_points.size() > 100000) {
    if (why) *why = "more than 100000 control points";
    return false;
  }
  Eigen::MatrixX3d q(msg.control_points.size(), 3);
  for (size_t i = 0; i < msg.control_points.size(); ++i)
    q.row(Eigen::Index(i)) << msg.control_points[i].x, msg.control_points[i].y, msg.control_points[i].z;
  UniformBspline s(q, msg.order, msg.knot_span_s);
  if (!s.isValid(why)) return false;
  if (msg.order < 3) {
    if (why) *why = "order below 3 (no continuous acceleration)";
    return false;
  }
  if (!(msg.knot_span_s >= kMinKnotSpanS && msg.knot_span_s <= kMaxKnotSpanS)) {
    if (why) *why = "knot span outside [" + std::to_string(kMinKnotSpanS) + ", " + std::to_string(kMaxKnotSpanS) + "] s";
    return false;
  }
  if (q.cwiseAbs().maxCoeff() > kMaxCoordinateM) {
    if (why) *why = "control points beyond " + std::to_string(kMaxCoordinateM) + " m";
    return false;
  }
  std::optional<Eigen::Vector3d> heading_target;
  if (msg.has_heading_target) {
    heading_target = Eigen::Vector3d(msg.heading_target.x, msg.heading_target.y, msg.heading_target.z);
    if (!heading_target->allFinite()) {
      if (why) *why = "non-finite heading target";
      return false;
    }
  }
  out->planner_session = msg.planner_session;
  out->id = msg.trajectory_id;
  out->start_time_s = msg.start_time.toSec();
  out->spline = s;
  out->heading_target = heading_target;
  out->reanchor = msg.reanchor;
  out->kind = msg.kind <= uint8_t(Bspline::KIND_MANOEUVRE) ? msg.kind : uint8_t(Bspline::KIND_PLAN);
  out->brake_start_s = std::max(out->start_time_s, msg.brake_start.toSec());
  return true;
}

bool goalFromMsg(const geometry_msgs::PoseStamped& msg, const std::string& frame_id, double goal_height_m,
                 Eigen::Vector3d* goal, std::string* why) {
  if (!msg.header.frame_id.empty() && msg.header.frame_id != frame_id) {
    if (why) *why = "goal in frame '" + msg.header.frame_id + "' (expected '" + frame_id + "')";
    return false;
  }
  *goal = Eigen::Vector3d(msg.pose.position.x, msg.pose.position.y, goal_height_m);
  return true;
}

bool goalsFromMsg(const nav_msgs::Path& msg, const std::string& frame_id, std::vector<Eigen::Vector3d>* goals,
                  std::string* why) {
  if (!msg.header.frame_id.empty() && msg.header.frame_id != frame_id) {
    if (why) *why = "waypoints in frame '" + msg.header.frame_id + "' (expected '" + frame_id + "')";
    return false;
  }
  if (msg.poses.size() > kMaxWaypoints) {
    if (why) *why = std::to_string(msg.poses.size()) + " waypoints (at most " + std::to_string(kMaxWaypoints) + ")";
    return false;
  }
  goals->clear();
  for (const auto& pose : msg.poses) goals->emplace_back(pose.pose.position.x, pose.pose.position.y, pose.pose.position.z);
  return true;
}

PositionCommand toMsg(const Setpoint& sp, const ros::Time& stamp, const std::string& frame_id) {
  PositionCommand cmd;
  cmd.header.stamp = stamp;
  cmd.header.frame_id = frame_id;
  cmd.position.x = sp.state.position.x();
  cmd.position.y = sp.state.position.y();
  cmd.position.z = sp.state.position.z();
  auto vec = [](const Eigen::Vector3d& v, geometry_msgs::Vector3* m) { m->x = v.x(), m->y = v.y(), m->z = v.z(); };
  vec(sp.state.velocity, &cmd.velocity);
  vec(sp.state.acceleration, &cmd.acceleration);
  vec(sp.state.jerk, &cmd.jerk);
  cmd.yaw = sp.yaw;
  cmd.yaw_rate = sp.yaw_rate;
  cmd.trajectory_id = sp.trajectory_id;
  cmd.planner_session = sp.planner_session;
  switch (sp.mode) {
    case Setpoint::Mode::kHoldBeforeFirst: cmd.mode = PositionCommand::MODE_HOLD_BEFORE_FIRST; break;
    case Setpoint::Mode::kTrajectory: cmd.mode = PositionCommand::MODE_TRAJECTORY; break;
    case Setpoint::Mode::kEndStop: cmd.mode = PositionCommand::MODE_END_STOP; break;
    case Setpoint::Mode::kWatchdogStop: cmd.mode = PositionCommand::MODE_WATCHDOG_STOP; break;
    case Setpoint::Mode::kHold: cmd.mode = PositionCommand::MODE_HOLD; break;
  }
  return cmd;
}

visualization_msgs::Marker lineStrip(const UniformBspline& spline, double dt_s, const std::string& frame_id,
                                     const std::string& ns, int id, double width_m, float r, float g, float b,
                                     float a) {
  visualization_msgs::Marker m;
  m.header.frame_id = frame_id;
  m.header.stamp = ros::Time::now();
  m.ns = ns;
  m.id = id;
  m.type = visualization_msgs::Marker::LINE_STRIP;
  m.action = visualization_msgs::Marker::ADD;
  m.pose.orientation.w = 1.0;
  m.scale.x = width_m;
  m.color.r = r, m.color.g = g, m.color.b = b, m.color.a = a;
  if (!spline.isValid()) return m;
  const double T = spline.duration();
  // The count capped in doubles: T / dt_s may exceed the int range.
  const int n = int(std::min(5000.0, std::max(2.0, std::ceil(T / dt_s) + 1.0)));
  for (int k = 0; k < n; ++k) {
    const Eigen::Vector3d p = spline.evaluate(T * k / (n - 1));
    geometry_msgs::Point pt;
    pt.x = p.x(), pt.y = p.y(), pt.z = p.z();
    m.points.push_back(pt);
  }
  return m;
}

}  // namespace topo_planner
