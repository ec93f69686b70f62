#include "plan_manage/flight_monitor.h"

#include <geometry_msgs/PoseStamped.h>
#include <topo_planner/FlightResult.h>

#include <Eigen/Geometry>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <sstream>

#include "uav_sim/ros/conversions.h"
#include "uav_sim/ros/param_reader.h"

namespace topo_planner {

namespace {

bool finitePositive(double x) { return std::isfinite(x) && x > 0.0; }
bool finiteNonNegative(double x) { return std::isfinite(x) && x >= 0.0; }

double stampOrNow(const ros::Time& stamp) { return (stamp.isZero() ? ros::Time::now() : stamp).toSec(); }

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
    : nh_(nh), pnh_(pnh), config_(config), recorder_(config.recorder, config.goals) {}

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
  m->cloud_topic_ = m->nh_.resolveName("map_generator/global_cloud");
  m->truth_sub_ = std::make_unique<TruthMapSubscriber>(
      m->nh_, m->cloud_topic_, config.truth, "flight_monitor",
      [self](const std::shared_ptr<const TruthMap>& map) { self->onTruthMap(map); });
  m->odom_sub_ = m->nh_.subscribe("odom", 50, &FlightMonitor::odomCallback, self, ros::TransportHints().tcpNoDelay());
  m->collision_sub_ = m->nh_.subscribe("quadrotor/collision", 50, &FlightMonitor::collisionCallback, self);
  m->replan_sub_ = m->nh_.subscribe("planning/replan_event", 100, &FlightMonitor::replanCallback, self);
  m->reference_sub_ = m->nh_.subscribe("planning/reference_path", 10, &FlightMonitor::referenceCallback, self);
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
  const double t = stampOrNow(msg->header.stamp);
  have_odom_ = true;
  last_odom_t_s_ = t;
  if (!recorder_.started() || done_ || !truth_) return;

  OdometrySample s;
  s.t_s = t;
  s.position_m = state.position;
  s.velocity_mps = state.velocity;
  // The ground is an obstacle too (the simulator counts touching it as a collision).
  s.clearance_m = std::min(truth_->obstacleDistance(s.position_m, config_.clearance_exact_within_m),
                           s.position_m.z() - config_.ground_z_m);
  handle(recorder_.addOdometry(s), t);
}

void FlightMonitor::collisionCallback(const topo_planner::CollisionConstPtr& msg) {
  const double t = stampOrNow(msg->header.stamp);
  if (recorder_.started() && !done_) {
    ROS_WARN_THROTTLE(1.0, "flight_monitor: COLLISION at (%.2f, %.2f, %.2f), clearance %.3f m (simulator count %u)",
                      msg->position.x, msg->position.y, msg->position.z, msg->clearance_m, msg->count);
  }
  recorder_.addSimCollisionCount(t, msg->count);
}

void FlightMonitor::replanCallback(const topo_planner::ReplanEventConstPtr& msg) {
  ReplanRecord r;
  r.t_s = stampOrNow(msg->header.stamp);
  r.position_m = Eigen::Vector3d(msg->position.x, msg->position.y, msg->position.z);
  r.trigger = msg->trigger;
  r.status = msg->status;
  r.fallback = msg->fallback;
  r.total_ms = msg->total_ms;
  r.trajectory_id = msg->trajectory_id;
  r.published = msg->trajectory_id >= 0;
  if (recorder_.started() && !done_) planned_since_goal_ = true;
  recorder_.addReplan(std::move(r));
}

void FlightMonitor::referenceCallback(const nav_msgs::PathConstPtr& msg) {
  ReferenceRecord r;
  r.id = int(references_.size());
  r.t_s = ros::Time::now().toSec();
  r.points_m.reserve(msg->poses.size());
  for (const geometry_msgs::PoseStamped& p : msg->poses) {
    const Eigen::Vector3d q(p.pose.position.x, p.pose.position.y, p.pose.position.z);
    if (q.allFinite()) r.points_m.push_back(q);
  }
  references_.push_back(std::move(r));
}

void FlightMonitor::checkTimer(const ros::TimerEvent&) {
  if (done_) return;
  const ros::Time now = ros::Time::now();
  if (!recorder_.started()) {
    if (!notReadyReason().empty()) {
      ready_since_ = ros::Time();
      return;
    }
    if (ready_since_.isZero()) ready_since_ = now;
    if ((now - ready_since_).toSec() < config_.start_delay_s) return;
    startup_timer_.stop();
    ROS_INFO("flight_monitor: true map, odometry and planner ready: starting the flight");
    handle(recorder_.start(now.toSec()), now.toSec());
    return;
  }
  handle(recorder_.checkTimeout(now.toSec()), now.toSec());
  if (done_ || config_.resend_period_s <= 0.0 || planned_since_goal_) return;
  if ((now - goal_sent_at_).toSec() >= config_.resend_period_s) {
    ROS_WARN("flight_monitor: no planning call since goal %d was sent %.1f s ago: sending it again",
             recorder_.activeGoal() + 1, (now - goal_sent_at_).toSec());
    sendGoal(recorder_.activeGoal());
  }
}

void FlightMonitor::startupTimeout(const ros::SteadyTimerEvent&) {
  if (done_ || recorder_.started()) return;
  const std::string why = "not ready after " + std::to_string(int(config_.startup_timeout_s)) +
                          " s (wall time): " + notReadyReason();
  ROS_ERROR("flight_monitor: %s", why.c_str());
  recorder_.finish(ros::Time::now().toSec(), FlightStatus::kNoStart, why);
  finishFlight(true);
}

// ---------------------------------------------------------------------------------------------
// Flight

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
  geometry_msgs::PoseStamped pose;
  pose.header = path.header;
  pose.pose.position = toPoint(g);
  pose.pose.orientation.w = 1.0;
  path.poses.push_back(pose);
  waypoint_pub_.publish(path);
  goal_sent_at_ = path.header.stamp;
  planned_since_goal_ = false;
  ROS_INFO("flight_monitor: goal %d/%zu sent: (%.2f, %.2f, %.2f)", index + 1, config_.goals.size(), g.x(), g.y(),
           g.z());
}

void FlightMonitor::handle(const FlightRecorder::Update& update, double now_s) {
  const int n = int(config_.goals.size());
  if (update.goal_reached >= 0)
    ROS_INFO("flight_monitor: %s",
             formatGoalLine(recorder_.goals()[size_t(update.goal_reached)], n, recorder_.startTime(), now_s).c_str());
  if (update.goal_timed_out >= 0)
    ROS_WARN("flight_monitor: %s",
             formatGoalLine(recorder_.goals()[size_t(update.goal_timed_out)], n, recorder_.startTime(), now_s).c_str());
  if (update.next_goal >= 0) sendGoal(update.next_goal);
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
  FlightReportInfo info;
  info.name = config_.name;
  info.start_m = config_.start_m;
  info.map_resolution_m = config_.truth.resolution_m;
  info.map_occupied_voxels = truth_ ? truth_->numOccupied() : 0;
  info.collision_radius_m = config_.recorder.collision_radius_m;
  info.scenario = config_.scenario;

  std::string error;
  bool ok = writeTraceCsv(stem + ".csv", recorder_.trace(), &error) &&
            writeReplanCsv(stem + "_events.csv", recorder_.replans(), t0, &error) &&
            writeMapCsv(stem + "_map.csv", map_columns_, &error) &&
            writeReferenceCsv(stem + "_reference.csv", references, &error) &&
            writeReportJson(stem + "_report.json", summary, recorder_.goals(), t0, info, &error);
  if (ok) {
    log(Level::kInfo, "wrote " + stem + "{.csv,_events.csv,_map.csv,_reference.csv,_report.json}");
  } else {
    log(Level::kError, error);
  }
}

}  // namespace topo_planner
