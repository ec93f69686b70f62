#include "topo_planner/plan_manage/flight_monitor.h"

#include <geometry_msgs/PoseStamped.h>
#include <topo_planner/FlightResult.h>

#include <Eigen/Geometry>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <sstream>

#include "topo_planner/plan_manage/trajectory_conversions.h"
#include "topo_planner/uav_sim/ros/conversions.h"
#include "topo_planner/uav_sim/ros/param_reader.h"

namespace topo_planner {

namespace {

bool finitePositive(double x) { return std::isfinite(x) && x > 0.0; }
bool finiteNonNegative(double x) { return std::isfinite(x) && x >= 0.0; }


// JSON text of a scalar parameter value (strings quoted), or "" for lists and dictionaries.
std::string jsonOfParam(XmlRpc::XmlRpcValue& v) {
  switch (v.getType()) {
    case XmlRpc::XmlRpcValue::TypeBoolean: return bool(v) ? "true" : "false";
    case XmlRpc::XmlRpcValue::TypeInt: return std::to_string(int(v));
    case XmlRpc::XmlRpcValue::TypeDouble: return jsonNumber(double(v));
    case XmlRpc::XmlRpcValue::TypeString: return jsonString(std::string(v));
    default: return "";
  }
}

enum class Level { kInfo, kWarn, kError };

// ROS_INFO/WARN/ERROR, or stderr once ROS has shut down (rosconsole drops messages then, and the
// report of an interrupted flight is written after the spinner stopped).
void log(Level level, const std::string& text) {
  if (!ros::ok() || ros::isShuttingDown()) {
    std::fprintf(stderr, "[%s] flight_monitor: %s\n", level == Level::kInfo ? "INFO" : level == Level::kWarn ? "WARN" : "ERROR",
                 text.c_str());
    return;
  }
  switch (level) {
    case Level::kInfo: ROS_INFO("flight_monitor: %s", text.c_str()); break;
    case Level::kWarn: ROS_WARN("flight_monitor: %s", text.c_str()); break;
    case Level::kError: ROS_ERROR("flight_monitor: %s", text.c_str()); break;
  }
}

geometry_msgs::Point toPoint(const Eigen::Vector3d& p) {
  geometry_msgs::Point m;
  m.x = p.x();
  m.y = p.y();
  m.z = p.z();
  return m;
}

}  // namespace

// ---------------------------------------------------------------------------------------------
// Configuration

bool FlightMonitor::Config::validate(std::string* why) const {
  std::ostringstream err;
  std::string core;
  if (!recorder.validate(&core)) err << core << "; ";
  if (!truth.validate(&core)) err << "truth: " << core << "; ";
  if (!oracle.validate(&core)) err << "oracle: " << core << "; ";
  if (!std::isfinite(ground_z_m)) err << "ground_z_m must be finite; ";
  if (!finitePositive(clearance_exact_within_m)) err << "clearance_exact_within_m must be positive; ";
  for (const Eigen::Vector3d& g : goals)
    if (!g.allFinite()) {
      err << "goals must be finite; ";
      break;
    }
  if (frame_id.empty()) err << "frame_id must not be empty; ";
  // Durations become ros::Duration, which throws beyond 2^31 s: keep them sensible.
  if (!(finiteNonNegative(start_delay_s) && start_delay_s <= 3600.0)) err << "start_delay_s must be in [0, 3600]; ";
  if (!(finitePositive(startup_timeout_s) && startup_timeout_s <= 86400.0))
    err << "startup_timeout_s must be in (0, 86400]; ";
  if (!(finiteNonNegative(resend_period_s) && resend_period_s <= 3600.0)) err << "resend_period_s must be in [0, 3600]; ";
  if (!(finiteNonNegative(resend_settle_s) && resend_settle_s <= 3600.0)) err << "resend_settle_s must be in [0, 3600]; ";
  if (!(finitePositive(check_period_s) && check_period_s <= 10.0)) err << "check_period_s must be in (0, 10]; ";
  if (name.empty() || name.find('/') != std::string::npos) err << "name must be a non-empty file name stem; ";
  const std::string s = err.str();
  if (why) *why = s.empty() ? "" : s.substr(0, s.size() - 2);
  return s.empty();
}

bool readFlightMonitorParams(const ros::NodeHandle& pnh, FlightMonitor::Config* config) {
  FlightMonitor::Config& c = *config;
  SimScenario scenario;
  std::string why;
  if (!readSimScenario(&scenario, &why)) {
    ROS_ERROR("flight_monitor: invalid scenario: %s", why.c_str());
    return false;
  }
  ParamReader r(pnh);
  std::vector<double> goals;
  r.read("goals_m", goals);
  if (!goals.empty()) {
    if (goals.size() % 3 != 0) {
      r.errors() << "goals_m must hold x y z triples (" << goals.size() << " numbers given); ";
    } else {
      scenario.goals_m.clear();
      for (size_t i = 0; i < goals.size(); i += 3) scenario.goals_m.emplace_back(goals[i], goals[i + 1], goals[i + 2]);
    }
  }
  c.goals = scenario.goals_m;
  c.start_m = scenario.start_m;

  FlightRecorder::Config& rc = c.recorder;
  r.read("goal_tolerance_m", rc.goal_tolerance_m);
  r.read("goal_max_speed_mps", rc.goal_max_speed_mps);
  std::string mission = rc.pass_through ? "waypoints" : "sequential";
  r.read("mission", mission);
  if (mission == "waypoints") {
    rc.pass_through = true;
  } else if (mission != "sequential") {
    r.errors() << "mission must be sequential or waypoints, not '" << mission << "'; ";
  }
  r.read("waypoint_tolerance_m", rc.waypoint_tolerance_m);
  r.read("goal_timeout_s", rc.goal_timeout_s);
  r.read("collision_radius_m", rc.collision_radius_m);
  r.read("contact_release_m", rc.contact_release_m);
  double trace_rate_hz = 1.0 / rc.trace_period_s;
  r.read("trace_rate_hz", trace_rate_hz);
  if (!(finitePositive(trace_rate_hz) && trace_rate_hz <= 1e4)) {
    r.errors() << "trace_rate_hz must be in (0, 10000]; ";
  } else {
    rc.trace_period_s = 1.0 / trace_rate_hz;
  }
  r.read("ground_z_m", c.ground_z_m);
  r.read("clearance_exact_within_m", c.clearance_exact_within_m);
  r.read("odom_twist_in_world", c.odom_twist_in_world);
  r.read("frame_id", c.frame_id);
  r.read("start_delay_s", c.start_delay_s);
  r.read("startup_timeout_s", c.startup_timeout_s);
  r.read("resend_period_s", c.resend_period_s);
  r.read("resend_settle_s", c.resend_settle_s);
  r.read("ground_truth_topic", c.ground_truth_topic);
  // The speed account and the oracle: the flight's limits (simulation.launch passes max_vel_mps and
  // max_acc_mps2) and the planner's guide clearance and height band.
  r.read("max_vel_mps", rc.speed.max_vel_mps);
  r.read("max_acc_mps2", rc.speed.max_acc_mps2);
  r.read("speed_account/fast_fraction", rc.speed.fast_fraction);
  r.read("speed_account/limit_fraction", rc.speed.limit_fraction);
  c.oracle.max_vel_mps = rc.speed.max_vel_mps;
  c.oracle.max_acc_mps2 = rc.speed.max_acc_mps2;
  c.oracle.pass_through = rc.pass_through;
  r.read("oracle/clearance_m", c.oracle.clearance_m);
  r.read("oracle/min_z_m", c.oracle.min_z_m);
  r.read("oracle/max_z_m", c.oracle.max_z_m);
  std::vector<double> window;
  r.read("oracle/window_m", window);  // the planner's map window: origin x y z, size x y z
  if (window.size() == 6) {
    c.oracle_window_origin_m = Eigen::Vector3d(window[0], window[1], window[2]);
    c.oracle_window_size_m = Eigen::Vector3d(window[3], window[4], window[5]);
  } else if (!window.empty()) {
    r.errors() << "oracle/window_m must hold 6 numbers (origin x y z, size x y z); ";
  }
  r.read("setpoint_jump_margin_m", rc.setpoints.jump_margin_m);
  r.read("reanchor_tolerance_m", rc.setpoints.reanchor_tolerance_m);
  r.read("reanchor_window_s", rc.setpoints.reanchor_window_s);
  double margin_m = 1.5, max_distance_m = 2.0;
  int num_threads = 1;
  r.read("truth/margin_m", margin_m);
  r.read("truth/max_distance_m", max_distance_m);
  r.read("truth/num_threads", num_threads);
  c.truth = truthMapConfig(scenario, margin_m, max_distance_m);
  c.truth.esdf.num_threads = num_threads;
  r.read("output_dir", c.output_dir);
  r.read("name", c.name);
  r.read("shutdown_when_done", c.shutdown_when_done);

  // The scenario's own figures go into the report verbatim (simulation.launch sets the first three).
  for (const char* key : {"density", "seed", "max_vel_mps"}) {
    XmlRpc::XmlRpcValue value;
    r.read(key, value);
    if (pnh.getParam(key, value)) c.scenario[key] = jsonOfParam(value);
  }
  r.skipNamespace("scenario");
  XmlRpc::XmlRpcValue extra;
  if (pnh.getParam("scenario", extra) && extra.getType() == XmlRpc::XmlRpcValue::TypeStruct) {
    for (auto& [key, value] : extra) {
      const std::string text = jsonOfParam(value);
      if (text.empty()) {
        ROS_WARN("flight_monitor: ignoring scenario/%s (not a scalar)", key.c_str());
      } else {
        c.scenario[key] = text;
      }
    }
  }
  for (auto it = c.scenario.begin(); it != c.scenario.end();)  // lists and dictionaries: not for the report
    it = it->second.empty() ? c.scenario.erase(it) : std::next(it);

  std::string range_errors;
  c.validate(&range_errors);
  if (c.goals.empty()) range_errors += std::string(range_errors.empty() ? "" : "; ") + "no goals";
  return r.finish("flight_monitor", range_errors);
}

// ---------------------------------------------------------------------------------------------
// Construction

FlightMonitor::FlightMonitor(const ros::NodeHandle& nh, const ros::NodeHandle& pnh, const Config& config)
    : nh_(nh),
      pnh_(pnh),
      config_(config),
      recorder_(config.recorder, config.goals),
      clock_(0.5),
      resend_(config.resend_settle_s) {}

std::unique_ptr<FlightMonitor> FlightMonitor::create(const ros::NodeHandle& nh, const ros::NodeHandle& pnh,
                                                     const Config& config, std::string* error) {
  std::string why;
  if (!config.validate(&why)) {
    if (error) *error = "invalid config: " + why;
    return nullptr;
  }
  std::unique_ptr<FlightMonitor> m(new FlightMonitor(nh, pnh, config));
  FlightMonitor* self = m.get();
  m->waypoint_pub_ = m->nh_.advertise<nav_msgs::Path>("planning/waypoints", 1, true);
  m->result_pub_ = m->pnh_.advertise<topo_planner::FlightResult>("result", 1, true);
  m->report_pub_ = m->pnh_.advertise<std_msgs::String>("report", 1, true);
  m->cloud_topic_ = m->nh_.resolveName("map_generator/global_cloud");
  m->truth_sub_ = std::make_unique<TruthMapSubscriber>(
      m->nh_, m->cloud_topic_, config.truth, "flight_monitor",
      [self](const std::shared_ptr<const TruthMap>& map) { self->onTruthMap(map); });
  m->odom_sub_ = m->nh_.subscribe("odom", 50, &FlightMonitor::odomCallback, self, ros::TransportHints().tcpNoDelay());
  m->collision_sub_ = m->nh_.subscribe("quadrotor/collision", 50, &FlightMonitor::collisionCallback, self);
  m->replan_sub_ = m->nh_.subscribe("planning/replan_event", 100, &FlightMonitor::replanCallback, self);
  m->reference_sub_ = m->nh_.subscribe("planning/reference_path", 10, &FlightMonitor::referenceCallback, self);
  m->bspline_sub_ = m->nh_.subscribe("planning/bspline", 20, &FlightMonitor::bsplineCallback, self,
                                     ros::TransportHints().tcpNoDelay());
  if (!config.ground_truth_topic.empty())
    m->truth_state_sub_ = m->nh_.subscribe(config.ground_truth_topic, 400, &FlightMonitor::truthCallback, self,
                                           ros::TransportHints().tcpNoDelay());
  m->setpoint_sub_ = m->nh_.subscribe("planning/position_cmd", 200, &FlightMonitor::setpointCallback, self,
                                      ros::TransportHints().tcpNoDelay());
  m->heartbeat_sub_ = m->nh_.subscribe("planning/heartbeat", 50, &FlightMonitor::heartbeatCallback, self);
  m->fault_sub_ = m->nh_.subscribe("quadrotor_sim/fault_event", 50, &FlightMonitor::faultCallback, self);
  m->offset_sub_ = m->nh_.subscribe("quadrotor_sim/odom_offset", 10, &FlightMonitor::offsetCallback, self,
                                    ros::TransportHints().tcpNoDelay());
  m->check_timer_ = m->nh_.createTimer(ros::Duration(config.check_period_s), &FlightMonitor::checkTimer, self);
  m->startup_timer_ = m->nh_.createSteadyTimer(ros::WallDuration(config.startup_timeout_s),
                                               &FlightMonitor::startupTimeout, self, /*oneshot=*/true);
  ROS_INFO("flight_monitor: %zu goals, waiting for the true map on %s, odometry on %s and a planner on %s",
           config.goals.size(), m->cloud_topic_.c_str(), m->odom_sub_.getTopic().c_str(),
           m->waypoint_pub_.getTopic().c_str());
  return m;
}

// ---------------------------------------------------------------------------------------------
// Callbacks

void FlightMonitor::onTruthMap(const std::shared_ptr<const TruthMap>& map) {
  truth_ = map;
  map_columns_ = occupiedColumns(map->occupancy());
}

void FlightMonitor::odomCallback(const nav_msgs::OdometryConstPtr& msg) {
  if (!msg->header.frame_id.empty() && msg->header.frame_id != config_.frame_id) {
    ROS_WARN_THROTTLE(5.0, "flight_monitor: odometry in frame '%s', expected '%s'; ignored",
                      msg->header.frame_id.c_str(), config_.frame_id.c_str());
    return;
  }
  Quadrotor::State state;
  std::string why;
  if (!odometryToState(*msg, config_.odom_twist_in_world, &state, &why)) {
    ROS_WARN_THROTTLE(5.0, "flight_monitor: odometry ignored: %s", why.c_str());
    return;
  }
  // Without a ground truth the odometry is the stream that shows ROS time steps (its blackouts
  // would too: fault injection needs the ground truth).
  double t;
  if (config_.ground_truth_topic.empty() && !msg->header.stamp.isZero()) {
    t = last_stream_t_s_ = clock_.addStreamStamp(msg->header.stamp.toSec());
    have_stream_time_ = true;
  } else {
    // Beside a ground truth, odometry must be stamped, in order, and not ahead of the truth's time:
    // another stamp is no vehicle's state of this clock.
    t = timeOf(msg->header.stamp);
    if (msg->header.stamp.isZero() || (have_odom_ && t < last_odom_t_s_) || (have_stream_time_ && t > nowS() + 1.0)) {
      ROS_WARN_THROTTLE(5.0, "flight_monitor: odometry stamped %.3f ignored (unstamped, out of order or ahead)",
                        msg->header.stamp.toSec());
      return;
    }
  }
  have_odom_ = true;
  last_odom_t_s_ = t;
  if (!recorder_.started() || done_ || !truth_) return;

  OdometrySample s;
  s.t_s = t;
  s.position_m = state.position;
  s.velocity_mps = state.velocity;
  s.clearance_m = config_.ground_truth_topic.empty() ? clearanceAt(s.position_m) : std::nan("");
  handle(recorder_.addOdometry(s), t);
}

double FlightMonitor::nowS() const {
  // The steady stream's latest time: ros::Time::now() right after a step, before the stream has
  // shown it, would be off by the step.
  return have_stream_time_ ? last_stream_t_s_ : timeOf(ros::Time());
}

double FlightMonitor::timeOf(const ros::Time& stamp) const {
  return clock_.correct((stamp.isZero() ? ros::Time::now() : stamp).toSec());
}

double FlightMonitor::clearanceAt(const Eigen::Vector3d& p) const {
  // The ground is an obstacle too (the simulator counts touching it as a collision).
  return std::min(truth_->obstacleDistance(p, config_.clearance_exact_within_m), p.z() - config_.ground_z_m);
}

void FlightMonitor::truthCallback(const nav_msgs::OdometryConstPtr& msg) {
  Quadrotor::State state;
  std::string why;
  if (msg->header.stamp.isZero() || !odometryToState(*msg, false, &state, &why)) {
    ROS_WARN_THROTTLE(5.0, "flight_monitor: ground truth ignored: %s", why.c_str());
    return;
  }
  const double t = last_stream_t_s_ = clock_.addStreamStamp(msg->header.stamp.toSec());
  have_stream_time_ = true;
  have_truth_position_ = true;
  truth_position_ = state.position;
  if (!recorder_.started() || done_ || !truth_) return;
  OdometrySample s;
  s.t_s = t;
  s.position_m = state.position;
  s.velocity_mps = state.velocity;
  s.clearance_m = clearanceAt(s.position_m);
  recorder_.addTruth(s);
}

void FlightMonitor::bsplineCallback(const topo_planner::BsplineConstPtr& msg) {
  ReceivedTrajectory received;
  std::string why;
  if (!fromMsg(*msg, &received, &why)) {
    ROS_WARN_THROTTLE(5.0, "flight_monitor: trajectory ignored: %s", why.c_str());
    return;
  }
  SpeedAccount::Trajectory t;
  t.session = received.planner_session;
  t.id = received.id;
  t.start_s = timeOf(msg->start_time);
  t.brake_start_s = t.start_s + (received.brake_start_s - received.start_time_s);
  t.kind = received.kind == Bspline::KIND_BRAKING     ? SpeedAccount::TrajectoryKind::kBraking
           : received.kind == Bspline::KIND_MANOEUVRE ? SpeedAccount::TrajectoryKind::kManoeuvre
                                                      : SpeedAccount::TrajectoryKind::kPlan;
  t.spline = received.spline;
  recorder_.addTrajectory(t);
}

void FlightMonitor::setpointCallback(const topo_planner::PositionCommandConstPtr& msg) {
  SetpointSample s;
  s.t_s = timeOf(msg->header.stamp);
  switch (msg->mode) {
    case PositionCommand::MODE_TRAJECTORY: s.mode = SpeedAccount::Mode::kTrajectory; break;
    case PositionCommand::MODE_END_STOP:
    case PositionCommand::MODE_WATCHDOG_STOP: s.mode = SpeedAccount::Mode::kStopping; break;
    default: s.mode = SpeedAccount::Mode::kHold; break;
  }
  s.planner_session = msg->planner_session;
  s.trajectory_id = msg->trajectory_id;
  s.position_m = Eigen::Vector3d(msg->position.x, msg->position.y, msg->position.z);
  s.velocity_mps = Eigen::Vector3d(msg->velocity.x, msg->velocity.y, msg->velocity.z);
  s.acceleration_mps2 = Eigen::Vector3d(msg->acceleration.x, msg->acceleration.y, msg->acceleration.z);
  // What the trajectory server commands is finite, in the world frame, in order and of this clock
  // (the planner refuses the same).
  if (!s.position_m.allFinite() || !s.velocity_mps.allFinite() || !s.acceleration_mps2.allFinite() ||
      (!msg->header.frame_id.empty() && msg->header.frame_id != config_.frame_id) || s.t_s < last_setpoint_t_s_ ||
      (have_stream_time_ && s.t_s > nowS() + 1.0)) {
    ROS_WARN_THROTTLE(5.0, "flight_monitor: setpoint ignored (non-finite, frame '%s', out of order or ahead)",
                      msg->header.frame_id.c_str());
    return;
  }
  last_setpoint_t_s_ = s.t_s;
  const int jumps = recorder_.setpoints().stats().jumps;
  recorder_.addSetpoint(s);
  if (recorder_.setpoints().stats().jumps > jumps) {
    const SetpointStep& st = recorder_.setpoints().stats().steps.back();
    ROS_WARN("flight_monitor: SETPOINT JUMP of %.2f m (allowed %.2f m) from (%.2f %.2f %.2f) to (%.2f %.2f %.2f)",
             (st.to_m - st.from_m).norm(), st.allowed_m, st.from_m.x(), st.from_m.y(), st.from_m.z(), st.to_m.x(),
             st.to_m.y(), st.to_m.z());
  }
}

void FlightMonitor::heartbeatCallback(const topo_planner::PlannerHeartbeatConstPtr& msg) {
  const double t = nowS();
  // The planner's heartbeat is in the world frame and stamped now (as the trajectory server takes it).
  if ((!msg->header.frame_id.empty() && msg->header.frame_id != config_.frame_id) ||
      !(std::abs(timeOf(msg->header.stamp) - t) <= 1.0) || msg->header.stamp.isZero()) {
    ROS_WARN_THROTTLE(5.0, "flight_monitor: heartbeat ignored (frame '%s', stamped %.3f)", msg->header.frame_id.c_str(),
                      msg->header.stamp.toSec());
    return;
  }
  if (resend_.onHeartbeat(msg->planner_session, msg->inputs_ok, t) && recorder_.started() && !done_)
    ROS_WARN("flight_monitor: the planner restarted (session %lu): goal %d goes again once its inputs are fresh",
             (unsigned long)msg->planner_session, recorder_.activeGoal() + 1);
}

void FlightMonitor::faultCallback(const std_msgs::StringConstPtr& msg) {
  std::istringstream words(msg->data);
  std::string kind, phase;
  words >> kind >> phase;
  const double t = nowS();
  recorder_.addFault(t, kind, phase, msg->data);
  if (!recorder_.started() || done_) return;
  ROS_WARN("flight_monitor: injected fault: %s", msg->data.c_str());
  if (phase == "end" || phase == "step") resend_.onFaultCleared(t);
  if (kind == "odom_blackout" && phase == "end") recorder_.addOdometryReturn(t);
}

void FlightMonitor::offsetCallback(const geometry_msgs::Vector3StampedConstPtr& msg) {
  const Eigen::Vector3d offset(msg->vector.x, msg->vector.y, msg->vector.z);
  if (!offset.allFinite()) return;
  const Eigen::Vector3d delta = offset - odom_offset_;
  odom_offset_ = offset;
  if (!delta.isZero()) recorder_.addOdometryJump(timeOf(msg->header.stamp), delta);
}

void FlightMonitor::collisionCallback(const topo_planner::CollisionConstPtr& msg) {
  const double t = timeOf(msg->header.stamp);
  if (recorder_.started() && !done_) {
    ROS_WARN_THROTTLE(1.0, "flight_monitor: COLLISION at (%.2f, %.2f, %.2f), clearance %.3f m (simulator count %u)",
                      msg->position.x, msg->position.y, msg->position.z, msg->clearance_m, msg->count);
  }
  recorder_.addSimCollisionCount(t, msg->count);
}

void FlightMonitor::replanCallback(const topo_planner::ReplanEventConstPtr& msg) {
  ReplanRecord r;
  r.t_s = timeOf(msg->header.stamp);
  r.position_m = Eigen::Vector3d(msg->position.x, msg->position.y, msg->position.z);
  r.trigger = msg->trigger;
  r.status = msg->status;
  r.fallback = msg->fallback;
  r.message = msg->message;
  r.total_ms = msg->total_ms;
  r.trajectory_id = msg->trajectory_id;
  r.published = msg->trajectory_id >= 0;
  r.stall = msg->fallback == "reroute";
  if (recorder_.started() && !done_) planned_since_goal_ = true;  // a stall event too: the planner has the goal
  recorder_.addReplan(std::move(r));
}

void FlightMonitor::referenceCallback(const nav_msgs::PathConstPtr& msg) {
  ReferenceRecord r;
  r.id = int(references_.size());
  r.t_s = nowS();
  r.points_m.reserve(msg->poses.size());
  for (const geometry_msgs::PoseStamped& p : msg->poses) {
    const Eigen::Vector3d q(p.pose.position.x, p.pose.position.y, p.pose.position.z);
    if (q.allFinite()) r.points_m.push_back(q);
  }
  references_.push_back(std::move(r));
}

void FlightMonitor::checkTimer(const ros::TimerEvent&) {
  if (done_) return;
  const double now = nowS();
  if (!recorder_.started()) {
    if (!notReadyReason().empty()) {
      ready_since_s_ = -1.0;
      return;
    }
    if (ready_since_s_ < 0.0) ready_since_s_ = now;
    if (now - ready_since_s_ < config_.start_delay_s) return;
    startup_timer_.stop();
    ROS_INFO("flight_monitor: true map, odometry and planner ready: starting the flight");
    computeOracle();
    handle(recorder_.start(now), now);
    return;
  }
  handle(recorder_.checkTimeout(now), now);
  if (done_) return;
  if (resend_.due(now)) {
    ROS_WARN("flight_monitor: planner restarted or fault cleared %.1f s ago: sending goal %d again",
             config_.resend_settle_s, recorder_.activeGoal() + 1);
    ++goal_resends_;
    sendGoal(recorder_.activeGoal());
    return;
  }
  if (config_.resend_period_s <= 0.0 || planned_since_goal_) return;
  if (now - goal_sent_t_s_ >= config_.resend_period_s) {
    ROS_WARN("flight_monitor: no planning call since goal %d was sent %.1f s ago: sending it again",
             recorder_.activeGoal() + 1, now - goal_sent_t_s_);
    ++goal_resends_;
    sendGoal(recorder_.activeGoal());
  }
}

void FlightMonitor::startupTimeout(const ros::SteadyTimerEvent&) {
  if (done_ || recorder_.started()) return;
  const std::string why = "not ready after " + std::to_string(int(config_.startup_timeout_s)) +
                          " s (wall time): " + notReadyReason();
  ROS_ERROR("flight_monitor: %s", why.c_str());
  recorder_.finish(nowS(), FlightStatus::kNoStart, why);
  finishFlight(true);
}

// ---------------------------------------------------------------------------------------------
// Flight

void FlightMonitor::computeOracle() {
  // From where the vehicle is (the true state; the scenario's start without one).
  const Eigen::Vector3d start = have_truth_position_ ? truth_position_ : config_.start_m;
  if (!truth_ || !start.allFinite()) return;
  const auto t0 = std::chrono::steady_clock::now();
  // In the planner's window when known (the true map reaches beyond it), else on the whole true map.
  const FlightOracle::Result oracle =
      config_.oracle_window_size_m.allFinite() && (config_.oracle_window_size_m.array() > 0.0).all()
          ? FlightOracle::computeInWindow(truth_->occupancy(), config_.oracle_window_origin_m, config_.oracle_window_size_m,
                                          start, config_.goals, config_.oracle)
          : FlightOracle::compute(truth_->esdf(), start, config_.goals, config_.oracle);
  const double ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
  if (!oracle.ok) {
    ROS_WARN("flight_monitor: no oracle time for this flight: %s", oracle.why.c_str());
    return;
  }
  recorder_.setOracle(oracle);
  ROS_INFO("flight_monitor: oracle: %.1f s for the %zu goals at %.1f m/s and %.1f m/s^2 (%.0f ms)", oracle.total_s,
           config_.goals.size(), config_.oracle.max_vel_mps, config_.oracle.max_acc_mps2, ms);
}

std::string FlightMonitor::notReadyReason() const {
  std::string why;
  if (!truth_) why += "no true map on " + cloud_topic_ + "; ";
  if (!have_odom_) why += "no odometry on " + odom_sub_.getTopic() + "; ";
  if (waypoint_pub_.getNumSubscribers() == 0) why += "no planner subscribed to " + waypoint_pub_.getTopic() + "; ";
  return why.empty() ? why : why.substr(0, why.size() - 2);
}

void FlightMonitor::sendGoal(int index) {
  if (index < 0 || size_t(index) >= config_.goals.size()) return;
  const Eigen::Vector3d& g = config_.goals[size_t(index)];
  nav_msgs::Path path;
  path.header.stamp = ros::Time::now();
  path.header.frame_id = config_.frame_id;
  // Sequential: the one goal; waypoints: every goal from this one on (the mission's remaining goals).
  const size_t end = config_.recorder.pass_through ? config_.goals.size() : size_t(index) + 1;
  for (size_t i = size_t(index); i < end; ++i) {
    geometry_msgs::PoseStamped pose;
    pose.header = path.header;
    pose.pose.position = toPoint(config_.goals[i]);
    pose.pose.orientation.w = 1.0;
    path.poses.push_back(pose);
  }
  waypoint_pub_.publish(path);
  goal_sent_t_s_ = timeOf(path.header.stamp);
  planned_since_goal_ = false;
  const std::string more = path.poses.size() > 1 ? " and the " + std::to_string(path.poses.size() - 1) + " after it" : "";
  ROS_INFO("flight_monitor: goal %d/%zu sent: (%.2f, %.2f, %.2f)%s", index + 1, config_.goals.size(), g.x(), g.y(),
           g.z(), more.c_str());
}

void FlightMonitor::handle(const FlightRecorder::Update& update, double now_s) {
  const int n = int(config_.goals.size());
  if (update.goal_reached >= 0)
    ROS_INFO("flight_monitor: %s",
             formatGoalLine(recorder_.goals()[size_t(update.goal_reached)], n, recorder_.startTime(), now_s).c_str());
  if (update.goal_timed_out >= 0)
    ROS_WARN("flight_monitor: %s",
             formatGoalLine(recorder_.goals()[size_t(update.goal_timed_out)], n, recorder_.startTime(), now_s).c_str());
  // A waypoint mission was sent whole: passing a waypoint sends nothing.
  if (update.next_goal >= 0 && (!config_.recorder.pass_through || update.goal_reached < 0)) sendGoal(update.next_goal);
  if (update.finished) finishFlight(true);
}

void FlightMonitor::finishInterrupted() {
  if (done_) return;
  std::ostringstream why;
  if (recorder_.started()) {
    why << "monitor shut down during goal " << recorder_.activeGoal() + 1 << "/" << config_.goals.size();
  } else {
    why << "monitor shut down before the flight started (" << notReadyReason() << ")";
  }
  const double t = recorder_.started() ? std::max(recorder_.lastTime(), last_odom_t_s_) : last_odom_t_s_;
  recorder_.finish(t, FlightStatus::kInterrupted, why.str());
  finishFlight(false);
}

void FlightMonitor::finishFlight(bool publish) {
  if (done_) return;
  done_ = true;
  check_timer_.stop();
  startup_timer_.stop();
  recorder_.setCounters(resend_.restarts(), goal_resends_, clock_.steps());
  const FlightSummary s = recorder_.summary();

  if (publish && ros::ok()) {
    topo_planner::FlightResult r;
    r.header.stamp = ros::Time::now();
    r.header.frame_id = config_.frame_id;
    r.success = s.success;
    r.message = s.message;
    r.goals_total = uint32_t(s.goals_total);
    r.goals_reached = uint32_t(s.goals_reached);
    r.collisions = uint32_t(s.collisions);
    r.min_clearance_m = s.min_clearance_m;
    r.mean_speed_mps = s.mean_speed_mps;
    r.max_speed_mps = s.max_speed_mps;
    r.replans = uint32_t(s.replans);
    r.replan_failures = uint32_t(s.replan_failures);
    r.replan_ms_median = s.replan_ms_median;
    r.replan_ms_p95 = s.replan_ms_p95;
    r.duration_s = s.duration_s;
    r.path_length_m = s.path_length_m;
    // The report first: a subscriber that stops at the result is then likely (not certain: the topics
    // are separate connections) to have the report too.
    std_msgs::String report;
    report.data = reportJson(s, recorder_.goals(), recorder_.startTime(), reportInfo(), &recorder_);
    report_pub_.publish(report);
    result_pub_.publish(r);
  }
  // Goals sent but neither reached nor timed out (an interrupted flight) get their line too.
  for (const GoalRecord& g : recorder_.goals())
    if (g.sent && !g.reached && !g.timed_out)
      log(Level::kWarn, formatGoalLine(g, int(config_.goals.size()), recorder_.startTime(), recorder_.lastTime()));
  log(s.success ? Level::kInfo : Level::kError, formatReport(s, config_.name));
  writeFiles(s);
  if (config_.shutdown_when_done && ros::ok()) {
    log(Level::kInfo, "done, shutting down (shutdown_when_done)");
    ros::requestShutdown();
  }
}

FlightReportInfo FlightMonitor::reportInfo() const {
  FlightReportInfo info;
  info.name = config_.name;
  info.start_m = config_.start_m;
  info.map_resolution_m = config_.truth.resolution_m;
  info.map_occupied_voxels = truth_ ? truth_->numOccupied() : 0;
  info.collision_radius_m = config_.recorder.collision_radius_m;
  info.scenario = config_.scenario;
  return info;
}

void FlightMonitor::writeFiles(const FlightSummary& summary) const {
  if (config_.output_dir.empty()) return;
  std::error_code ec;
  std::filesystem::create_directories(config_.output_dir, ec);
  if (ec) {
    log(Level::kError, "cannot create " + config_.output_dir + ": " + ec.message());
    return;
  }
  const std::string stem = (std::filesystem::path(config_.output_dir) / config_.name).string();
  const double t0 = recorder_.startTime();
  std::vector<ReferenceRecord> references = references_;
  for (ReferenceRecord& r : references) r.t_s -= t0;
  const FlightReportInfo info = reportInfo();
  std::string error;
  bool ok = writeTraceCsv(stem + ".csv", recorder_.trace(), &error) &&
            writeReplanCsv(stem + "_events.csv", recorder_.replans(), t0, &error) &&
            writeMapCsv(stem + "_map.csv", map_columns_, &error) &&
            writeReferenceCsv(stem + "_reference.csv", references, &error) &&
            writeReportJson(stem + "_report.json", summary, recorder_.goals(), t0, info, &error, &recorder_);
  if (ok) {
    log(Level::kInfo, "wrote " + stem + "{.csv,_events.csv,_map.csv,_reference.csv,_report.json}");
  } else {
    log(Level::kError, error);
  }
}

}  // namespace topo_planner
