#include "topo_planner/uav_sim/ros/quadrotor_sim.h"

#include <diagnostic_msgs/DiagnosticStatus.h>
#include <geometry_msgs/TransformStamped.h>
#include <geometry_msgs/Vector3Stamped.h>
#include <rosgraph_msgs/Clock.h>
#include <std_msgs/Bool.h>
#include <std_msgs/String.h>
#include <topo_planner/Collision.h>
#include <topo_planner/PositionCommand.h>

#include <cmath>
#include <cstdio>
#include <sstream>

#include "topo_planner/uav_sim/ros/conversions.h"
#include "topo_planner/uav_sim/ros/param_reader.h"

namespace topo_planner {

namespace {

using SteadyClock = std::chrono::steady_clock;

bool finitePositive(double x) { return std::isfinite(x) && x > 0.0; }
bool finiteNonNegative(double x) { return std::isfinite(x) && x >= 0.0; }

geometry_msgs::TransformStamped toTransform(const Eigen::Isometry3d& T, const ros::Time& stamp,
                                            const std::string& parent, const std::string& child) {
  geometry_msgs::TransformStamped t;
  t.header.stamp = stamp;
  t.header.frame_id = parent;
  t.child_frame_id = child;
  const Eigen::Quaterniond q(T.linear());
  t.transform.translation.x = T.translation().x();
  t.transform.translation.y = T.translation().y();
  t.transform.translation.z = T.translation().z();
  t.transform.rotation.w = q.w();
  t.transform.rotation.x = q.x();
  t.transform.rotation.y = q.y();
  t.transform.rotation.z = q.z();
  return t;
}

}  // namespace

// ---------------------------------------------------------------------------------------------
// Configuration

Eigen::Isometry3d QuadrotorSim::Config::defaultBodyToCamera() {
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  T.linear() << 0, 0, 1, -1, 0, 0, 0, -1, 0;  // columns: optical x, y, z in the FLU body frame
  return T;
}

bool QuadrotorSim::Config::validate(std::string* why) const {
  std::ostringstream err;
  std::string core;
  if (!vehicle.validate(&core)) err << "vehicle: " << core << "; ";
  if (!scenario.validate(&core)) err << core << "; ";
  if (!std::isfinite(start_yaw_rad)) err << "start_yaw_rad must be finite; ";
  if (!(finitePositive(step_s) && step_s <= 0.01)) err << "step_s must be in (0, 0.01]; ";
  if (!(finitePositive(odom_rate_hz) && odom_rate_hz <= 1.0 / step_s)) {
    err << "odom_rate_hz must be positive and at most 1 / step_s; ";
  } else {
    const double steps = 1.0 / (odom_rate_hz * step_s);
    if (std::abs(steps - std::round(steps)) > 1e-6) err << "1 / (odom_rate_hz * step_s) must be a whole number; ";
  }
  if (!(finitePositive(clock_start_s) && clock_start_s < 1e9)) err << "clock_start_s must be in (0, 1e9); ";
  if (!(finitePositive(realtime_factor) && realtime_factor <= 1000.0)) err << "realtime_factor must be in (0, 1000]; ";
  if (!(finiteNonNegative(max_lag_s) && max_lag_s <= 10.0)) err << "max_lag_s must be in [0, 10]; ";
  if (!(finitePositive(lockstep_timeout_s) && lockstep_timeout_s <= 10.0))
    err << "lockstep_timeout_s must be in (0, 10]; ";
  if (!(finitePositive(perception_max_lag_s) && perception_max_lag_s <= 10.0))
    err << "perception_max_lag_s must be in (0, 10]; ";
  if (!(finitePositive(perception_timeout_s) && perception_timeout_s <= 60.0))
    err << "perception_timeout_s must be in (0, 60]; ";
  if (!(finitePositive(planner_max_lag_s) && planner_max_lag_s <= 10.0))
    err << "planner_max_lag_s must be in (0, 10]; ";
  if (!(finitePositive(setpoint_max_lag_s) && setpoint_max_lag_s <= 10.0))
    err << "setpoint_max_lag_s must be in (0, 10]; ";
  if (!(finitePositive(command_timeout_s) && command_timeout_s <= 3600.0))
    err << "command_timeout_s must be in (0, 3600]; ";
  if (!(finitePositive(max_command_age_s) && max_command_age_s <= 10.0))
    err << "max_command_age_s must be in (0, 10]; ";
  if (!(finitePositive(collision_radius_m) && collision_radius_m <= 10.0))
    err << "collision_radius_m must be in (0, 10]; ";
  if (!(finiteNonNegative(collision_release_m) && collision_release_m <= 1.0))
    err << "collision_release_m must be in [0, 1]; ";
  if (!std::isfinite(ground_z_m)) err << "ground_z_m must be finite; ";
  if (!finiteNonNegative(position_noise_m) || !finiteNonNegative(velocity_noise_mps) ||
      !finiteNonNegative(position_drift_m_per_sqrt_s))
    err << "odometry noise sigmas must be >= 0; ";
  if (!(finiteNonNegative(odom_delay_s) && odom_delay_s <= 10.0)) err << "odom_delay_s must be in [0, 10]; ";
  if (world_frame.empty() || body_frame.empty() || camera_frame.empty()) err << "frame names must not be empty; ";
  if (!T_body_camera.matrix().allFinite()) err << "camera_extrinsic must be finite; ";
  if (!(finiteNonNegative(truth_map_margin_m) && truth_map_margin_m <= 100.0))
    err << "truth_map_margin_m must be in [0, 100]; ";
  if (!(finiteNonNegative(map_wait_s) && map_wait_s <= 3600.0)) err << "map_wait_s must be in [0, 3600]; ";
  if (!faults.validate(clock_start_s, &core)) err << "faults: " << core << "; ";
  if (!faults.clock_steps.empty() && !publish_clock) err << "faults/clock_steps need publish_clock (sim time); ";
  if (!(finiteNonNegative(faults_start_on_speed_mps) && faults_start_on_speed_mps <= 100.0))
    err << "faults/start_on_speed_mps must be in [0, 100]; ";
  if (!(finitePositive(status_period_s) && status_period_s <= 1e6)) err << "status_period_s must be positive; ";
  if (scenario.start_m.z() < ground_z_m) err << "/sim/start_m is below the ground; ";
  const std::string s = err.str();
  if (why) *why = s.empty() ? "" : s.substr(0, s.size() - 2);
  return s.empty();
}

bool readQuadrotorSimParams(const ros::NodeHandle& pnh, QuadrotorSim::Config* config) {
  QuadrotorSim::Config& c = *config;
  ParamReader r(pnh);
  std::string scenario_error;
  if (!readSimScenario(&c.scenario, &scenario_error)) r.errors() << scenario_error << "; ";
  readVehicleParams(r, &c.vehicle);
  bool use_sim_time = false;
  ros::param::get("/use_sim_time", use_sim_time);
  c.publish_clock = use_sim_time;
  r.read("start_yaw_rad", c.start_yaw_rad);
  r.read("step_s", c.step_s);
  r.read("odom_rate_hz", c.odom_rate_hz);
  r.read("publish_clock", c.publish_clock);
  r.read("clock_start_s", c.clock_start_s);
  r.read("realtime_factor", c.realtime_factor);
  r.read("max_lag_s", c.max_lag_s);
  r.read("lockstep", c.lockstep);
  r.read("lockstep_timeout_s", c.lockstep_timeout_s);
  r.read("perception_topic", c.perception_topic);
  r.read("perception_max_lag_s", c.perception_max_lag_s);
  r.read("perception_timeout_s", c.perception_timeout_s);
  r.read("planner_topic", c.planner_topic);
  r.read("planner_max_lag_s", c.planner_max_lag_s);
  r.read("setpoint_topic", c.setpoint_topic);
  r.read("setpoint_max_lag_s", c.setpoint_max_lag_s);
  // The wall-clock waits of the locksteps stretch by this (make test-asan / test-tsan: every node
  // runs several times slower; the simulated flight is the same).
  double wall_timeout_scale = 1.0;
  r.read("wall_timeout_scale", wall_timeout_scale);
  if (!(wall_timeout_scale >= 1.0 && wall_timeout_scale <= 100.0)) {
    r.errors() << "wall_timeout_scale must be in [1, 100]; ";
  } else {
    c.lockstep_timeout_s *= wall_timeout_scale;
    c.perception_timeout_s *= wall_timeout_scale;
  }
  r.read("command_timeout_s", c.command_timeout_s);
  r.read("max_command_age_s", c.max_command_age_s);
  std::string failsafe = c.failsafe == QuadrotorSim::Failsafe::kHold ? "hold" : "cut";
  r.read("failsafe", failsafe);
  if (failsafe == "hold")
    c.failsafe = QuadrotorSim::Failsafe::kHold;
  else if (failsafe == "cut")
    c.failsafe = QuadrotorSim::Failsafe::kCut;
  else
    r.errors() << "failsafe must be hold or cut, not '" << failsafe << "'; ";
  r.read("collision_radius_m", c.collision_radius_m);
  r.read("collision_release_m", c.collision_release_m);
  r.read("ground_z_m", c.ground_z_m);
  r.read("odom_noise/position_m", c.position_noise_m);
  r.read("odom_noise/velocity_mps", c.velocity_noise_mps);
  r.read("odom_noise/drift_m_per_sqrt_s", c.position_drift_m_per_sqrt_s);
  r.readUnsigned("odom_noise/seed", c.noise_seed);
  r.read("odom_delay_s", c.odom_delay_s);
  r.read("world_frame", c.world_frame);
  r.read("body_frame", c.body_frame);
  r.read("camera_frame", c.camera_frame);
  r.readTransform("camera_extrinsic", c.T_body_camera);
  r.read("truth_map_margin_m", c.truth_map_margin_m);
  r.read("map_wait_s", c.map_wait_s);
  r.read("status_period_s", c.status_period_s);
  std::vector<double> depth_blackouts, odom_blackouts, odom_jumps, clock_steps;
  r.read("faults/depth_blackouts_s", depth_blackouts);
  r.read("faults/odom_blackouts_s", odom_blackouts);
  r.read("faults/odom_jumps", odom_jumps);
  r.read("faults/clock_steps", clock_steps);
  r.read("faults/start_on_speed_mps", c.faults_start_on_speed_mps);
  std::string fault_error;
  if (!FaultSchedule::fromLists(depth_blackouts, odom_blackouts, odom_jumps, clock_steps, &c.faults, &fault_error))
    r.errors() << "faults: " << fault_error << "; ";
  if (use_sim_time && !c.publish_clock)
    r.errors() << "/use_sim_time is true but publish_clock is false: nothing would drive the clock; ";
  if (!use_sim_time && c.publish_clock)
    ROS_WARN("quadrotor_sim: publish_clock without /use_sim_time: the other nodes will not follow /clock");
  std::string range;
  c.validate(&range);
  return r.finish("quadrotor_sim", range);
}

// ---------------------------------------------------------------------------------------------
// Construction

QuadrotorSim::QuadrotorSim(const ros::NodeHandle& nh, const ros::NodeHandle& pnh, const Config& config)
    : nh_(nh),
      pnh_(pnh),
      config_(config),
      quad_(config.vehicle),
      failsafe_controller_(GeometricController::Config(), config.vehicle),
      contact_(config.collision_radius_m, config.collision_release_m),
      noise_rng_(config.noise_seed) {}

std::unique_ptr<QuadrotorSim> QuadrotorSim::create(const ros::NodeHandle& nh, const ros::NodeHandle& pnh,
                                                   const Config& config, std::string* error) {
  std::string why;
  if (!config.validate(&why)) {
    if (error) *error = "invalid config: " + why;
    return nullptr;
  }
  std::unique_ptr<QuadrotorSim> sim(new QuadrotorSim(nh, pnh, config));
  QuadrotorSim& s = *sim;
  s.step_ns_ = int64_t(std::llround(config.step_s * 1e9));
  s.steps_per_odom_ = int(std::lround(1.0 / (config.odom_rate_hz * config.step_s)));
  s.delay_steps_ = uint64_t(std::llround(config.odom_delay_s / config.step_s));

  Quadrotor::State start;  // hovering: rotors at hover speed, at rest
  start.position = config.scenario.start_m;
  start.orientation = Eigen::Quaterniond(Eigen::AngleAxisd(config.start_yaw_rad, Eigen::Vector3d::UnitZ()));
  start.rotor_speed.setConstant(s.quad_.hoverRotorSpeed());
  s.quad_.setState(start);
  s.quad_.setRotorSpeedCommand(start.rotor_speed);

  s.odom_pub_ = s.nh_.advertise<nav_msgs::Odometry>("odom", 10);
  s.truth_pub_ = s.pnh_.advertise<nav_msgs::Odometry>("ground_truth", 10);
  s.fc_odom_pub_ = s.pnh_.advertise<nav_msgs::Odometry>("fc_odom", 10);
  s.collision_pub_ = s.nh_.advertise<topo_planner::Collision>("quadrotor/collision", 10);
  if (config.publish_clock) s.clock_pub_ = s.nh_.advertise<rosgraph_msgs::Clock>("/clock", 10);
  s.depth_blackout_pub_ = s.pnh_.advertise<std_msgs::Bool>("depth_blackout", 1, /*latch=*/true);
  s.odom_offset_pub_ = s.pnh_.advertise<geometry_msgs::Vector3Stamped>("odom_offset", 1, /*latch=*/true);
  s.fault_event_pub_ = s.pnh_.advertise<std_msgs::String>("fault_event", 20);
  s.status_pub_ = s.pnh_.advertise<diagnostic_msgs::DiagnosticStatus>("status", 5, /*latch=*/true);
  s.static_broadcaster_.sendTransform(
      toTransform(config.T_body_camera, ros::Time(config.clock_start_s), config.body_frame, config.camera_frame));

  s.truth_ = std::make_unique<TruthMapSubscriber>(
      s.nh_, "map_generator/global_cloud", truthMapConfig(config.scenario, config.truth_map_margin_m), "quadrotor_sim");
  // Rotor commands on their own queue and thread: the loop may be waiting for them (lockstep).
  ros::NodeHandle command_nh(s.nh_);
  command_nh.setCallbackQueue(&s.command_queue_);
  s.command_sub_ = command_nh.subscribe("controller/rotor_command", 10, &QuadrotorSim::commandCallback, &s,
                                        ros::TransportHints().tcpNoDelay());
  // The mapping's frames fused, on the same queue (the loop may be waiting for them: perception lockstep).
  // And the planner's ticks (planner lockstep), and the trajectory server's setpoints (setpoint lockstep).
  auto subscribeReports = [&](const std::string& topic, Source source) {
    return command_nh.subscribe<std_msgs::Header>(
        topic, 10, [&s, source](const std_msgs::HeaderConstPtr& msg) { s.reportCallback(source, msg->stamp); },
        ros::VoidConstPtr(), ros::TransportHints().tcpNoDelay());
  };
  const bool locksteps = config.publish_clock && config.lockstep;
  if (locksteps && !config.perception_topic.empty()) s.fused_sub_ = subscribeReports(config.perception_topic, kMapping);
  if (locksteps && !config.planner_topic.empty()) s.planner_sub_ = subscribeReports(config.planner_topic, kPlanner);
  if (locksteps && !config.setpoint_topic.empty())
    s.setpoint_sub_ = command_nh.subscribe<topo_planner::PositionCommand>(
        config.setpoint_topic, 10,
        [&s](const topo_planner::PositionCommandConstPtr& msg) { s.reportCallback(kSetpoints, msg->header.stamp); },
        ros::VoidConstPtr(), ros::TransportHints().tcpNoDelay());
  s.command_spinner_ = std::make_unique<ros::AsyncSpinner>(1, &s.command_queue_);
  s.command_spinner_->start();
  ROS_INFO("quadrotor_sim: start (%.2f %.2f %.2f) hovering, %.0f Hz odometry, %s, collision radius %.2f m",
           start.position.x(), start.position.y(), start.position.z(), config.odom_rate_hz,
           config.publish_clock ? "publishing /clock" : "real time", config.collision_radius_m);
  if (!config.faults.empty()) {
    char origin[96];
    if (config.faults_start_on_speed_mps > 0.0)
      std::snprintf(origin, sizeof(origin), "the first moment faster than %.2f m/s", config.faults_start_on_speed_mps);
    else
      std::snprintf(origin, sizeof(origin), "the clock start");
    ROS_WARN("quadrotor_sim: faults scheduled: %s; times from %s", config.faults.describe().c_str(), origin);
  }
  s.thread_ = std::thread(&QuadrotorSim::loop, &s);
  return sim;
}

QuadrotorSim::~QuadrotorSim() {
  stop_ = true;
  command_cv_.notify_all();
  perception_cv_.notify_all();
  if (thread_.joinable()) thread_.join();
  if (command_spinner_) command_spinner_->stop();
}

QuadrotorSim::Stats QuadrotorSim::stats() const {
  std::lock_guard<std::mutex> lock(stats_mutex_);
  return stats_;
}

// ---------------------------------------------------------------------------------------------
// Commands

void QuadrotorSim::commandCallback(const topo_planner::RotorCommandConstPtr& msg) {
  const Eigen::Vector4d w(msg->rotor_speed_radps[0], msg->rotor_speed_radps[1], msg->rotor_speed_radps[2],
                          msg->rotor_speed_radps[3]);
  if (!w.allFinite() || (w.array() < 0.0).any()) {
    {
      std::lock_guard<std::mutex> lock(stats_mutex_);
      ++stats_.bad_commands;
    }
    ROS_WARN_THROTTLE(1.0, "quadrotor_sim: refusing a rotor command with NaN/inf/negative speeds; keeping the last");
    return;
  }
  double age_s = 0.0;
  bool stale = false;
  {
    std::lock_guard<std::mutex> lock(command_mutex_);
    // An answer to a stamp newer than any odometry published is one from before a backward clock
    // step: it answers nothing the loop waits for now (and its age is not known: it is taken).
    const ros::Time answers = msg->header.stamp;
    if (answers <= newest_published_) {
      command_answers_ = answers;
      age_s = (newest_published_ - answers).toSec();
      stale = !answers.isZero() && age_s > config_.max_command_age_s;
    }
    if (!stale) {
      command_ = w;
      command_step_ = current_step_.load();
      have_command_ = true;
    }
    lockstep_suspended_ = false;  // the controller is alive: waiting for it lets it catch up
  }
  command_cv_.notify_all();
  if (stale) {
    ROS_WARN_THROTTLE(1.0, "quadrotor_sim: refusing a stale rotor command (computed on odometry %.0f ms old, more "
                      "than max_command_age_s %.0f ms): the controller lags the clock", 1e3 * age_s,
                      1e3 * config_.max_command_age_s);
  }
  std::lock_guard<std::mutex> lock(stats_mutex_);
  ++(stale ? stats_.stale_commands : stats_.commands);
}

// ---------------------------------------------------------------------------------------------
// The loop

ros::Time QuadrotorSim::stampOf(uint64_t step) const {
  ros::Duration d;
  d.fromNSec(int64_t(step - anchor_step_) * step_ns_);
  return anchor_stamp_ + d;
}

void QuadrotorSim::publishClock() {
  rosgraph_msgs::Clock clock;
  clock.clock = stampOf(step_);
  clock_pub_.publish(clock);
}

bool QuadrotorSim::waitForMap() {
  const auto deadline = SteadyClock::now() + std::chrono::duration<double>(config_.map_wait_s);
  while (!stop_ && ros::ok() && !truth_->map() && SteadyClock::now() < deadline) {
    ROS_INFO_THROTTLE(5.0, "quadrotor_sim: waiting for the true map on %s before starting the clock",
                      nh_.resolveName("map_generator/global_cloud").c_str());
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  return bool(truth_->map());
}

void QuadrotorSim::loop() {
  const double dt = config_.step_s;
  const int n = steps_per_odom_;
  if (config_.publish_clock) {
    anchor_stamp_ = ros::Time(config_.clock_start_s);
    publishClock();
    if (!waitForMap())
      ROS_ERROR("quadrotor_sim: no true map after %.0f s: flying without collision checks until it arrives",
                config_.map_wait_s);
  } else {
    anchor_stamp_ = ros::Time::now();
    if (!truth_->map()) ROS_WARN("quadrotor_sim: no true map yet: collisions are checked once it arrives");
  }
  // The fault state at t = 0 (latched for late subscribers), and the faults that start at 0.
  std_msgs::Bool blackout;
  blackout.data = false;
  depth_blackout_pub_.publish(blackout);
  geometry_msgs::Vector3Stamped offset;
  offset.header.stamp = stampOf(step_);
  offset.header.frame_id = config_.world_frame;
  odom_offset_pub_.publish(offset);
  if (config_.faults_start_on_speed_mps <= 0.0) {
    fault_origin_step_ = int64_t(step_);
    applyFaults(-1.0, 0.0);
  }
  // Wall time of a batch of n steps, and the largest backlog the loop catches up.
  const auto batch_wall = std::chrono::duration<double>(n * dt / config_.realtime_factor);
  const auto max_lag = std::chrono::duration<double>(config_.max_lag_s);
  auto anchor_wall = SteadyClock::now();
  uint64_t anchor_wall_step = step_;
  auto status_wall = anchor_wall;
  uint64_t status_step = step_;

  while (!stop_ && ros::ok()) {
    const auto target = anchor_wall + std::chrono::duration_cast<SteadyClock::duration>(
                                          batch_wall * (double(step_ + n - anchor_wall_step) / n));
    const auto now = SteadyClock::now();
    if (now < target) {
      std::this_thread::sleep_until(target);
    } else if (now - target > max_lag) {
      // Too far behind: drop the backlog. With sim time the clock just runs slower; in real time
      // the simulated time jumps to now.
      anchor_wall = now - std::chrono::duration_cast<SteadyClock::duration>(batch_wall);
      anchor_wall_step = step_;
      if (!config_.publish_clock) {
        anchor_stamp_ = ros::Time::now() - ros::Duration(n * dt);
        anchor_step_ = step_;
      }
      std::lock_guard<std::mutex> lock(stats_mutex_);
      ++stats_.lag_events;
    }

    const std::shared_ptr<const TruthMap> map = truth_->map();
    for (int k = 0; k < n; ++k) {
      step(map);
      if (config_.publish_clock) publishClock();
    }
    const ros::Time published = publishOdometry();
    if (config_.publish_clock && config_.lockstep && !published.isZero()) waitForReply(published);
    if (fused_sub_ || planner_sub_ || setpoint_sub_) waitForPerception(stampOf(step_));

    const auto wall = SteadyClock::now();
    const double period = std::chrono::duration<double>(wall - status_wall).count();
    if (period >= config_.status_period_s) {
      logStatus(period, step_ - status_step);
      status_wall = wall;
      status_step = step_;
    }
  }
}

void QuadrotorSim::step(const std::shared_ptr<const TruthMap>& map) {
  Eigen::Vector4d command;
  bool have, timed_out;
  double silence_s;
  {
    std::lock_guard<std::mutex> lock(command_mutex_);
    have = have_command_;
    command = command_;
    silence_s = double(step_ - std::min(step_, command_step_)) * config_.step_s;
    timed_out = have && silence_s > config_.command_timeout_s;
  }
  if (timed_out && !in_failsafe_) {
    in_failsafe_ = true;
    failsafe_reference_ = TrackingReference();
    failsafe_reference_.position = quad_.state().position;
    failsafe_reference_.yaw = yawOf(quad_.state().orientation);
    ROS_WARN("quadrotor_sim: no rotor command for %.2f s: failsafe %s at (%.2f %.2f %.2f)", silence_s,
             config_.failsafe == Failsafe::kHold ? "position hold" : "rotor cut", failsafe_reference_.position.x(),
             failsafe_reference_.position.y(), failsafe_reference_.position.z());
    std::lock_guard<std::mutex> lock(stats_mutex_);
    ++stats_.failsafe_events;
  } else if (!timed_out && in_failsafe_) {
    in_failsafe_ = false;
    ROS_INFO("quadrotor_sim: rotor commands are back: failsafe off");
  }
  if (in_failsafe_) {
    command = config_.failsafe == Failsafe::kHold
                  ? failsafe_controller_.compute(quad_.state(), failsafe_reference_).rotor_speed
                  : Eigen::Vector4d::Zero();  // clamped to the minimum rotor speed by the core
  }
  if (have || in_failsafe_) quad_.setRotorSpeedCommand(command);  // before any command: hover speed
  quad_.step(config_.step_s);
  ++step_;
  current_step_.store(step_);
  if (!config_.faults.empty()) {
    if (fault_origin_step_ < 0 && quad_.state().velocity.norm() > config_.faults_start_on_speed_mps) {
      fault_origin_step_ = int64_t(step_);
      ROS_INFO("quadrotor_sim: faster than %.2f m/s at t %.3f s: the fault schedule starts",
               config_.faults_start_on_speed_mps, double(step_) * config_.step_s);
      applyFaults(-1.0, 0.0);
    } else if (fault_origin_step_ >= 0) {
      // Whole steps since the origin: consecutive intervals share their ends exactly.
      const int64_t k = int64_t(step_) - fault_origin_step_;
      applyFaults(double(k - 1) * config_.step_s, double(k) * config_.step_s);
    }
  }

  Quadrotor::State s = quad_.state();
  if (!s.position.allFinite() || !s.velocity.allFinite() || !s.orientation.coeffs().allFinite()) {
    // The core ignores NaN commands, so this is a bug; keep the simulation alive and say so.
    ROS_ERROR_THROTTLE(1.0, "quadrotor_sim: the state became non-finite: resetting to hover at the start");
    Quadrotor::State reset;
    reset.position = config_.scenario.start_m;
    reset.rotor_speed.setConstant(quad_.hoverRotorSpeed());
    quad_.setState(reset);
    s = reset;
  }
  if (s.position.z() < config_.ground_z_m) {  // the ground stops the body's centre
    s.position.z() = config_.ground_z_m;
    if (s.velocity.z() < 0.0) {
      s.velocity.setZero();
      s.angular_velocity.setZero();
    }
    quad_.setState(s);
  }
  checkCollision(map);
}

void QuadrotorSim::checkCollision(const std::shared_ptr<const TruthMap>& map) {
  const Eigen::Vector3d p = quad_.state().position;
  const double r = config_.collision_radius_m;
  const double ground = p.z() - config_.ground_z_m;
  const double obstacle = map ? map->obstacleDistance(p, contact_.exactWithin()) : INFINITY;
  const double clearance = std::min(ground, obstacle);
  if (contact_.update(clearance)) {
    uint32_t count;
    {
      std::lock_guard<std::mutex> lock(stats_mutex_);
      count = ++stats_.collisions;
    }
    topo_planner::Collision msg;
    msg.header.stamp = stampOf(step_);
    msg.header.frame_id = config_.world_frame;
    msg.position.x = p.x();
    msg.position.y = p.y();
    msg.position.z = p.z();
    msg.clearance_m = clearance;
    msg.count = count;
    collision_pub_.publish(msg);
    ROS_WARN("quadrotor_sim: collision %u with the %s at (%.2f %.2f %.2f), clearance %.4f m < radius %.2f m", count,
             ground <= obstacle ? "ground" : "map", p.x(), p.y(), p.z(), clearance, r);
  }
}

void QuadrotorSim::applyFaults(double t0_s, double t1_s) {
  for (const FaultSchedule::Event& e : config_.faults.eventsIn(t0_s, t1_s)) {
    switch (e.kind) {
      case FaultSchedule::Kind::kDepthBlackout: {
        std_msgs::Bool msg;
        msg.data = config_.faults.depthBlackout(t1_s);
        depth_blackout_ = msg.data;
        depth_blackout_pub_.publish(msg);
        break;
      }
      case FaultSchedule::Kind::kOdomBlackout:
        odom_blackout_ = config_.faults.odomBlackout(t1_s);
        break;
      case FaultSchedule::Kind::kOdomJump: {
        odom_offset_ += e.offset_m;
        geometry_msgs::Vector3Stamped msg;
        msg.header.stamp = stampOf(step_);
        msg.header.frame_id = config_.world_frame;
        msg.vector.x = odom_offset_.x();
        msg.vector.y = odom_offset_.y();
        msg.vector.z = odom_offset_.z();
        odom_offset_pub_.publish(msg);
        break;
      }
      case FaultSchedule::Kind::kClockStep: {
        // Re-anchor the stamps: step_ keeps its stamp plus the step; the steps after follow it.
        anchor_stamp_ = stampOf(step_) + ros::Duration(e.step_s);
        anchor_step_ = step_;
        std::lock_guard<std::mutex> lock(command_mutex_);
        command_answers_ = ros::Time();  // answers to the old stamps must not satisfy the lockstep
        break;
      }
    }
    const std::string line = describe(e);
    std_msgs::String msg;
    msg.data = line;
    fault_event_pub_.publish(msg);
    ROS_WARN("quadrotor_sim: fault: %s (ROS time now %.3f)", line.c_str(), stampOf(step_).toSec());
    std::lock_guard<std::mutex> lock(stats_mutex_);
    ++stats_.fault_events;
  }
}

ros::Time QuadrotorSim::publishOdometry() {
  const ros::Time stamp = stampOf(step_);
  const Quadrotor::State& truth = quad_.state();
  if (truth_pub_.getNumSubscribers() > 0) {
    nav_msgs::Odometry msg;
    stateToOdometry(truth, stamp, config_.world_frame, config_.body_frame, &msg);
    truth_pub_.publish(msg);
  }
  Quadrotor::State measured = truth;
  if (config_.position_drift_m_per_sqrt_s > 0.0) {
    std::normal_distribution<double> n01(0.0, 1.0);
    const double dt = 1.0 / config_.odom_rate_hz;
    for (int a = 0; a < 3; ++a) drift_[a] += config_.position_drift_m_per_sqrt_s * std::sqrt(dt) * n01(noise_rng_);
    measured.position += drift_;
  }
  // The stamp the controller's answer is waited for (lockstep): the estimate it flies on.
  ros::Time reply_to;
  if (fc_odom_pub_.getNumSubscribers() > 0) {
    // The flight controller's estimate: the estimator's frame (its drift and jumps), at the IMU's
    // latency and smoothness (no white noise, no delay). Its subscriber is the controller (the
    // realistic profile), which answers this stamp, newer than the delayed odometry's.
    Quadrotor::State fc = measured;
    fc.position += odom_offset_;
    nav_msgs::Odometry msg;
    stateToOdometry(fc, stamp, config_.world_frame, config_.body_frame, &msg);
    {
      std::lock_guard<std::mutex> lock(command_mutex_);
      newest_published_ = stamp;
    }
    fc_odom_pub_.publish(msg);
    reply_to = stamp;
  }
  if (config_.position_noise_m > 0.0 || config_.velocity_noise_mps > 0.0) {
    std::normal_distribution<double> n01(0.0, 1.0);
    for (int a = 0; a < 3; ++a) measured.position[a] += config_.position_noise_m * n01(noise_rng_);
    for (int a = 0; a < 3; ++a) measured.velocity[a] += config_.velocity_noise_mps * n01(noise_rng_);
  }
  measured.position += odom_offset_;  // odometry jumps (zero without)
  Pending p;
  p.release_step = step_ + delay_steps_;
  stateToOdometry(measured, stamp, config_.world_frame, config_.body_frame, &p.msg);
  pending_.push_back(std::move(p));

  ros::Time newest;
  while (!pending_.empty() && pending_.front().release_step <= step_) {
    const nav_msgs::Odometry& msg = pending_.front().msg;
    if (odom_blackout_) {  // the estimator is silent: nothing is published, not even late
      pending_.pop_front();
      std::lock_guard<std::mutex> lock(stats_mutex_);
      ++stats_.odom_dropped;
      continue;
    }
    Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
    const auto& q = msg.pose.pose.orientation;
    T.linear() = Eigen::Quaterniond(q.w, q.x, q.y, q.z).toRotationMatrix();
    T.translation() = Eigen::Vector3d(msg.pose.pose.position.x, msg.pose.pose.position.y, msg.pose.pose.position.z);
    tf_broadcaster_.sendTransform(toTransform(T, msg.header.stamp, config_.world_frame, config_.body_frame));
    if (reply_to.isZero()) {  // (else the controller's estimate is the newer: answers to it count)
      std::lock_guard<std::mutex> lock(command_mutex_);
      newest_published_ = msg.header.stamp;
    }
    odom_pub_.publish(msg);
    newest = msg.header.stamp;
    pending_.pop_front();
  }
  return reply_to.isZero() ? newest : reply_to;
}

void QuadrotorSim::waitForReply(const ros::Time& odom_stamp) {
  std::unique_lock<std::mutex> lock(command_mutex_);
  if (!have_command_ || lockstep_suspended_) return;
  {
    std::lock_guard<std::mutex> stats_lock(stats_mutex_);
    ++stats_.lockstep_waits;
  }
  const bool answered = command_cv_.wait_for(lock, std::chrono::duration<double>(config_.lockstep_timeout_s),
                                             [&] { return stop_ || command_answers_ >= odom_stamp; });
  if (answered) return;
  lockstep_suspended_ = true;  // until the next command
  lock.unlock();
  {
    std::lock_guard<std::mutex> stats_lock(stats_mutex_);
    ++stats_.lockstep_timeouts;
  }
  ROS_WARN_THROTTLE(5.0,
                    "quadrotor_sim: no rotor command answered the odometry of %.3f within %.0f ms (wall): "
                    "running on without waiting until the next command",
                    odom_stamp.toSec(), 1e3 * config_.lockstep_timeout_s);
}

void QuadrotorSim::reportCallback(Source source, const ros::Time& stamp) {
  if (stamp.isZero()) return;
  {
    std::lock_guard<std::mutex> lock(perception_mutex_);
    // The latest, not the largest: after a backward clock step the reports are stamped earlier.
    reported_[source] = stamp;
    suspended_[source] = false;
  }
  perception_cv_.notify_all();
}

void QuadrotorSim::waitForPerception(const ros::Time& clock) {
  struct Lockstep {
    double lag_s;
    uint64_t Stats::*waits;
    uint64_t Stats::*timeouts;
    const char* awaited;
  };
  static_assert(kNumSources == 3, "a lockstep per source");
  const Lockstep locksteps[kNumSources] = {
      {config_.perception_max_lag_s, &Stats::perception_waits, &Stats::perception_timeouts, "depth frame fused"},
      {config_.planner_max_lag_s, &Stats::planner_waits, &Stats::planner_timeouts, "planning tick finished"},
      {config_.setpoint_max_lag_s, &Stats::setpoint_waits, &Stats::setpoint_timeouts, "setpoint"}};
  // By index, not over the enumerators: GCC 12 under ASan took an enumerator for any value of the
  // enum's range, up to kNumSources, and warned of a subscript out of bounds.
  for (int index = 0; index < kNumSources; ++index) {
    const Source source = static_cast<Source>(index);
    const Lockstep& ls = locksteps[index];
    std::unique_lock<std::mutex> lock(perception_mutex_);
    // Not before the first report, nor while the camera is blacked out (no frame will come).
    if (reported_[source].isZero() || suspended_[source] || (source == kMapping && depth_blackout_)) continue;
    const ros::Time due = clock - ros::Duration(ls.lag_s);
    if (reported_[source] >= due) continue;
    {
      std::lock_guard<std::mutex> stats_lock(stats_mutex_);
      ++(stats_.*ls.waits);
    }
    const bool caught_up = perception_cv_.wait_for(lock, std::chrono::duration<double>(config_.perception_timeout_s),
                                                   [&] { return stop_ || reported_[source] >= due; });
    if (caught_up) continue;
    suspended_[source] = true;  // until its next report
    const double last = reported_[source].toSec();
    lock.unlock();
    {
      std::lock_guard<std::mutex> stats_lock(stats_mutex_);
      ++(stats_.*ls.timeouts);
    }
    ROS_WARN_THROTTLE(5.0,
                      "quadrotor_sim: no %s after %.3f within %.1f s (wall; the last one %.3f): running on without "
                      "waiting until the next one",
                      ls.awaited, due.toSec(),
                      config_.perception_timeout_s, last);
  }
}

void QuadrotorSim::logStatus(double wall_s, uint64_t steps_in_period) {
  const Stats s = stats();
  const Quadrotor::State& q = quad_.state();
  const double factor = steps_in_period * config_.step_s / wall_s;
  ROS_INFO(
      "quadrotor_sim: t %.1f s, real-time factor %.2f (asked %.2f), at (%.2f %.2f %.2f) %.2f m/s, "
      "%u collisions, %lu commands (%lu refused, %lu stale), %lu lockstep waits (%lu in vain), %lu failsafes, %lu backlogs dropped, "
      "%lu fault changes, %lu odometry messages dropped, %lu waits for the mapping (%lu in vain), %lu for the "
      "planner (%lu in vain), %lu for setpoints (%lu in vain)",
      stampOf(step_).toSec(), factor, config_.publish_clock ? config_.realtime_factor : 1.0, q.position.x(),
      q.position.y(), q.position.z(), q.velocity.norm(), s.collisions, (unsigned long)s.commands,
      (unsigned long)s.bad_commands, (unsigned long)s.stale_commands, (unsigned long)s.lockstep_waits, (unsigned long)s.lockstep_timeouts, (unsigned long)s.failsafe_events,
      (unsigned long)s.lag_events, (unsigned long)s.fault_events, (unsigned long)s.odom_dropped,
      (unsigned long)s.perception_waits, (unsigned long)s.perception_timeouts, (unsigned long)s.planner_waits,
      (unsigned long)s.planner_timeouts, (unsigned long)s.setpoint_waits, (unsigned long)s.setpoint_timeouts);
  // The same on ~status (the counters since the start), for tests and benchmarks.
  diagnostic_msgs::DiagnosticStatus status;
  status.name = "quadrotor_sim";
  status.hardware_id = "simulator";
  status.level = s.collisions > 0 ? diagnostic_msgs::DiagnosticStatus::WARN : diagnostic_msgs::DiagnosticStatus::OK;
  status.message = s.collisions > 0 ? "collisions" : "ok";
  auto add = [&](const char* key, double value) {
    diagnostic_msgs::KeyValue kv;
    kv.key = key;
    char text[32];
    std::snprintf(text, sizeof(text), "%.15g", value);  // counters exact (a soak waits millions of times)
    kv.value = text;
    status.values.push_back(kv);
  };
  add("sim_time_s", stampOf(step_).toSec());
  add("realtime_factor", factor);
  add("collisions", s.collisions);
  add("commands", double(s.commands));
  add("stale_commands", double(s.stale_commands));
  add("lockstep_waits", double(s.lockstep_waits));
  add("lockstep_timeouts", double(s.lockstep_timeouts));
  add("perception_waits", double(s.perception_waits));
  add("perception_timeouts", double(s.perception_timeouts));
  add("planner_waits", double(s.planner_waits));
  add("planner_timeouts", double(s.planner_timeouts));
  add("setpoint_waits", double(s.setpoint_waits));
  add("setpoint_timeouts", double(s.setpoint_timeouts));
  status_pub_.publish(status);
  if (config_.publish_clock && factor < 0.8 * config_.realtime_factor)
    ROS_WARN(
        "quadrotor_sim: the simulation runs at %.2f x real time, below the %.2f asked (loaded machine or a slow "
        "controller under lockstep)",
        factor, config_.realtime_factor);
}

}  // namespace topo_planner
