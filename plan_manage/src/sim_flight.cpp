#include "topo_planner/plan_manage/sim_flight.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <memory>
#include <sstream>

#include "topo_planner/plan_manage/planner_params.h"
#include "topo_planner/plan_manage/yaml_params.h"

namespace topo_planner {

Eigen::Isometry3d SimFlight::Config::defaultBodyToCamera() {
  // Optical frame (x right, y down, z forward) in a FLU body: z_c = x_b, x_c = -y_b, y_c = -z_b.
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  T.linear() << 0, 0, 1, -1, 0, 0, 0, -1, 0;
  return T;
}

bool SimFlight::Config::validate(std::string* why) const {
  std::ostringstream e;
  std::string sub;
  if (!fsm.validate(&sub)) e << "fsm: " << sub << "; ";
  if (!server.validate(&sub)) e << "server: " << sub << "; ";
  if (!map.validate(&sub)) e << "map: " << sub << "; ";
  if (!esdf.validate(&sub)) e << "esdf: " << sub << "; ";
  if (!camera.camera.valid()) e << "camera intrinsics invalid; ";
  if (!speed.validate(&sub)) e << "speed: " << sub << "; ";
  if (!oracle.validate(&sub)) e << "oracle: " << sub << "; ";
  auto positive = [&](double x, const char* name) {
    if (!(std::isfinite(x) && x > 0.0)) e << name << " must be positive; ";
  };
  positive(camera_rate_hz, "camera_rate_hz");
  positive(plan_period_s, "plan_period_s");
  positive(server_period_s, "server_period_s");
  positive(goal_tolerance_m, "goal_tolerance_m");
  positive(goal_timeout_s, "goal_timeout_s");
  if (!(start_delay_s >= 0.0 && std::isfinite(start_delay_s))) e << "start_delay_s must be >= 0; ";
  if (!(plan_period_s >= server_period_s)) e << "plan_period_s must be at least server_period_s; ";
  if (!T_body_camera.matrix().allFinite()) e << "T_body_camera must be finite; ";
  const std::string s = e.str();
  if (why) *why = s.empty() ? "" : s.substr(0, s.size() - 2);
  return s.empty();
}

namespace {

Eigen::Isometry3d bodyPose(const Eigen::Vector3d& p, double yaw) {
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  T.linear() = Eigen::AngleAxisd(yaw, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  T.translation() = p;
  return T;
}

SpeedAccount::Mode accountMode(Setpoint::Mode m) {
  switch (m) {
    case Setpoint::Mode::kTrajectory: return SpeedAccount::Mode::kTrajectory;
    case Setpoint::Mode::kEndStop:
    case Setpoint::Mode::kWatchdogStop: return SpeedAccount::Mode::kStopping;
    default: return SpeedAccount::Mode::kHold;
  }
}

}  // namespace

SimFlight::Result SimFlight::fly(const TruthMap& truth, const Eigen::Vector3d& start,
                                 const std::vector<Eigen::Vector3d>& goals, const Config& config,
                                 const Observer& observer) {
  Result r;
  std::string why;
  if (!config.validate(&why)) {
    r.message = "invalid config: " + why;
    return r;
  }
  if (goals.empty() || !start.allFinite()) {
    r.message = "no goals, or a non-finite start";
    return r;
  }
  auto occupancy = std::shared_ptr<OccupancyMap>(OccupancyMap::create(config.map, &why));
  if (!occupancy) {
    r.message = "map: " + why;
    return r;
  }
  std::unique_ptr<EsdfMap> esdf = EsdfMap::create(config.esdf, occupancy, &why);
  std::unique_ptr<ReplanFsm> fsm = ReplanFsm::create(config.fsm, &why);
  if (!esdf || !fsm) {
    r.message = "planner: " + why;
    return r;
  }
  esdf->updateAll();
  if (config.plan_observer) fsm->setPlanObserver(config.plan_observer);
  SetpointGenerator server(config.server);
  DepthCamera camera(config.camera, truth.esdf());
  SpeedAccount account(config.speed);
  ContactCounter contacts(config.collision_radius_m, 0.05);
  const uint64_t session = 1;

  r.goals.resize(goals.size());
  for (size_t i = 0; i < goals.size(); ++i) r.goals[i].position = goals[i];
  if (config.compute_oracle) {
    const FlightOracle::Result oracle =
        FlightOracle::computeInWindow(truth.occupancy(), config.map.origin_m, config.map.size_m, start, goals, config.oracle);
    if (oracle.ok)
      for (size_t i = 0; i < goals.size(); ++i) r.goals[i].oracle_time_s = oracle.time_s[i];
  }

  // The vehicle: where its setpoint is, at rest at the start until the first trajectory.
  Eigen::Vector3d position = start, velocity = Eigen::Vector3d::Zero();
  double yaw = std::atan2(goals[0].y() - start.y(), goals[0].x() - start.x());
  server.setVehiclePose(position, yaw);
  const double dt = config.server_period_s;
  const int plan_every = std::max(1, int(std::lround(config.plan_period_s / dt)));
  const double frame_period = 1.0 / config.camera_rate_hz;
  double next_frame_s = 0.0;
  std::vector<float> depth;
  size_t active = 0;
  bool goal_given = false;
  double goal_given_s = 0.0, flight_start_s = NAN;
  double speed_integral = 0.0;
  Setpoint previous_setpoint;
  double previous_setpoint_s = 0.0;  // when the server sampled it (the stamp the node's message carries)
  bool have_setpoint = false;

  for (long k = 0;; ++k) {
    const double t = k * dt;
    // The camera: a frame from where the vehicle is, fused as the mapping node fuses it.
    if (t + 1e-9 >= next_frame_s) {
      next_frame_s += frame_period;
      const Eigen::Isometry3d T_world_camera = bodyPose(position, yaw) * config.T_body_camera;
      if (camera.render(T_world_camera, &depth)) {
        DepthImageView view;
        view.data = reinterpret_cast<const uint8_t*>(depth.data());
        view.width = config.camera.camera.width;
        view.height = config.camera.camera.height;
        view.row_step_bytes = size_t(view.width) * sizeof(float);
        view.encoding = DepthEncoding::kFloat32;
        const FusionResult fused = occupancy->fuseDepthImage(view, config.camera.camera, T_world_camera);
        if (fused.status == MapStatus::kSuccess) {
          esdf->update(fused.changed_box);
          fsm->setDepthFused(t);
        }
      }
    }
    // The mission: the next goal once the camera has looked for start_delay_s, and after each goal.
    if (!goal_given && t >= config.start_delay_s) {
      if (std::isnan(flight_start_s)) flight_start_s = t;
      fsm->setOdometry(t, position, velocity);
      const GoalStatus status = fsm->setGoals({goals[active]}, *esdf);
      if (status != GoalStatus::kAccepted) {
        r.message = "goal " + std::to_string(active + 1) + " refused: " + toString(status);
        break;
      }
      goal_given = true;
      goal_given_s = t;
    }
    // The planner: odometry and the server's setpoint in, the safety check and the tick.
    const FsmOutput* last_output = nullptr;
    const ExecTrajectory* published = nullptr;
    FsmOutput outputs[2];
    if (k % plan_every == 0) {
      fsm->setOdometry(t, position, velocity);
      if (have_setpoint) {
        ServerSetpoint sp;
        sp.stamp_s = previous_setpoint_s;
        sp.position = previous_setpoint.state.position;
        sp.velocity = previous_setpoint.state.velocity;
        switch (previous_setpoint.mode) {
          case Setpoint::Mode::kHoldBeforeFirst: sp.mode = ServerSetpoint::Mode::kBeforeFirst; break;
          case Setpoint::Mode::kTrajectory: sp.mode = ServerSetpoint::Mode::kTrajectory; break;
          case Setpoint::Mode::kEndStop:
          case Setpoint::Mode::kWatchdogStop: sp.mode = ServerSetpoint::Mode::kStopping; break;
          case Setpoint::Mode::kHold: sp.mode = ServerSetpoint::Mode::kHold; break;
        }
        sp.own_session = previous_setpoint.planner_session == session;
        sp.trajectory_id = previous_setpoint.trajectory_id;
        fsm->setServerSetpoint(sp);
      }
      outputs[0] = fsm->checkSafety(t, *esdf);
      const auto t0 = std::chrono::steady_clock::now();
      outputs[1] = fsm->tick(t, *esdf);
      const double ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
      for (FsmOutput& out : outputs) {
        if (out.event) {
          (out.event->published ? r.replans : r.replan_failures) += 1;
          r.replan_ms.push_back(&out == &outputs[1] ? ms : 0.0);
          r.planner_ms.push_back(out.event->stats.total_ms);
          if (&out == &outputs[1] && ms >= 5.0) {
            r.slow_calls.push_back(*out.event);
            r.slow_calls.back().stats.total_ms = ms;  // the tick's
          }
        }
        if (out.trajectory) {
          const ExecTrajectory& traj = *out.trajectory;
          server.add(session, traj.id, traj.start_time_s, traj.spline,
                     traj.has_heading_target ? std::optional<Eigen::Vector3d>(traj.heading_target) : std::nullopt,
                     traj.reanchor);
          SpeedAccount::Trajectory a;
          a.session = session;
          a.id = traj.id;
          a.start_s = traj.start_time_s;
          a.brake_start_s = std::min(traj.brake_start_s, traj.endTime());
          a.kind = traj.braking ? SpeedAccount::TrajectoryKind::kBraking
                   : traj.escape ? SpeedAccount::TrajectoryKind::kManoeuvre
                                 : SpeedAccount::TrajectoryKind::kPlan;
          a.spline = traj.spline;
          account.addTrajectory(a);
          r.emergency_stops += traj.braking ? 1 : 0;
          published = &traj;
        }
        if (out.new_reference) {
          const PolynomialTrajectory ref = fsm->reference();
          char text[160];
          std::snprintf(text, sizeof(text), "; reference of %.2f s, %zu segments, max speed %.2f m/s", ref.duration(),
                        ref.segments().size(), ref.maxSpeed(0.05));
          out.message += text;
        }
        if (out.event || out.trajectory || !out.message.empty()) last_output = &out;
      }
      if (!outputs[0].server_diverged && !outputs[1].server_diverged) server.noteHeartbeat(t);
    }
    // The trajectory server, and the vehicle on its setpoint.
    Setpoint sp;
    if (server.sample(t, &sp)) {
      if (have_setpoint) {
        const double step = (sp.state.position - previous_setpoint.state.position).norm() -
                            std::max(sp.state.velocity.norm(), previous_setpoint.state.velocity.norm()) * dt;
        r.max_setpoint_step_m = std::max(r.max_setpoint_step_m, step);
      }
      const double v = sp.state.velocity.norm();
      if (v > 0.1 && sp.state.acceleration.dot(sp.state.velocity) / v < -(config.fsm.max_brake_acc_mps2 + 0.5))
        ++r.max_decel_events;
      position = sp.state.position;
      velocity = sp.state.velocity;
      yaw = sp.yaw;
      previous_setpoint = sp;
      previous_setpoint_s = t;
      have_setpoint = true;
      SpeedAccount::Setpoint as;
      as.mode = accountMode(sp.mode);
      as.session = sp.planner_session;
      as.trajectory_id = sp.trajectory_id;
      as.velocity = sp.state.velocity;
      as.acceleration = sp.state.acceleration;
      account.setSetpoint(as);
    }
    // The referee: contacts with the true map, speed, goals.
    const double clearance = std::min(truth.obstacleDistance(position, 1.0), position.z() - config.ground_z_m);
    r.min_clearance_m = std::min(r.min_clearance_m, clearance);
    if (contacts.update(clearance) && goal_given) ++r.collisions;
    const double speed = velocity.norm();
    if (!std::isnan(flight_start_s)) {
      account.addSpeed(t, speed);
      if (k > 0) {
        speed_integral += speed * dt;
        r.path_length_m += speed * dt;
      }
      r.max_speed_mps = std::max(r.max_speed_mps, speed);
    }
    if (observer) {
      Step s;
      s.t_s = t;
      s.setpoint = previous_setpoint;
      s.clearance_m = clearance;
      s.output = last_output;
      s.published = published;
      observer(s);
    }
    if (goal_given) {
      Goal& g = r.goals[active];
      g.time_s = t - goal_given_s;
      if ((position - g.position).norm() <= config.goal_tolerance_m && speed <= config.goal_max_speed_mps) {
        g.reached = true;
        ++r.goals_reached;
        goal_given = false;
        if (++active == goals.size()) break;
        continue;
      }
      if (g.time_s > config.goal_timeout_s) {
        r.message = "goal " + std::to_string(active + 1) + " not reached in " + std::to_string(int(config.goal_timeout_s)) +
                    " s (" + std::to_string((position - g.position).norm()) + " m away)";
        break;
      }
    }
    r.duration_s = std::isnan(flight_start_s) ? 0.0 : t - flight_start_s;
  }
  r.speed = account.totals();
  r.fast_share = r.speed.total_s > 0.0 ? r.speed.fast_s / r.speed.total_s : 0.0;
  r.mean_speed_mps = r.duration_s > 0.0 ? speed_integral / r.duration_s : 0.0;
  double oracle = 0.0, flown = 0.0;
  bool known = true;
  for (const Goal& g : r.goals)
    if (g.reached) {
      oracle += g.oracle_time_s;
      flown += g.time_s;
      known = known && std::isfinite(g.oracle_time_s);
    }
  if (r.goals_reached > 0 && known && oracle > 0.0) {
    r.oracle_time_s = oracle;
    r.reached_time_s = flown;
    r.time_ratio = flown / oracle;
  }
  r.ok = r.goals_reached == int(goals.size()) && r.collisions == 0;
  if (r.message.empty()) r.message = r.ok ? "every goal reached, no contact" : std::to_string(r.collisions) + " contacts";
  return r;
}

bool loadSimFlightConfig(const std::string& config_dir, double max_vel_mps, double max_acc_mps2, bool realistic,
                         SimFlight::Config* config, std::string* why,
                         const std::vector<std::pair<std::string, std::string>>& planner_overrides) {
  const double max_vel = max_vel_mps, max_acc = max_acc_mps2;
  SimFlight::Config& c = *config;
  std::optional<YamlParams> planner = YamlParams::load(config_dir + "/planner.yaml", why);
  if (!planner) return false;
  for (const auto& [name, value] : planner_overrides)
    if (!planner->set(name, value)) {
      *why = "cannot set " + name + " to " + value;
      return false;
    }
  double ratio = 0.75;
  readFsmParams(*planner, &c.fsm, &ratio);
  setFlightLimits(max_vel, max_acc, ratio, &c.fsm);
  c.fsm.brake_acc_mps2 = std::min(c.fsm.brake_acc_mps2, max_acc);
  c.fsm.replanner.search.roadmap.max_time_s = 0.0;  // budgets by count: deterministic
  c.fsm.replanner.optimizer.max_time_s = 0.0;
  if (!planner->errors().str().empty()) {
    *why = "config/planner.yaml: " + planner->errors().str();
    return false;
  }
  // The mapping (config/mapping.yaml) in the flight's window; the camera (config/depth_camera.yaml).
  std::optional<YamlParams> mapping = YamlParams::load(config_dir + "/mapping.yaml", why);
  std::optional<YamlParams> camera = YamlParams::load(config_dir + "/depth_camera.yaml", why);
  std::optional<YamlParams> server = YamlParams::load(config_dir + "/traj_server.yaml", why);
  if (!mapping || !camera || !server) return false;
  mapping->read("map/resolution_m", c.map.resolution_m);
  mapping->read("map/prob_hit", c.map.prob_hit);
  mapping->read("map/prob_miss", c.map.prob_miss);
  mapping->read("map/prob_min", c.map.prob_min);
  mapping->read("map/prob_max", c.map.prob_max);
  mapping->read("map/prob_occupied", c.map.prob_occupied);
  mapping->read("map/min_ray_length_m", c.map.min_ray_length_m);
  mapping->read("map/max_ray_length_m", c.map.max_ray_length_m);
  if (!planner->has("fsm/sensing_range_m")) c.fsm.sensing_range_m = c.map.max_ray_length_m;  // as the planner node
  mapping->read("map/depth_pixel_skip", c.map.depth_pixel_skip);
  mapping->read("map/merge_rays", c.map.merge_rays);
  mapping->read("map/project_free_space", c.map.project_free_space);
  mapping->read("esdf/max_distance_m", c.esdf.max_distance_m);
  mapping->read("esdf/inflate_radius_m", c.esdf.inflate_radius_m);
  mapping->read("esdf/num_threads", c.esdf.num_threads);
  camera->read("camera/width", c.camera.camera.width);
  camera->read("camera/height", c.camera.camera.height);
  camera->read("camera/fx", c.camera.camera.fx);
  camera->read("camera/fy", c.camera.camera.fy);
  camera->read("camera/cx", c.camera.camera.cx);
  camera->read("camera/cy", c.camera.camera.cy);
  camera->read("min_range_m", c.camera.min_range_m);
  camera->read("max_range_m", c.camera.max_range_m);
  camera->read("rate_hz", c.camera_rate_hz);
  if (realistic) {  // launch/simulator.launch's depth noise and holes
    c.camera.noise_stddev_at_1m = 0.005;
    c.camera.invalid_fraction = 0.05;
  }
  server->read("max_yaw_rate_radps", c.server.max_yaw_rate_radps);
  server->read("yaw_lookahead_s", c.server.lookahead_s);
  server->read("yaw_min_displacement_m", c.server.min_displacement_m);
  server->read("heartbeat_timeout_s", c.server.heartbeat_timeout_s);
  server->read("stop_acc_mps2", c.server.stop_acc_mps2);
  server->read("stop_jerk_mps3", c.server.stop_jerk_mps3);
  server->read("max_takeover_gap_m", c.server.max_takeover_gap_m);
  server->read("max_takeover_velocity_gap_mps", c.server.max_takeover_velocity_gap_mps);
  c.speed.max_vel_mps = c.oracle.max_vel_mps = max_vel;
  c.speed.max_acc_mps2 = c.oracle.max_acc_mps2 = max_acc;
  c.oracle.clearance_m = c.fsm.replanner.search.clearance_m;
  c.oracle.min_z_m = c.fsm.route.min_z_m;
  c.oracle.max_z_m = c.fsm.route.max_z_m;

  return config->validate(why);
}

std::string formatSimFlight(const SimFlight::Result& r) {
  char text[512];
  std::snprintf(text, sizeof(text),
                "goals %d/%zu, collisions %d, min clearance %.2f m, %.1f s (oracle %.1f s, %.2fx), mean %.2f m/s, "
                "max %.2f m/s, %.0f%% fast, replans %d (%d failed), stops %d",
                r.goals_reached, r.goals.size(), r.collisions, r.min_clearance_m, r.reached_time_s, r.oracle_time_s,
                r.time_ratio, r.mean_speed_mps, r.max_speed_mps, 100.0 * r.fast_share, r.replans, r.replan_failures,
                r.emergency_stops);
  return text;
}

}  // namespace topo_planner
