#include "topo_planner/plan_manage/planner_server.h"

#include <std_msgs/Header.h>

#include <visualization_msgs/MarkerArray.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <random>

#include "topo_planner/plan_manage/trajectory_conversions.h"
#include "topo_planner/topo_replan/plan_problem_io.h"
#include "topo_planner/Bspline.h"
#include "topo_planner/PlannerHeartbeat.h"
#include "topo_planner/ReplanEvent.h"
#include "topo_planner/uav_sim/ros/param_reader.h"

namespace topo_planner {

std::unique_ptr<PlannerServer> PlannerServer::create(const ros::NodeHandle& nh, const Config& config,
                                                     std::string* error) {
  std::unique_ptr<PlannerServer> server(new PlannerServer(nh, config));
  server->fsm_ = ReplanFsm::create(config.fsm, error);
  if (!server->fsm_) return nullptr;
  if (!config.node.dump_failed_plans_dir.empty()) {
    // Diagnostics: each failed replanning problem saved for replay_plan (planning thread only).
    const std::string dir = config.node.dump_failed_plans_dir;
    std::error_code ec;
    std::filesystem::create_directories(dir, ec);
    if (ec) {
      if (error) *error = "debug/dump_failed_plans_dir: cannot create '" + dir + "': " + ec.message();
      return nullptr;
    }
    PlannerServer* s = server.get();
    const int max_dumps = config.node.max_failed_plan_dumps;
    server->fsm_->setPlanObserver([s, dir, max_dumps](const EsdfMap& map, const ReplanRequest& request,
                                                      const ReplanResult& result) {
      if (result.status == ReplanStatus::kSuccess || s->failed_plan_dumps_ >= max_dumps) return;
      char name[32];
      std::snprintf(name, sizeof(name), "/plan_%05d", s->failed_plan_dumps_++);
      std::string why;
      if (savePlanProblem(dir + name, map, request, result.message, &why))
        ROS_INFO_THROTTLE(5.0, "planner: failed plan saved as %s%s.problem (replay_plan)", dir.c_str(), name);
      else
        ROS_WARN_THROTTLE(5.0, "planner: could not save a failed plan: %s", why.c_str());
    });
  }
  // The mapping in ~mapping, on its own queue.
  ros::NodeHandle mapping_nh(nh, "mapping");
  mapping_nh.setCallbackQueue(&server->mapping_queue_);
  server->mapping_ = MappingServer::create(mapping_nh, config.mapping, error);
  if (!server->mapping_) return nullptr;

  PlannerServer& s = *server;
  ros::NodeHandle pnh = s.nh_;
  std::random_device entropy;
  s.session_ = (uint64_t(entropy()) << 32) ^ uint64_t(entropy()) ^ uint64_t(ros::WallTime::now().toNSec());
  s.heartbeat_pub_ = pnh.advertise<PlannerHeartbeat>("heartbeat", 10);
  s.tick_done_pub_ = pnh.advertise<std_msgs::Header>("tick_done", 10);
  s.bspline_pub_ = pnh.advertise<Bspline>("bspline", 10);
  s.event_pub_ = pnh.advertise<ReplanEvent>("replan_event", 100);
  s.reference_pub_ = pnh.advertise<nav_msgs::Path>("reference_path", 1, true);
  s.route_pub_ = pnh.advertise<nav_msgs::Path>("global_route", 1, true);
  s.traj_vis_pub_ = pnh.advertise<visualization_msgs::MarkerArray>("vis/trajectory", 5);
  s.candidates_vis_pub_ = pnh.advertise<visualization_msgs::MarkerArray>("vis/candidates", 5);
  s.guides_vis_pub_ = pnh.advertise<visualization_msgs::MarkerArray>("vis/guide_paths", 5);
  s.roadmap_vis_pub_ = pnh.advertise<visualization_msgs::MarkerArray>("vis/roadmap", 5);
  s.odom_sub_ = pnh.subscribe("odometry", 10, &PlannerServer::odomCallback, &s, ros::TransportHints().tcpNoDelay());
  s.goal_sub_ = pnh.subscribe("goal", 1, &PlannerServer::goalCallback, &s);
  s.position_cmd_sub_ = pnh.subscribe("position_cmd", 10, &PlannerServer::positionCmdCallback, &s,
                                      ros::TransportHints().tcpNoDelay());
  s.waypoints_sub_ = pnh.subscribe("waypoints", 1, &PlannerServer::waypointsCallback, &s);

  ros::NodeHandle plan_nh(pnh), safety_nh(pnh);
  plan_nh.setCallbackQueue(&s.planning_queue_);
  safety_nh.setCallbackQueue(&s.safety_queue_);
  s.plan_timer_ = plan_nh.createTimer(ros::Duration(config.node.plan_period_s), &PlannerServer::planTimer, &s);
  s.safety_timer_ = safety_nh.createTimer(ros::Duration(config.node.safety_period_s), &PlannerServer::safetyTimer, &s);
  s.diagnostics_.reset(new diagnostic_updater::Updater(ros::NodeHandle(), pnh));
  s.diagnostics_->setHardwareID("topo_planner");
  s.diagnostics_->add("planner", [&s](diagnostic_updater::DiagnosticStatusWrapper& status) {
    const double now = ros::Time::now().toSec();
    const InputHealth inputs = s.fsm_->inputHealth(now);
    PlannerHealth::Inputs in;
    in.state = toString(s.fsm_->state());
    in.have_odometry = s.fsm_->state() != FsmState::kInit;
    in.inputs_ok = inputs.ok;
    in.inputs_why = inputs.why;
    in.odom_age_s = inputs.odom_age_s;
    in.depth_age_s = inputs.depth_age_s;
    healthToStatus(s.health_.report(now, in), &status);
  });
  s.diagnostics_->add("mapping", [&s](diagnostic_updater::DiagnosticStatusWrapper& status) {
    healthToStatus(s.mapping_->health(ros::Time::now().toSec()), &status);
  });
  // Flight limits and clearances at run time, starting from the loaded values (main thread).
  s.requested_ = config.fsm;
  s.reconfigure_.reset(new dynamic_reconfigure::Server<PlannerConfig>(s.reconfigure_mutex_, ros::NodeHandle(pnh, "limits")));
  s.reconfigure_->updateConfig(limitsOf(config.fsm));
  s.reconfigure_->setCallback([&s](PlannerConfig& limits, uint32_t level) { s.reconfigureCallback(limits, level); });
  s.mapping_spinner_.reset(new ros::AsyncSpinner(2, &s.mapping_queue_));
  s.planning_spinner_.reset(new ros::AsyncSpinner(1, &s.planning_queue_));
  s.safety_spinner_.reset(new ros::AsyncSpinner(1, &s.safety_queue_));
  s.mapping_spinner_->start();
  s.planning_spinner_->start();
  s.safety_spinner_->start();
  return server;
}

PlannerServer::PlannerServer(const ros::NodeHandle& nh, const Config& config) : nh_(nh), config_(config) {}

PlannerServer::~PlannerServer() {
  // Stop the timers' threads before the FSM and the maps they use go away.
  for (auto* spinner : {&planning_spinner_, &safety_spinner_, &mapping_spinner_})
    if (*spinner) (*spinner)->stop();
  plan_timer_.stop();
  safety_timer_.stop();
}

void PlannerServer::odomCallback(const nav_msgs::OdometryConstPtr& msg) {
  const std::string& frame = msg->header.frame_id;
  if (!frame.empty() && frame != config_.node.frame_id && frame != "/" + config_.node.frame_id) {
    ROS_WARN_THROTTLE(2.0, "planner: odometry in frame '%s' ignored (expected '%s')", frame.c_str(),
                      config_.node.frame_id.c_str());
    return;
  }
  const auto& p = msg->pose.pose.position;
  const auto& q = msg->pose.pose.orientation;
  const auto& v = msg->twist.twist.linear;
  Eigen::Vector3d velocity(v.x, v.y, v.z);
  const Eigen::Quaterniond orientation(q.w, q.x, q.y, q.z);
  if (!config_.node.odom_twist_in_world) {
    const double n = orientation.norm();
    if (!std::isfinite(n) || std::abs(n - 1.0) > 1e-2) {
      ROS_WARN_THROTTLE(2.0, "planner: odometry with a non-unit orientation ignored");
      return;
    }
    velocity = orientation.normalized() * velocity;
  }
  const double t = msg->header.stamp.toSec();
  if (ros::Time::now().isZero()) return;  // simulated time before the first /clock: no clock yet
  std::string why;
  if (!fsm_->setOdometry(t, Eigen::Vector3d(p.x, p.y, p.z), velocity, ros::Time::now().toSec(), &why))
    ROS_WARN_THROTTLE(2.0, "planner: odometry ignored: %s", why.c_str());
}

void PlannerServer::positionCmdCallback(const PositionCommandConstPtr& msg) {
  // The trajectory server's setpoint: whether it follows this planner's trajectory (ReplanFsm).
  if (!msg->header.frame_id.empty() && msg->header.frame_id != config_.node.frame_id) {
    ROS_WARN_THROTTLE(5.0, "planner: position command in frame '%s' ignored (expected '%s')",
                      msg->header.frame_id.c_str(), config_.node.frame_id.c_str());
    return;
  }
  ServerSetpoint sp;
  sp.stamp_s = msg->header.stamp.toSec();
  sp.arrival_s = ros::Time::now().toSec();
  sp.position = Eigen::Vector3d(msg->position.x, msg->position.y, msg->position.z);
  sp.velocity = Eigen::Vector3d(msg->velocity.x, msg->velocity.y, msg->velocity.z);
  switch (msg->mode) {
    case PositionCommand::MODE_HOLD_BEFORE_FIRST: sp.mode = ServerSetpoint::Mode::kBeforeFirst; break;
    case PositionCommand::MODE_TRAJECTORY: sp.mode = ServerSetpoint::Mode::kTrajectory; break;
    case PositionCommand::MODE_END_STOP:
    case PositionCommand::MODE_WATCHDOG_STOP: sp.mode = ServerSetpoint::Mode::kStopping; break;
    case PositionCommand::MODE_HOLD: sp.mode = ServerSetpoint::Mode::kHold; break;
    default:
      ROS_WARN_THROTTLE(5.0, "planner: position command with an unknown mode %u ignored", unsigned(msg->mode));
      return;
  }
  sp.own_session = msg->planner_session == session_;
  sp.trajectory_id = msg->trajectory_id;
  if (!fsm_->setServerSetpoint(sp))
    ROS_WARN_THROTTLE(5.0, "planner: position command ignored (non-finite, out of order, or stamped %.3f s ahead of "
                      "the clock)",
                      sp.stamp_s - sp.arrival_s);
}

void PlannerServer::goalCallback(const geometry_msgs::PoseStampedConstPtr& msg) {
  Eigen::Vector3d goal;
  std::string why;
  if (!goalFromMsg(*msg, config_.node.frame_id, config_.node.goal_height_m, &goal, &why)) {
    ROS_WARN_THROTTLE(1.0, "planner: 2D Nav Goal ignored: %s", why.c_str());
    return;
  }
  submitGoals({goal}, "2D Nav Goal");
}

void PlannerServer::waypointsCallback(const nav_msgs::PathConstPtr& msg) {
  std::vector<Eigen::Vector3d> goals;
  std::string why;
  if (!goalsFromMsg(*msg, config_.node.frame_id, &goals, &why)) {
    ROS_WARN_THROTTLE(1.0, "planner: waypoints ignored: %s", why.c_str());
    return;
  }
  submitGoals(goals, "waypoints");
}

void PlannerServer::submitGoals(const std::vector<Eigen::Vector3d>& goals, const char* source) {
  // Checked against the map at once (the tick's lock order: the map's, then the FSM's): goals in
  // an obstacle or outside the map change nothing.
  GoalStatus status = GoalStatus::kInvalidInput;
  mapping_->readMaps([&](const OccupancyMap&, const EsdfMap& esdf) { status = fsm_->setGoals(goals, esdf); });
  if (status != GoalStatus::kAccepted) {
    ROS_WARN_THROTTLE(1.0, "planner: %s refused: %s", source, toString(status));
    return;
  }
  const Eigen::Vector3d& g = goals.back();
  ROS_INFO("planner: %s: %zu goal(s), last (%.2f, %.2f, %.2f)", source, goals.size(), g.x(), g.y(), g.z());
}

void PlannerServer::feedDepth() {
  const MappingServer::Stats stats = mapping_->stats();
  if (stats.depth_stamp_s >= 0.0) fsm_->setDepthFused(stats.depth_stamp_s, stats.depth_arrival_s);
}

void PlannerServer::publishHeartbeat(double now) {
  const InputHealth health = fsm_->inputHealth(now);
  PlannerHeartbeat hb;
  hb.header.stamp = ros::Time::now();
  hb.header.frame_id = config_.node.frame_id;
  hb.planner_session = session_;
  hb.fsm_state = toString(fsm_->state());
  hb.inputs_ok = health.ok;
  hb.inputs_status = health.why;
  hb.depth_age_s = health.depth_age_s;
  hb.odom_age_s = health.odom_age_s;
  heartbeat_pub_.publish(hb);
  if (!health.ok && fsm_->state() != FsmState::kInit)
    ROS_WARN_THROTTLE(2.0, "planner: inputs stale: %s (goals refused, no planning, a moving vehicle stops)",
                      health.why.c_str());
}

void PlannerServer::planTimer(const ros::TimerEvent&) {
  if (ros::Time::now().isZero()) return;  // simulated time before the first /clock
  const double now = ros::Time::now().toSec();
  feedDepth();
  // The mission of the parameter goals_m, once the inputs allow it.
  if (!config_.node.goals.empty() && !initial_goals_sent_ && fsm_->inputHealth(now).ok &&
      fsm_->setGoals(config_.node.goals) == GoalStatus::kAccepted) {
    initial_goals_sent_ = true;
    ROS_INFO("planner: parameter goals_m: %zu goal(s)", config_.node.goals.size());
  }
  FsmOutput out;
  mapping_->readMaps([&](const OccupancyMap&, const EsdfMap& esdf) {
    out = fsm_->tick(now, esdf, [] { return ros::Time::now().toSec(); });
  });
  handle(out);
  // The tick of `now` is done (its plan published): the simulator's planner lockstep holds its
  // clock within a lag of this, so a slow plan does not come late in simulated time.
  std_msgs::Header done;
  done.stamp = ros::Time(now);
  tick_done_pub_.publish(done);
}

void PlannerServer::safetyTimer(const ros::TimerEvent&) {
  if (ros::Time::now().isZero()) return;  // simulated time before the first /clock
  const double now = ros::Time::now().toSec();
  feedDepth();
  FsmOutput out;
  mapping_->readMaps([&](const OccupancyMap&, const EsdfMap& esdf) { out = fsm_->checkSafety(now, esdf); });
  handle(out);
  // While the trajectory server does not follow this planner's trajectory, no heartbeat: its watchdog
  // stops the vehicle along its path (what it flies is no longer checked here), then the FSM plans
  // from its hold.
  if (!out.server_diverged) publishHeartbeat(now);
  diagnostics_->update();  // publishes at its own period
  const int jumps = fsm_->timeJumps();
  if (jumps != time_jumps_logged_) {
    ROS_WARN("planner: ROS time jumped (%d so far): timing shifted, replanning from the current state", jumps);
    time_jumps_logged_ = jumps;
  }
}


PlannerConfig PlannerServer::limitsOf(const ReplanFsm::Config& f) {
  PlannerConfig c;
  c.max_vel_mps = f.replanner.optimizer.max_vel_mps;
  c.max_acc_mps2 = f.replanner.optimizer.max_acc_mps2;
  c.brake_acc_mps2 = f.brake_acc_mps2;
  c.safety_clearance_m = f.safety_clearance_m;
  c.search_clearance_m = f.replanner.search.clearance_m;
  c.optimizer_clearance_m = f.replanner.optimizer.clearance_m;
  return c;
}

void PlannerServer::reconfigureCallback(PlannerConfig& limits, uint32_t) {
  ReplanFsm::Config next = requested_;
  TopoReplanner::Config& p = next.replanner;
  setFlightLimits(limits.max_vel_mps, limits.max_acc_mps2, config_.node.reference_speed_ratio, &next);
  next.brake_acc_mps2 = limits.brake_acc_mps2;
  next.safety_clearance_m = limits.safety_clearance_m;
  if (requested_.route.clearance_m == requested_.replanner.search.clearance_m) next.route.clearance_m = limits.search_clearance_m;
  p.search.clearance_m = p.astar.clearance_m = limits.search_clearance_m;
  p.optimizer.clearance_m = limits.optimizer_clearance_m;
  const PlannerConfig before = limitsOf(requested_), after = limitsOf(next);
  if (before.max_vel_mps == after.max_vel_mps && before.max_acc_mps2 == after.max_acc_mps2 &&
      before.brake_acc_mps2 == after.brake_acc_mps2 && before.safety_clearance_m == after.safety_clearance_m &&
      before.search_clearance_m == after.search_clearance_m && before.optimizer_clearance_m == after.optimizer_clearance_m)
    return;  // nothing changed (the server's first call)
  std::string why;
  if (!fsm_->reconfigure(next, &why)) {
    ROS_WARN("planner: reconfigure refused, the limits in use are kept: %s", why.c_str());
    limits = before;  // what the server reports back
    return;
  }
  requested_ = next;
  ROS_INFO("planner: reconfigured (from the next plan): max_vel %.2f m/s, max_acc %.2f m/s^2, brake %.2f m/s^2, "
           "clearances: safety %.2f m, search %.2f m, optimizer %.2f m",
           after.max_vel_mps, after.max_acc_mps2, after.brake_acc_mps2, after.safety_clearance_m,
           after.search_clearance_m, after.optimizer_clearance_m);
}

void PlannerServer::handle(const FsmOutput& out) {
  if (!out.message.empty()) ROS_INFO("planner: %s", out.message.c_str());
  if (out.new_reference) publishReference();
  if (out.new_route) publishRoute();
  if (out.trajectory) bspline_pub_.publish(toMsg(*out.trajectory, config_.node.frame_id, session_));
  if (out.event) {
    const FsmEvent& e = *out.event;
    const double now = ros::Time::now().toSec();
    if (e.trigger == FsmEvent::Trigger::kEmergency) health_.addEmergencyStop(now);
    else health_.addPlanningCall(now, e.published, e.stats.total_ms);
    if (e.fallback == "give_up") health_.addGiveUp(now, e.message);
    ReplanEvent msg;
    msg.header.stamp = ros::Time::now();
    msg.header.frame_id = config_.node.frame_id;
    msg.trajectory_id = out.trajectory ? out.trajectory->id : -1;
    msg.fsm_state = toString(e.state);
    msg.trigger = toString(e.trigger);
    msg.status = toString(e.status);
    msg.fallback = e.fallback;
    msg.message = e.message;
    msg.position.x = e.position.x(), msg.position.y = e.position.y(), msg.position.z = e.position.z();
    msg.total_ms = e.stats.total_ms;
    msg.search_ms = e.stats.search_ms;
    msg.optimize_ms = e.stats.optimize_ms;
    msg.guide_paths = e.stats.paths;
    msg.feasible_candidates = e.stats.feasible_candidates;
    event_pub_.publish(msg);
    if (!e.published && e.status == ReplanStatus::kSuccess)
      ROS_WARN_THROTTLE(1.0, "planner: %s plan discarded (%s): %s", toString(e.trigger), e.fallback.c_str(),
                        e.fallback == "discarded_late" ? "it finished after its takeover time"
                                                       : "a braking trajectory took over while planning");
    else if (e.fallback == "give_up")
      ROS_ERROR("planner: %s", e.message.c_str());
    else if (!e.published)
      ROS_WARN_THROTTLE(1.0, "planner: %s plan failed: %s (%s); fallback %s", toString(e.trigger), toString(e.status),
                        e.message.c_str(), e.fallback.c_str());
    else if (e.trigger == FsmEvent::Trigger::kEmergency)
      ROS_WARN("planner: EMERGENCY STOP: %s", e.message.c_str());
  }
  if (out.plan) publishPlanMarkers(*out.plan, out.trajectory ? &*out.trajectory : nullptr);
  else if (out.trajectory) publishPlanMarkers(ReplanResult(), &*out.trajectory);
  if (out.goal_reached) ROS_INFO("planner: goal reached");
  if (out.odometry_jumped && config_.node.clear_map_on_odom_jump) mapping_->clearMap("the odometry jumped");
}

void PlannerServer::publishRoute() {
  nav_msgs::Path path;
  path.header.stamp = ros::Time::now();
  path.header.frame_id = config_.node.frame_id;
  for (const Eigen::Vector3d& p : fsm_->route()) {
    geometry_msgs::PoseStamped pose;
    pose.header = path.header;
    pose.pose.position.x = p.x(), pose.pose.position.y = p.y(), pose.pose.position.z = p.z();
    pose.pose.orientation.w = 1.0;
    path.poses.push_back(pose);
  }
  route_pub_.publish(path);
}

void PlannerServer::publishReference() {
  const PolynomialTrajectory ref = fsm_->reference();
  nav_msgs::Path path;
  path.header.stamp = ros::Time::now();
  path.header.frame_id = config_.node.frame_id;
  const double T = ref.duration();
  const int n = int(std::min(20000.0, std::max(2.0, std::ceil(T / config_.node.vis_sample_s) + 1.0)));
  for (int k = 0; k < n; ++k) {
    const Eigen::Vector3d p = ref.position(T * k / (n - 1));
    geometry_msgs::PoseStamped pose;
    pose.header = path.header;
    pose.pose.position.x = p.x(), pose.pose.position.y = p.y(), pose.pose.position.z = p.z();
    pose.pose.orientation.w = 1.0;
    path.poses.push_back(pose);
  }
  reference_pub_.publish(path);
}

void PlannerServer::publishPlanMarkers(const ReplanResult& plan, const ExecTrajectory* chosen) {
  const std::string& f = config_.node.frame_id;
  auto clear = [&](const std::string& ns) {
    visualization_msgs::Marker m;
    m.header.frame_id = f;
    m.ns = ns;
    m.action = visualization_msgs::Marker::DELETEALL;
    return m;
  };
  if (chosen) {
    visualization_msgs::MarkerArray a;
    a.markers.push_back(clear("trajectory"));
    const bool braking = chosen->braking;
    a.markers.push_back(lineStrip(chosen->spline, config_.node.vis_sample_s, f, "trajectory", 0, 0.12, braking ? 1.f : 0.f,
                                  braking ? 0.f : 0.8f, 0.f));
    traj_vis_pub_.publish(a);
  }
  if (plan.candidates.empty()) return;
  visualization_msgs::MarkerArray candidates, guides;
  candidates.markers.push_back(clear("candidates"));
  guides.markers.push_back(clear("guide_paths"));
  for (size_t i = 0; i < plan.candidates.size(); ++i) {
    const ReplanCandidate& c = plan.candidates[i];
    const bool ok = std::isfinite(c.selection_cost);
    candidates.markers.push_back(lineStrip(c.result.spline, config_.node.vis_sample_s, f, "candidates", int(i), 0.05,
                                           ok ? 0.2f : 0.9f, ok ? 0.4f : 0.3f, ok ? 1.0f : 0.3f, 0.8f));
    visualization_msgs::Marker g;
    g.header.frame_id = f;
    g.header.stamp = ros::Time::now();
    g.ns = "guide_paths";
    g.id = int(i);
    g.type = visualization_msgs::Marker::LINE_STRIP;
    g.pose.orientation.w = 1.0;
    g.scale.x = 0.04;
    g.color.r = 1.0f, g.color.g = 0.6f, g.color.b = 0.0f, g.color.a = 0.9f;
    for (const Eigen::Vector3d& p : c.guide) {
      geometry_msgs::Point pt;
      pt.x = p.x(), pt.y = p.y(), pt.z = p.z();
      g.points.push_back(pt);
    }
    guides.markers.push_back(g);
  }
  candidates_vis_pub_.publish(candidates);
  guides_vis_pub_.publish(guides);
  if (plan.roadmap.guards.empty()) return;
  // The topological roadmap (Alg. 1): guards red, connectors blue, edges grey.
  visualization_msgs::MarkerArray roadmap;
  roadmap.markers.push_back(clear("roadmap"));
  auto point = [](const Eigen::Vector3d& p) {
    geometry_msgs::Point pt;
    pt.x = p.x(), pt.y = p.y(), pt.z = p.z();
    return pt;
  };
  auto marker = [&](int id, int type, double scale, float r, float g, float b) {
    visualization_msgs::Marker m;
    m.header.frame_id = f;
    m.header.stamp = ros::Time::now();
    m.ns = "roadmap";
    m.id = id;
    m.type = type;
    m.pose.orientation.w = 1.0;
    m.scale.x = m.scale.y = m.scale.z = scale;
    m.color.r = r, m.color.g = g, m.color.b = b, m.color.a = 0.8f;
    return m;
  };
  visualization_msgs::Marker guards = marker(0, visualization_msgs::Marker::SPHERE_LIST, 0.15, 1.0f, 0.1f, 0.1f);
  for (const Eigen::Vector3d& p : plan.roadmap.guards) guards.points.push_back(point(p));
  visualization_msgs::Marker connectors = marker(1, visualization_msgs::Marker::SPHERE_LIST, 0.1, 0.1f, 0.3f, 1.0f);
  for (const Eigen::Vector3d& p : plan.roadmap.connectors) connectors.points.push_back(point(p));
  visualization_msgs::Marker edges = marker(2, visualization_msgs::Marker::LINE_LIST, 0.02, 0.6f, 0.6f, 0.6f);
  for (const auto& e : plan.roadmap.edges) edges.points.push_back(point(e.first)), edges.points.push_back(point(e.second));
  roadmap.markers.push_back(guards);
  if (!connectors.points.empty()) roadmap.markers.push_back(connectors);
  if (!edges.points.empty()) roadmap.markers.push_back(edges);
  roadmap_vis_pub_.publish(roadmap);
}

bool readPlannerParams(const ros::NodeHandle& nh, PlannerServer::Config* config) {
  PlannerServer::Config& c = *config;
  if (!readMappingParams(ros::NodeHandle(nh, "mapping"), &c.mapping)) return false;
  ParamReader r(nh);
  r.skipNamespace("mapping");
  r.read("frame_id", c.node.frame_id);
  r.read("odom_twist_in_world", c.node.odom_twist_in_world);
  r.read("goal_height_m", c.node.goal_height_m);
  r.read("plan_period_s", c.node.plan_period_s);
  r.read("safety_period_s", c.node.safety_period_s);
  ReplanFsm::Config& f = c.fsm;
  r.read("vis_sample_s", c.node.vis_sample_s);
  r.read("clear_map_on_odom_jump", c.node.clear_map_on_odom_jump);
  r.read("debug/dump_failed_plans_dir", c.node.dump_failed_plans_dir);
  r.read("debug/max_failed_plan_dumps", c.node.max_failed_plan_dumps);
  std::vector<double> goals;
  r.read("goals_m", goals);
  if (goals.size() % 3 != 0) r.errors() << "goals_m must hold x, y, z triples; ";
  for (size_t i = 0; i + 2 < goals.size(); i += 3) c.node.goals.emplace_back(goals[i], goals[i + 1], goals[i + 2]);
  f.sensing_range_m = c.mapping.occupancy.max_ray_length_m;  // unless fsm/sensing_range_m says otherwise
  readFsmParams(r, &f, &c.node.reference_speed_ratio);

  std::string why;
  std::string range;
  if (!c.node.validate(&why)) range += why + "; ";
  if (!f.validate(&why)) range += why + "; ";
  return r.finish("planner", range);
}

}  // namespace topo_planner
