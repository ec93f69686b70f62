#include "topo_planner/topo_replan/replan_fsm.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <utility>

#include "topo_planner/bspline_opt/bspline_costs.h"

namespace topo_planner {

const char* toString(FsmState state) {
  switch (state) {
    case FsmState::kInit: return "INIT";
    case FsmState::kWaitTarget: return "WAIT_TARGET";
    case FsmState::kGenNewTraj: return "GEN_NEW_TRAJ";
    case FsmState::kExecTraj: return "EXEC_TRAJ";
    case FsmState::kReplanTraj: return "REPLAN_TRAJ";
    case FsmState::kEmergencyStop: return "EMERGENCY_STOP";
  }
  return "unknown";
}

const char* toString(GoalStatus status) {
  switch (status) {
    case GoalStatus::kAccepted: return "kAccepted";
    case GoalStatus::kNoOdometry: return "kNoOdometry";
    case GoalStatus::kInvalidInput: return "kInvalidInput";
    case GoalStatus::kGoalInObstacle: return "kGoalInObstacle";
    case GoalStatus::kGoalOutOfMap: return "kGoalOutOfMap";
    case GoalStatus::kReferenceFailed: return "kReferenceFailed";
    case GoalStatus::kInputsStale: return "kInputsStale";
    case GoalStatus::kUnreachable: return "kUnreachable";
    case GoalStatus::kGivenUp: return "kGivenUp";
  }
  return "unknown";
}

const char* toString(FsmEvent::Trigger trigger) {
  switch (trigger) {
    case FsmEvent::Trigger::kNewGoal: return "new_goal";
    case FsmEvent::Trigger::kCollisionAhead: return "collision_ahead";
    case FsmEvent::Trigger::kPeriodic: return "periodic";
    case FsmEvent::Trigger::kRetry: return "retry";
    case FsmEvent::Trigger::kEmergency: return "emergency";
    case FsmEvent::Trigger::kTimeJump: return "time_jump";
    case FsmEvent::Trigger::kReroute: return "reroute";
  }
  return "unknown";
}

std::unique_ptr<ReplanFsm> ReplanFsm::create(const Config& config, std::string* error) {
  std::string why;
  if (!config.validate(&why)) {
    if (error) *error = "invalid FSM config: " + why;
    return nullptr;
  }
  std::unique_ptr<TopoReplanner> replanner = TopoReplanner::create(replannerConfig(config), error);
  if (!replanner) return nullptr;
  return std::unique_ptr<ReplanFsm>(new ReplanFsm(config, std::move(replanner)));
}

namespace {
// The route search that may leave a narrow passage around the vehicle (routeLocked).
GlobalRouter::Config startRouterConfig(const ReplanFsm::Config& config) {
  GlobalRouter::Config c = config.route;
  c.start_radius_m = std::max(c.start_radius_m, config.max_backoff_length_m + 1.0);
  return c;
}
}  // namespace

ReplanFsm::ReplanFsm(const Config& config, std::unique_ptr<TopoReplanner> replanner)
    : config_(config),
      replanner_(std::move(replanner)),
      inputs_(inputMonitorConfig(config)),
      server_(serverLinkConfig(config)),
      router_(std::make_unique<GlobalRouter>(config.route)),
      start_router_(std::make_unique<GlobalRouter>(startRouterConfig(config))),
      route_watch_(routeWatchConfig(config)),
      remedies_(remediesConfig(config)),
      takeover_delay_s_(config.takeover_delay_s) {}

ReplanFsm::Config ReplanFsm::config() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return config_;
}

bool ReplanFsm::reconfigure(const Config& config, std::string* why) {
  std::string reason;
  if (!config.validate(&reason)) {
    if (why) *why = "invalid settings: " + reason;
    return false;
  }
  std::lock_guard<std::mutex> lock(mutex_);
  pending_config_ = config;
  return true;
}

void ReplanFsm::applyPendingConfigLocked(FsmOutput* out) {
  if (!pending_config_) return;
  std::string error;
  std::unique_ptr<TopoReplanner> replanner = TopoReplanner::create(replannerConfig(*pending_config_), &error);
  if (!out->message.empty()) out->message += "; ";
  if (replanner) {
    config_ = *pending_config_;
    replanner_ = std::move(replanner);
    router_ = std::make_unique<GlobalRouter>(config_.route);
    start_router_ = std::make_unique<GlobalRouter>(startRouterConfig(config_));
    inputs_.setConfig(inputMonitorConfig(config_));
    server_.setConfig(serverLinkConfig(config_));
    route_watch_.setConfig(routeWatchConfig(config_));
    remedies_.setConfig(remediesConfig(config_));
    takeover_delay_s_ = std::max(takeover_delay_s_, config_.takeover_delay_s);
    route_stale_ = true;  // its clearance may have changed: searched again at the next reference
    out->message += "new settings applied";
  } else {
    out->message += "new settings not applied: " + error;
  }
  pending_config_.reset();
}

FsmState ReplanFsm::state() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return state_;
}

GoalStatus ReplanFsm::lastGoalStatus() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return last_goal_status_;
}

std::optional<ExecTrajectory> ReplanFsm::current() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return current_;
}

PolynomialTrajectory ReplanFsm::reference() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return reference_;
}

bool ReplanFsm::setOdometry(double t, const Eigen::Vector3d& position, const Eigen::Vector3d& velocity,
                            double arrival_s, std::string* why) {
  if (std::isnan(arrival_s)) arrival_s = t;
  if (!std::isfinite(t) || !std::isfinite(arrival_s) || !position.allFinite() || !velocity.allFinite()) {
    if (why) *why = "NaN/inf values";
    return false;
  }
  std::lock_guard<std::mutex> lock(mutex_);
  FsmOutput ignored;
  observeClockLocked(arrival_s, &ignored);  // a time jump shifts the last odometry stamp before the order check
  if (!inputs_.acceptOdometry(t, arrival_s, why)) return false;
  odom_position_ = position;
  odom_velocity_ = velocity;
  // Intermediate goals the vehicle came close to are done (the last one ends the mission in tick()).
  while (next_goal_ + 1 < goals_.size() && (position - goals_[next_goal_]).norm() <= config_.waypoint_reached_radius_m)
    ++next_goal_;
  return true;
}

bool ReplanFsm::setServerSetpoint(const ServerSetpoint& setpoint) {
  std::lock_guard<std::mutex> lock(mutex_);
  return server_.set(setpoint);
}

bool ReplanFsm::followServerLocked(double t, const EsdfMap& map, FsmOutput* out) {
  const ServerLink::Verdict v = server_.judge(t, current_ ? &*current_ : nullptr, previous_ ? &*previous_ : nullptr,
                                              [this](double s) { return takeoverStateLocked(s); });
  switch (v.kind) {
    case ServerLink::Verdict::Kind::kFollows:
      if (v.resync_s != 0.0) {
        for (std::optional<ExecTrajectory>* traj : {&current_, &previous_})
          if (*traj) {
            (*traj)->start_time_s -= v.resync_s;
            (*traj)->brake_start_s -= v.resync_s;
          }
        char text[160];
        std::snprintf(text, sizeof(text), "timing re-synchronised with the trajectory server by %+.3f s", -v.resync_s);
        if (!out->message.empty()) out->message += "; ";
        out->message += text;
      }
      return false;
    case ServerLink::Verdict::Kind::kDiverged:
      out->server_diverged = true;
      if (v.first_report) {
        if (!out->message.empty()) out->message += "; ";
        out->message += "the trajectory server does not follow the commanded trajectory (" + v.why +
                        "): waiting for its hold (no heartbeat meanwhile, so its watchdog stops the vehicle)";
      }
      return true;
    case ServerLink::Verdict::Kind::kHolds:
      break;
  }
  // At its hold: that is the commanded state now. Hold there (a trajectory at rest, continuous with
  // the server's setpoint) and replan from it (EMERGENCY_STOP: from rest through the goals left).
  out->server_diverged = true;
  server_.anchored(t);
  const FlatState hold = FlatState::atRest(v.hold);
  emergencyStopLocked(t, map, "the trajectory server holds on its own (" + v.why + "): holding there", out, &hold,
                      ReplanStatus::kInvalidInput);
  return true;
}

int ReplanFsm::serverResyncs() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return server_.resyncs();
}

void ReplanFsm::setDepthFused(double stamp_s, double arrival_s) {
  if (std::isnan(arrival_s)) arrival_s = stamp_s;
  if (!std::isfinite(stamp_s) || !std::isfinite(arrival_s)) return;
  std::lock_guard<std::mutex> lock(mutex_);
  inputs_.depthFused(stamp_s, arrival_s);
}

InputHealth ReplanFsm::inputHealth(double t) const {
  std::lock_guard<std::mutex> lock(mutex_);
  return inputs_.health(t);
}

void ReplanFsm::observeClockLocked(double now, FsmOutput* out) {
  const std::optional<InputMonitor::TimeJump> jump = inputs_.observeClock(now);
  if (!jump) return;
  // A time jump: everything stamped on the old clock moves with it, so the commanded motion goes
  // on where it was (the trajectory server shifts its copy the same way).
  const double shift = jump->shift_s;
  for (std::optional<ExecTrajectory>* traj : {&current_, &previous_})
    if (*traj) {
      (*traj)->start_time_s += shift;
      (*traj)->brake_start_s += shift;
    }
  server_.shift(*jump);
  remedies_.shift(shift);  // its times are read from this clock
  progress_.shift(shift);
  progress_tick_s_ += shift;
  rest_retry_after_s_ += shift;    // the paced retries keep their pace
  moving_retry_after_s_ += shift;
  time_jumped_ = true;
  time_jump_clock_s_ = now;
  if (!out->message.empty()) out->message += "; ";
  char text[128];
  std::snprintf(text, sizeof(text), "time jump of %+.3f s: timing shifted by %+.3f s, replanning from the current state",
                jump->step_s, shift);
  out->message += text;
}

int ReplanFsm::timeJumps() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return inputs_.timeJumps();
}

std::vector<Eigen::Vector3d> ReplanFsm::remainingGoalsLocked() const {
  if (next_goal_ >= goals_.size()) return goals_.empty() ? goals_ : std::vector<Eigen::Vector3d>{goals_.back()};
  return std::vector<Eigen::Vector3d>(goals_.begin() + long(next_goal_), goals_.end());
}

std::vector<Eigen::Vector3d> ReplanFsm::remainingGoals() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return remainingGoalsLocked();
}

Path ReplanFsm::route() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return route_;
}

GoalStatus ReplanFsm::setGoals(const std::vector<Eigen::Vector3d>& goals) {
  std::lock_guard<std::mutex> lock(mutex_);
  return acceptGoalsLocked(goals);
}

GoalStatus ReplanFsm::setGoals(const std::vector<Eigen::Vector3d>& goals, const EsdfMap& map) {
  std::lock_guard<std::mutex> lock(mutex_);
  bool finite = !goals.empty();
  for (const Eigen::Vector3d& g : goals) finite = finite && g.allFinite();
  std::string why;
  const GoalStatus on_map = finite ? checkGoalsLocked(goals, map, &why) : GoalStatus::kAccepted;
  if (on_map != GoalStatus::kAccepted) return last_goal_status_ = on_map;
  return acceptGoalsLocked(goals);
}

GoalStatus ReplanFsm::checkGoalsLocked(const std::vector<Eigen::Vector3d>& goals, const EsdfMap& map,
                                       std::string* why) const {
  for (size_t i = 0; i < goals.size(); ++i) {
    const DistanceQuery q = map.query(goals[i]);
    if (q.status == QueryStatus::kOutOfMap || q.status == QueryStatus::kInvalidInput) {
      *why = "goal " + std::to_string(i) + " is outside the map";
      return GoalStatus::kGoalOutOfMap;
    }
    if (q.distance < config_.goal_clearance_m) {
      *why = "goal " + std::to_string(i) + " is " + std::to_string(q.distance) + " m from an obstacle";
      return GoalStatus::kGoalInObstacle;
    }
  }
  return GoalStatus::kAccepted;
}

GoalStatus ReplanFsm::acceptGoalsLocked(const std::vector<Eigen::Vector3d>& goals) {
  if (goals.empty()) return last_goal_status_ = GoalStatus::kInvalidInput;
  for (const Eigen::Vector3d& g : goals)
    if (!g.allFinite()) return last_goal_status_ = GoalStatus::kInvalidInput;
  if (!inputs_.haveOdometry()) return last_goal_status_ = GoalStatus::kNoOdometry;
  std::string why;
  if (!inputs_.haveClock() || !inputs_.fresh(inputs_.clock(), &why)) return last_goal_status_ = GoalStatus::kInputsStale;
  // Refused here, not at the next tick: a flood of such goals (any host can publish them) would
  // otherwise replace valid goals not yet taken up, and clear the global route of the mission flown.
  if (map_geometry_)
    for (const Eigen::Vector3d& g : goals)
      if (!map_geometry_->inWindow(g)) return last_goal_status_ = GoalStatus::kGoalOutOfMap;
  pending_goals_ = goals;
  goals_pending_ = true;
  new_mission_ = true;
  rerouting_ = false;
  remedies_.goalsGiven();
  route_stale_ = true;
  ++route_epoch_;
  return GoalStatus::kAccepted;
}

void ReplanFsm::setState(FsmState s, FsmOutput* out, const std::string& why) {
  if (s == state_) return;
  if (!out->message.empty()) out->message += "; ";
  out->message += std::string(toString(state_)) + " -> " + toString(s) + (why.empty() ? "" : " (" + why + ")");
  state_ = s;
}

void ReplanFsm::replaceCurrentLocked(const ExecTrajectory& next) {
  // The one it replaces is still flown until the new one's start time (a planned trajectory takes
  // over takeover_delay_s after planning began): the state before then is on it.
  if (current_) previous_ = current_;
  current_ = next;
}

const ExecTrajectory* ReplanFsm::flownAtLocked(double t) const {
  if (!current_) return nullptr;
  // Before the current one's start, the one it replaces: flown then, or (t a rounding error before
  // its own start: 26.15 + 0.1 > 26.25) about to be. The current one, clamped to its later start,
  // would put the state where the vehicle is only later (a stop from there stepped the setpoint).
  if (previous_ && t < current_->start_time_s) return &*previous_;
  return &*current_;
}

FlatState ReplanFsm::takeoverStateLocked(double t_takeover) const {
  if (!current_) {
    // Not commanded yet: the trajectory server holds (a restarted planner: where its stop ended), or
    // the controller holds the position where it started.
    if (const std::optional<Eigen::Vector3d> hold = server_.holdAt(t_takeover)) return FlatState::atRest(*hold);
    return FlatState::atRest(odom_position_);
  }
  const ExecTrajectory& flown = *flownAtLocked(t_takeover);
  const UniformBspline& s = flown.spline;
  const double tau = std::clamp(t_takeover - flown.start_time_s, 0.0, s.duration());
  FlatState st;
  st.position = s.evaluate(tau);
  const UniformBspline vel = s.derivative();
  st.velocity = vel.evaluate(tau);
  if (vel.degree() >= 1) {
    const UniformBspline acc = vel.derivative();
    st.acceleration = acc.evaluate(tau);
    if (acc.degree() >= 1) st.jerk = acc.derivative().evaluate(tau);
  }
  if (tau >= s.duration()) st.velocity = st.acceleration = st.jerk = Eigen::Vector3d::Zero();
  return st;
}

double ReplanFsm::referenceTimeAtLocked(double t) const {
  if (!current_ || current_->manoeuvre()) return 0.0;
  const double d = current_->spline.duration();
  const double frac = d > 0.0 ? std::clamp((t - current_->start_time_s) / d, 0.0, 1.0) : 1.0;
  const double estimate = current_->reference_start_s + frac * (current_->reference_end_s - current_->reference_start_s);
  // The local trajectory is timed differently from the reference (detours, time reallocation): take
  // the reference point closest to where the vehicle will be, near the proportional estimate.
  const Eigen::Vector3d p = current_->spline.evaluate(std::clamp(t - current_->start_time_s, 0.0, d));
  double best = estimate, best_d2 = (reference_.position(estimate) - p).squaredNorm();
  for (double s = std::max(0.0, estimate - 2.0); s <= std::min(reference_.duration(), estimate + 2.0); s += 0.01) {
    const double d2 = (reference_.position(s) - p).squaredNorm();
    if (d2 < best_d2) best = s, best_d2 = d2;
  }
  return best;
}

double ReplanFsm::stopTimeLocked(double t, double deceleration) const {
  return takeoverStateLocked(t).velocity.norm() / deceleration + config_.emergency_margin_s + takeover_delay_s_;
}

ExecTrajectory ReplanFsm::brakingTrajectoryLocked(double t, const EsdfMap& map, std::string* report,
                                                  const FlatState* from) const {
  FlatState s0 = from ? *from : takeoverStateLocked(t);
  if (!current_ && !from) s0.velocity = odom_velocity_;
  // Along the trajectory flown at t (a plan waiting for its takeover is not flown yet). From another
  // state (a re-anchoring after an odometry jump), along its velocity and never harder than
  // brake_acc_mps2: the map is in the old frame.
  return brakingTrajectory(s0, from ? nullptr : flownAtLocked(t), t, map, manoeuvreConfig(config_), !from, report);
}

ReferenceConfig ReplanFsm::referenceConfigLocked() const {
  ReferenceConfig r = config_.reference;
  r.max_vel_mps = std::min(r.max_vel_mps, cruiseSpeed(config_));
  return r;
}

bool ReplanFsm::commitToKnownSpace(const UniformBspline& plan, double t0, const EsdfMap& map, ExecTrajectory* traj,
                                   std::string* why) const {
  KnownSpaceCommitment::Committed c;
  if (!KnownSpaceCommitment(commitmentConfig(config_)).commit(plan, map, known_anchor_, &c, why)) return false;
  traj->spline = std::move(c.spline);
  traj->brake_start_s = t0 + c.brake_start_tau_s;
  traj->stops_before_unknown = c.stops_before_unknown;
  traj->has_heading_target = c.heading_target.has_value();
  if (c.heading_target) traj->heading_target = *c.heading_target;
  return true;
}

void ReplanFsm::referenceNotRebuiltLocked(double t, const EsdfMap& map, FsmOutput* out) {
  if (last_goal_status_ != GoalStatus::kReferenceFailed) {
    // The map shows a goal of the mission in an obstacle (or out of the map window): it ends, saying why.
    giveUpLocked(t, map, last_goal_status_, ReplanStatus::kGoalInCollision,
                 std::string("the mission's goals are no longer valid (") + toString(last_goal_status_) + ")", out);
    return;
  }
  // The minimum-snap reference could not be built from the state it starts from (its limits, from a
  // fast or turning state): the goals are still valid. A moving vehicle stops and rebuilds it from
  // rest; at rest it is tried again at the next tick (the mission's time limit bounds the tries).
  last_goal_status_ = GoalStatus::kAccepted;
  const bool moving = current_ && !current_->manoeuvre() && t < current_->endTime();
  if (moving) {
    emergencyStopLocked(t, map, "the mission's reference could not be rebuilt from the moving state: stopping to "
                        "rebuild it from rest", out, nullptr, ReplanStatus::kInvalidInput);
    return;
  }
  remedies_.planFailed();
  if (state_ != FsmState::kGenNewTraj && state_ != FsmState::kEmergencyStop)
    setState(FsmState::kGenNewTraj, out, "the mission's reference could not be rebuilt: trying again");
}

void ReplanFsm::startManoeuvreLocked(ExecTrajectory manoeuvre, bool backoff, FsmEvent* event, FsmOutput* out,
                                     const std::string& why) {
  if (backoff) {
    remedies_.backedOff();
    // The way back is used up: a later back-off goes on from where this one ends.
    const Eigen::Vector3d end = manoeuvre.spline.evaluate(manoeuvre.spline.duration());
    while (!flown_.empty() && (flown_.back() - end).norm() > 0.3) flown_.pop_back();
  }
  manoeuvre.id = next_id_++;
  replaceCurrentLocked(manoeuvre);
  remedies_.newStart();  // the tries after it are counted anew
  route_stale_ = true;   // searched again from where it ends
  ++route_epoch_;
  collision_ahead_ = false;
  event->published = true;
  event->fallback = backoff ? "back_off" : "escape";
  out->trajectory = manoeuvre;
  setState(FsmState::kEmergencyStop, out, why);
}

void ReplanFsm::addStallZoneLocked(const GlobalRouter::Zone& zone) {
  stall_zones_.push_back(zone);
  if (stall_zones_.size() > kMaxStallZones) stall_zones_.erase(stall_zones_.begin());
}

bool ReplanFsm::handleStallLocked(double t, const EsdfMap& map, FsmOutput* out) {
  const bool flying = state_ == FsmState::kGenNewTraj || state_ == FsmState::kExecTraj ||
                      state_ == FsmState::kReplanTraj || state_ == FsmState::kEmergencyStop;
  if (!config_.global_route || !(config_.progress_timeout_s > 0.0) || !progress_.active() || goals_.empty() || !flying)
    return false;
  const FlatState here = takeoverStateLocked(t);
  progress_.update(t, here.position);
  progress_tick_s_ = t;
  remedies_.progressMeasured(progress_.lastGain());  // progress: the remedies start over
  const bool at_rest = (!current_ || t >= current_->endTime()) && odom_velocity_.norm() < config_.stopped_speed_mps;
  FsmEvent event;
  event.trigger = FsmEvent::Trigger::kReroute;
  event.state = state_;
  event.status = ReplanStatus::kSuccess;
  event.position = here.position;
  std::string report;
  // A stop begun as a remedy has ended: back off from there.
  if (remedies_.backoffNowStopped(state_ == FsmState::kEmergencyStop && at_rest)) {
    std::optional<ExecTrajectory> backoff = backoffTrajectory(takeoverStateLocked(t), t, map, flown_, known_anchor_, manoeuvreConfig(config_), &report);
    if (backoff) {
      event.message = "no progress: " + report;
      startManoeuvreLocked(*backoff, true, &event, out, report);
      out->event = event;
      return true;
    }
    // None: the stopped vehicle plans anew from where it is (EMERGENCY_STOP's own rule).
    if (!out->message.empty()) out->message += "; ";
    out->message += report;
    return false;
  }
  const double since = progress_.sinceGain(t);
  char text[200];
  std::snprintf(text, sizeof(text), "no progress towards the goal for %.0f s (%.1f m left, %.1f m when it last gained)",
                since, progress_.remaining(), progress_.best());
  const bool manoeuvring = current_ && current_->manoeuvre() && t < current_->endTime();
  bool forced = false;
  const MissionRemedies::Stall stall = remedies_.stall(since, manoeuvring, goals_pending_, &forced);
  if (stall == MissionRemedies::Stall::kGiveUp) {
    char limit[220];
    std::snprintf(limit, sizeof(limit),
                  "no progress towards the goal for the mission's time limit of %.0f s (%.1f m left, %.1f m when it "
                  "last gained)", remedies_.missionLimit(), progress_.remaining(), progress_.best());
    giveUpLocked(t, map, GoalStatus::kGivenUp, ReplanStatus::kSuccess, limit, out);
    return true;
  }
  if (stall == MissionRemedies::Stall::kNone) return false;
  if (forced) {
    std::snprintf(text, sizeof(text), "%d plans failed at rest, no back-off left (%.1f m left)",
                  config_.max_plan_failures, progress_.remaining());
  }
  // A stall (counted): the next remedy. Every one marks the place for the route searches to avoid.
  // The zone lies ahead along the way, where the vehicle was heading (one around the vehicle alone
  // weighs on every way out of it alike).
  if (config_.stall_zone_radius_m > 0.0)
    addStallZoneLocked({progress_.ahead(config_.stall_zone_radius_m), config_.stall_zone_radius_m});
  route_stale_ = true;
  event.message = text;
  if (remedies_.stallBacksOff()) {
    if (!at_rest) {
      // Stop first (the back-off starts from rest), then back off (above).
      emergencyStopLocked(t, map, std::string(text) + ": stopping to back off", out, nullptr, ReplanStatus::kSuccess);
      out->event->trigger = FsmEvent::Trigger::kReroute;
      remedies_.stopThenBackOff();
      return true;
    }
    std::optional<ExecTrajectory> backoff = backoffTrajectory(takeoverStateLocked(t), t, map, flown_, known_anchor_, manoeuvreConfig(config_), &report);
    if (backoff) {
      event.message += "; " + report;
      startManoeuvreLocked(*backoff, true, &event, out, report);
      out->event = event;
      return true;
    }
    event.message += "; " + report;
  }
  // Re-route from where the vehicle is (at the next tick), around the places it stalled at.
  if (state_ == FsmState::kExecTraj || state_ == FsmState::kReplanTraj) {
    pending_goals_ = remainingGoalsLocked();
    goals_pending_ = !pending_goals_.empty();
    rerouting_ = goals_pending_;
  }
  event.fallback = "reroute";
  event.message += "; re-routing around where it stalled";
  out->event = event;
  if (!out->message.empty()) out->message += "; ";
  out->message += event.message;
  return true;
}

void ReplanFsm::giveUpLocked(double t, const EsdfMap& map, GoalStatus status, ReplanStatus replan_status,
                             const std::string& why, FsmOutput* out) {
  const std::string reason = "mission given up: " + why;
  last_goal_status_ = status;
  goals_.clear();
  next_goal_ = 0;
  if (rerouting_) goals_pending_ = false;  // the re-route of this mission; new goals (setGoals) stay pending
  rerouting_ = false;
  route_.clear();
  route_goals_.clear();
  route_watch_.reset(route_, map);
  remedies_.missionEnded();
  progress_.clear();
  const bool moving = current_ && !current_->braking && t < current_->endTime();
  if (moving) {
    // A controlled stop along the current path (an escape or back-off under way is cut short too);
    // with no goals left the stop ends in WAIT_TARGET.
    emergencyStopLocked(t, map, reason, out, nullptr, replan_status);
    out->event->fallback = "give_up";
    return;
  }
  FsmEvent event;
  event.trigger = FsmEvent::Trigger::kRetry;
  event.state = state_;
  event.status = replan_status;
  event.fallback = "give_up";
  event.message = reason;
  event.position = takeoverStateLocked(t).position;
  out->event = event;
  setState(FsmState::kWaitTarget, out, reason);
}

bool ReplanFsm::routeBlockedLocked(double t, const EsdfMap& map, FsmOutput* out) {
  if (!config_.global_route || !(config_.route_check_length_m > 0.0) || route_watch_.empty() || goals_.empty() ||
      route_goals_ != remainingGoalsLocked() || t - route_checked_s_ < config_.route_check_interval_s)
    return false;
  route_checked_s_ = t;
  const std::optional<RouteWatch::Blocked> blocked = route_watch_.check(takeoverStateLocked(t).position, map);
  if (!blocked) return false;
  char text[200];
  std::snprintf(text, sizeof(text),
                "the route is blocked %.1f m ahead at (%.2f, %.2f, %.2f) (%.2f m from a known obstacle): re-routing",
                blocked->ahead_m, blocked->where.x(), blocked->where.y(), blocked->where.z(), blocked->distance_m);
  reroute_reason_ = text;
  route_stale_ = true;
  pending_goals_ = remainingGoalsLocked();
  goals_pending_ = !pending_goals_.empty();
  rerouting_ = goals_pending_;
  if (!out->message.empty()) out->message += "; ";
  out->message += text;
  return true;
}

void ReplanFsm::routeLocked(double t, const EsdfMap& map, std::unique_lock<std::mutex>* lock, FsmOutput* out,
                            const std::function<double()>& now, double* searched_until) {
  // Does this tick start (or rebuild) a reference, and through which goals?
  const bool at_rest = (!current_ || t >= current_->endTime()) && odom_velocity_.norm() < config_.stopped_speed_mps;
  bool starts = false;
  switch (state_) {
    case FsmState::kInit: starts = goals_pending_ && inputs_.haveOdometry(); break;
    case FsmState::kWaitTarget:
    case FsmState::kExecTraj:
    case FsmState::kReplanTraj: starts = goals_pending_; break;
    case FsmState::kGenNewTraj: starts = true; break;
    case FsmState::kEmergencyStop: starts = at_rest && (goals_pending_ || !goals_.empty()); break;
  }
  if (!starts) return;
  const std::vector<Eigen::Vector3d> goals = goals_pending_ ? pending_goals_ : remainingGoalsLocked();
  if (goals.empty() || (!route_stale_ && goals == route_goals_)) return;
  for (const Eigen::Vector3d& g : goals)
    if (!g.allFinite()) return;  // refused by startGoalsLocked
  // New goals this tick's startGoalsLocked will refuse: no search, and the route of the mission
  // flown stays (one searched for them replaced it, or cleared it when the goal's clearance
  // failed the search, and the mission went on without).
  std::string refused;
  if (goals_pending_ && !rerouting_ && checkGoalsLocked(goals, map, &refused) != GoalStatus::kAccepted) return;
  const Eigen::Vector3d start = takeoverStateLocked(t + takeover_delay_s_).position;
  const uint64_t epoch = route_epoch_;
  const bool rerouting = rerouting_;

  // The places this mission stalled at weigh against a way through them (set here: the routers are
  // tick()'s, and replaced by a reconfiguration).
  router_->setAvoided(stall_zones_);
  start_router_->setAvoided(stall_zones_);
  // The search, with the mutex released: the safety thread and the inputs go on meanwhile.
  lock->unlock();
  Path route{start};
  SearchStatus status = SearchStatus::kSuccess;
  size_t failed_leg = 0;
  int expansions = 0;
  bool near_start = false;  // some leg has a route only with the start region relaxed
  for (size_t i = 0; i < goals.size() && status == SearchStatus::kSuccess; ++i) {
    GlobalRouter::Result leg = router_->route(map, route.back(), goals[i]);
    expansions += leg.expansions;
    if (leg.status == SearchStatus::kNoPath && i == 0) {
      // Not yet a proof: the vehicle may hover in a passage narrower than the route's clearance (a
      // dead-end slot it braked in) that the small relaxed start region does not leave.
      leg = start_router_->route(map, route.back(), goals[i]);
      expansions += leg.expansions;
      near_start = leg.status == SearchStatus::kSuccess;
    }
    status = leg.status;
    failed_leg = i;
    if (status == SearchStatus::kSuccess) route.insert(route.end(), leg.path.begin() + 1, leg.path.end());
  }
  *searched_until = now ? now() : t;  // the clock, read without the mutex
  lock->lock();

  if (route_epoch_ != epoch) {
    // New goals, a stop or an odometry jump meanwhile: the search answered another question.
    return;
  }
  route_stale_ = false;
  route_goals_ = goals;
  remedies_.routeSearched();
  char text[240];
  if (status == SearchStatus::kSuccess) {
    route_ = std::move(route);
    route_watch_.reset(route_, map);
    out->new_route = true;
    std::snprintf(text, sizeof(text), "global route: %.1f m through %zu points (%d expansions)%s", pathLength(route_),
                  route_.size(), expansions,
                  near_start ? ", narrower than its clearance near the vehicle" : "");
  } else if (status == SearchStatus::kNoPath && config_.route.unknown_is_free) {
    // Both searches exhausted the map window: with unknown space free, no way to this goal exists.
    std::snprintf(text, sizeof(text),
                  "goal %zu (%.2f, %.2f, %.2f) is unreachable in the known map: no route keeps %.2f m from obstacles "
                  "(except within %.1f m of the vehicle) within the height band [%.2f, %.2f] m",
                  failed_leg, goals[failed_leg].x(), goals[failed_leg].y(), goals[failed_leg].z(), config_.route.clearance_m,
                  start_router_->config().start_radius_m, std::max(config_.route.min_z_m, map.geometry().windowMin().z()),
                  std::min(config_.route.max_z_m, map.geometry().windowMax().z()));
    if (!out->message.empty()) out->message += "; ";
    if (goals_pending_ && !rerouting) {
      // New goals: refused like a goal in an obstacle (a mission in progress goes on).
      goals_pending_ = false;
      new_mission_ = false;
      last_goal_status_ = GoalStatus::kUnreachable;
      out->message += std::string("goal refused: ") + toString(GoalStatus::kUnreachable) + ": " + text;
      return;
    }
    giveUpLocked(t, map, GoalStatus::kUnreachable, ReplanStatus::kNoPath, text, out);
    return;
  } else {
    // No proof either way (budget, start or goal inside the route's end clearance, or unknown space
    // not free to the route): straight references.
    route_.clear();
    route_watch_.reset(route_, map);
    out->new_route = true;
    std::snprintf(text, sizeof(text), "no global route (%s at goal %zu): references go straight through the goals",
                  toString(status), failed_leg);
  }
  if (!out->message.empty()) out->message += "; ";
  out->message += text;
}

bool ReplanFsm::startGoalsLocked(double t, const EsdfMap& map, FsmOutput* out) {
  goals_pending_ = false;
  const std::vector<Eigen::Vector3d> goals = pending_goals_;
  const bool rerouted = std::exchange(rerouting_, false);
  auto refuse = [&](GoalStatus status, const std::string& why) {
    last_goal_status_ = status;
    new_mission_ = false;
    if (!out->message.empty()) out->message += "; ";
    out->message += std::string("goal refused: ") + toString(status) + ": " + why;
    return false;
  };
  if (goals.empty()) return refuse(GoalStatus::kInvalidInput, "no goals");
  std::string why;
  const GoalStatus on_map = checkGoalsLocked(goals, map, &why);
  if (on_map != GoalStatus::kAccepted) return refuse(on_map, why);
  // The reference starts from the state at which the first trajectory on it will take over.
  FlatState start = takeoverStateLocked(t + takeover_delay_s_);
  if (state_ == FsmState::kInit || state_ == FsmState::kWaitTarget || !known_anchor_) known_anchor_ = start.position;
  start.jerk.setZero();  // the reference's jerk at the start is free of the spline's knots
  std::vector<Eigen::Vector3d> waypoints{start.position};
  // Through the global route when there is one for these goals (its first point is where the
  // vehicle was when it was searched; the reference starts from where it takes over).
  const bool routed = config_.global_route && route_.size() >= 2 && route_goals_ == goals;
  if (routed) {
    for (size_t i = 1; i < route_.size(); ++i)
      if ((route_[i] - waypoints.back()).norm() > 1e-3) waypoints.push_back(route_[i]);
  } else {
    for (const Eigen::Vector3d& g : goals)
      if ((g - waypoints.back()).norm() > 1e-3) waypoints.push_back(g);
  }
  if (waypoints.size() < 2) waypoints.push_back(goals.back() + Eigen::Vector3d(1e-3, 0, 0));
  // Moving across or away from the first leg (a re-route at speed): from the velocity along it only
  // (the plans start from the vehicle's state; the profile timing is not held to the reference's ramp).
  start = referenceStartState(start, waypoints[1] - waypoints[0]);
  PolynomialTrajectory ref;
  const TrajectoryStatus status =
      referenceTrajectory(waypoints, start, FlatState::atRest(waypoints.back()), referenceConfigLocked(), &ref);
  if (status != TrajectoryStatus::kSuccess)
    return refuse(GoalStatus::kReferenceFailed, std::string("minimum-snap reference: ") + toString(status));
  goals_ = goals;
  next_goal_ = 0;
  const bool new_mission = std::exchange(new_mission_, false);
  if (new_mission) {
    remedies_.newMission(t, ref.duration());
    MissionProgress::Config progress;
    progress.min_gain_m = config_.progress_min_gain_m;
    progress_ = MissionProgress(progress);
    // The places stalled at stay weighed by later missions (a return leg through them), the oldest
    // dropped beyond kMaxStallZones.
  }
  // The distance left is measured along the way the reference takes; a rebuilt one re-bases it.
  progress_.reset(waypoints, t, start.position, !new_mission);
  remedies_.referenceStarted(progress_.lastGain());
  progress_tick_s_ = t;
  reference_ = std::move(ref);
  last_goal_status_ = GoalStatus::kAccepted;
  out->new_reference = true;
  setState(FsmState::kGenNewTraj, out,
           std::string(rerouted ? "re-routed" : "new") + " reference, " + std::to_string(goals.size()) + " goal(s)" +
               (routed ? ", along the global route" : ""));
  return true;
}

void ReplanFsm::plan(double t, const EsdfMap& map, FsmEvent::Trigger trigger, std::unique_lock<std::mutex>* lock,
                     FsmOutput* out, const std::function<double()>& now) {
  const bool generating = state_ == FsmState::kGenNewTraj;
  const double t_take = t + takeover_delay_s_;
  ReplanRequest request;
  request.start = takeoverStateLocked(t_take);
  request.reference_time_s = generating ? 0.0 : referenceTimeAtLocked(t_take);
  request.attempt = uint32_t(remedies_.failures());  // a retry draws another roadmap
  // An intermediate goal not reached yet bounds the local goal where the reference passes it: the
  // plans go through it (within waypoint_reached_radius_m, when it counts as reached) instead of
  // cutting its corner (1.4 m off a waypoint at the end of a wall in fault_hidden_corner).
  if (next_goal_ + 1 < goals_.size() && !reference_.empty()) {
    const double t_pass = waypointPassTime(reference_, goals_[next_goal_], request.reference_time_s,
                                           config_.waypoint_reached_radius_m);
    if (std::isfinite(t_pass)) request.max_local_goal_time_s = t_pass;
  }
  const PolynomialTrajectory reference = reference_;
  request.reference = &reference;
  const int64_t current_id = current_ ? current_->id : -1;
  FsmEvent event;
  event.trigger = trigger;
  event.state = state_;
  event.position = request.start.position;
  if (!generating) setState(FsmState::kReplanTraj, out, toString(trigger));

  lock->unlock();
  ReplanResult result = replanner_->replan(map, request);
  const double finished = now ? now() : t;
  lock->lock();
  // The plan handed on at the end of this call, after the observer saw what the FSM made of it (its
  // start-velocity and known-space checks) outside the lock: the tick ends there.
  auto conclude = [&] {
    if (plan_observer_) {
      lock->unlock();
      plan_observer_(map, request, result);
      lock->lock();
    }
    out->plan = std::move(result);
  };

  // The known-space commitment of a successful plan (on the map it was planned on).
  ExecTrajectory traj;
  if (result.status == ReplanStatus::kSuccess) {
    std::string why;
    const double step = (result.trajectory.derivative().evaluate(0.0) - request.start.velocity).norm();
    if (step > config_.max_start_velocity_step_mps) {
      char text[128];
      std::snprintf(text, sizeof(text), "its start velocity is %.2f m/s off the commanded one (limit %.2f)", step,
                    config_.max_start_velocity_step_mps);
      result.status = ReplanStatus::kOptimizationFailed;
      result.message += (result.message.empty() ? "" : "; ") + std::string(text);
    } else if (!commitToKnownSpace(result.trajectory, t_take, map, &traj, &why)) {
      result.status = ReplanStatus::kOptimizationFailed;
      result.message += (result.message.empty() ? "" : "; ") + why;
    }
  }
  event.status = result.status;
  event.message = result.message;
  const std::string reroute_reason = std::exchange(reroute_reason_, std::string());
  if (trigger == FsmEvent::Trigger::kReroute && !reroute_reason.empty())
    event.message = reroute_reason + (event.message.empty() ? "" : "; " + event.message);
  event.stats = result.stats;
  const bool superseded = (current_ ? current_->id : -1) != current_id;
  // The takeover delay adapts to the planning time: a late plan lengthens it (up to the maximum),
  // on time plans bring it back towards the configured value.
  if (finished > t_take)
    takeover_delay_s_ = std::min(config_.max_takeover_delay_s, 1.5 * (finished - t));
  else
    takeover_delay_s_ = std::max(config_.takeover_delay_s, std::max(0.9 * takeover_delay_s_, 1.5 * (finished - t)));
  if (result.status == ReplanStatus::kSuccess && !superseded && finished <= t_take) {
    traj.id = next_id_++;
    traj.start_time_s = t_take;
    traj.reference_start_s = result.local_start_time_s;
    traj.reference_end_s = result.local_goal_time_s;
    if (traj.stops_before_unknown) {
      // It rejoins the reference only as far as it goes (proportionally, refined in referenceTimeAtLocked).
      const double planned = result.trajectory.duration();
      const double frac = planned > 0.0 ? std::clamp((traj.brake_start_s - t_take) / planned, 0.0, 1.0) : 0.0;
      traj.reference_end_s = traj.reference_start_s + frac * (traj.reference_end_s - traj.reference_start_s);
    }
    traj.ends_at_goal = !traj.stops_before_unknown && result.local_goal_time_s >= reference.duration() - 1e-6;
    // A plan cut to a hold where the vehicle is (unknown space right ahead), again and again at the
    // same place: turning to look has not shown the way (it may lie above or below the camera's
    // view). Back off along the flown path, where the camera sees more, and re-route from there.
    // (A hold, or a stop a few centimetres on: the cut plans of a vehicle that hovers at the edge.)
    const bool look_hold = traj.stops_before_unknown && request.start.velocity.norm() < config_.stopped_speed_mps &&
                           (traj.spline.evaluate(traj.spline.duration()) - traj.spline.evaluate(0.0)).norm() < 0.3;
    remedies_.countLookHold(look_hold, request.start.position, t);
    std::optional<ExecTrajectory> backoff;
    std::string backoff_report;
    bool to_anchor = false;
    if (remedies_.lookHoldBackoffDue(t)) {
      // From the takeover time, as the plan it replaces (the hold published last tick may start
      // between now and then: taking over at t would leave it out).
      backoff = backoffTrajectory(takeoverStateLocked(t_take), t_take, map, flown_, known_anchor_,
                                  manoeuvreConfig(config_), &backoff_report, &to_anchor);
      if (backoff && backoff->has_heading_target) backoff.reset();  // a look again: no use
    }
    // Holding there is no progress: it does not restart the mission's time limit, and ends the
    // mission when that passes.
    if (look_hold && !backoff && config_.global_route && remedies_.noPlanForTheLimit(t)) {
      char text[160];
      std::snprintf(text, sizeof(text), "held at the edge of the known space, no way on for the mission's time limit of %.0f s",
                    remedies_.missionLimit());
      giveUpLocked(t, map, GoalStatus::kGivenUp, ReplanStatus::kSuccess, text, out);
      event.fallback = "give_up";
      event.message += (event.message.empty() ? "" : "; ") + out->event->message;
      out->event = event;
      conclude();
      return;
    }
    if (backoff) {
      // Holding there did not show the way on: a stall. The route rebuilt after the back-off weighs
      // against the place (another opening, another side), as the progress remedy's routes do: the
      // zone lies ahead along the way (where the progress is tracked), else around the hold. (Not
      // after a back-off to the anchor: the camera's blind zone held it there, not the way.)
      const bool tracked = config_.progress_timeout_s > 0.0 && progress_.active();
      if (config_.stall_zone_radius_m > 0.0 && !to_anchor)
        addStallZoneLocked({tracked ? progress_.ahead(config_.stall_zone_radius_m) : remedies_.lookHoldPosition(),
                            config_.stall_zone_radius_m});
      route_stale_ = route_stale_ || !to_anchor;
      event.message += (event.message.empty() ? "" : "; ") + std::string("held at the edge of the known space ") +
                       std::to_string(config_.max_look_holds) + " times; " + backoff_report;
      startManoeuvreLocked(*backoff, true, &event, out, backoff_report);
      out->event = event;
      conclude();
      return;
    }
    replaceCurrentLocked(traj);
    collision_ahead_ = false;
    remedies_.planSucceeded(t, look_hold);
    if (traj.stops_before_unknown) {  // in the event log: where the vehicle waits on its map
      char text[96];
      std::snprintf(text, sizeof(text), "stops before unknown space, braking from +%.2f s", traj.brake_start_s - t_take);
      event.message = text;
    }
    event.published = true;
    out->trajectory = traj;
    setState(FsmState::kExecTraj, out, "");
  } else {
    remedies_.planFailed();
    // What the vehicle does now (MissionRemedies); a discarded plan keeps its label unless it ends the
    // mission. A braking trajectory that took over while planning (superseded) owns the state now.
    const bool late = result.status == ReplanStatus::kSuccess;
    if (late) event.fallback = superseded ? "discarded_superseded" : "discarded_late";
    const bool at_rest = !current_ || t >= current_->endTime();
    MissionRemedies::AfterFailure remedy;
    if (!superseded) remedy = remedies_.afterFailure(t, result.status, generating, at_rest);
    const bool giving_up = remedy.give_up.has_value();
    if (giving_up) {
      event.fallback = "give_up";
    } else if (!superseded && !late) {
      const bool moving = current_ && !current_->manoeuvre() && t < current_->endTime();
      event.fallback = generating && !moving ? "hover_retry" : "keep_current";
    }
    // At rest too close to an obstacle for the replanner to start: a slow escape first, then (as
    // after braking) a new reference from where it ends; with none, or when first plans keep failing
    // from rest, a back-off along the flown path, and a re-route from there.
    std::string escape_report;
    std::optional<ExecTrajectory> escape;
    if (remedy.escape) escape = escapeTrajectory(takeoverStateLocked(t), t, map, manoeuvreConfig(config_), &escape_report);
    bool backoff = false;
    if (!escape && remedy.backoff) {
      std::string report;
      escape = backoffTrajectory(takeoverStateLocked(t), t, map, flown_, known_anchor_, manoeuvreConfig(config_), &report);
      backoff = escape.has_value();
      escape_report += (escape_report.empty() ? "" : "; ") + report;
    }
    if (!escape && !escape_report.empty()) event.message += "; " + escape_report;
    // Still failing at rest with no back-off left: the stall remedy (a zone ahead, a re-route) now,
    // not when the progress clock runs out.
    if (!escape && !superseded && generating && at_rest && !giving_up) remedies_.forceStallAfterFailure();
    if (event.fallback == "hover_retry") rest_retry_after_s_ = finished + config_.rest_retry_interval_s;
    if (event.fallback == "keep_current") moving_retry_after_s_ = finished + config_.moving_retry_interval_s;
    if (!superseded && !giving_up && !escape && remedies_.rerouteAfterFailure(result.status)) {
      route_stale_ = true;
      if (!generating && !goals_pending_) {
        // A moving vehicle: a new reference from the takeover state, next tick (unless new goals
        // arrived while planning: they are flown instead).
        pending_goals_ = remainingGoalsLocked();
        goals_pending_ = !pending_goals_.empty();
        rerouting_ = goals_pending_;
      }
    }
    if (escape) {
      event.message += "; " + escape_report;
      startManoeuvreLocked(*escape, backoff, &event, out, escape_report);
    } else if (giving_up) {
      giveUpLocked(t, map, GoalStatus::kGivenUp, result.status, *remedy.give_up, out);
      event.published = out->trajectory.has_value();  // the stop of a moving vehicle
      event.message += "; " + out->event->message;
    } else if (!superseded && !generating) {
      setState(FsmState::kExecTraj, out, "");
      collision_ahead_ = collision_ahead_ || trigger == FsmEvent::Trigger::kCollisionAhead;
    }
  }
  out->event = event;
  conclude();
}

FsmOutput ReplanFsm::tick(double t, const EsdfMap& map, const std::function<double()>& now) {
  std::unique_lock<std::mutex> lock(mutex_);
  FsmOutput out;
  if (!std::isfinite(t)) return out;
  map_geometry_ = map.geometry();
  observeClockLocked(t, &out);
  // Here only, not in checkSafety(): the replanner and the routers are used by tick() alone,
  // outside the lock, so only tick() may replace them.
  applyPendingConfigLocked(&out);
  if (inputs_.haveOdometry() && followServerLocked(t, map, &out)) return out;
  // Nothing is planned on stale inputs (checkSafety() brakes a moving vehicle); goals wait.
  std::string stale;
  if (state_ != FsmState::kInit && !inputs_.fresh(t, &stale)) {
    // Nothing is planned: no stall (the progress clock pauses).
    if (progress_.active() && std::isfinite(progress_tick_s_) && t > progress_tick_s_) progress_.shift(t - progress_tick_s_);
    progress_tick_s_ = t;
    if (goals_pending_ && state_ == FsmState::kWaitTarget) {
      goals_pending_ = false;
      last_goal_status_ = GoalStatus::kInputsStale;
    }
    if (!inputs_reported_) {
      inputs_reported_ = true;
      if (!out.message.empty()) out.message += "; ";
      out.message += "inputs stale (" + stale + "): not planning";
    }
    return out;
  }
  // After a time jump the replan waits for a trajectory server setpoint sampled after it (when a
  // server reports): the FSM re-synchronises its timing to it first (followServerLocked), since the
  // two shifted by their own estimates of the time between calls.
  if (time_jumped_ && server_.freshAt(t) && server_.latest()->stamp_s < time_jump_clock_s_)
    return out;
  const bool jumped = std::exchange(time_jumped_, false);
  if (inputs_reported_ && state_ != FsmState::kInit) {
    inputs_reported_ = false;
    if (!out.message.empty()) out.message += "; ";
    out.message += "inputs fresh again";
  }
  // The flown path, for back-offs: commanded positions (checked trajectories) 0.25 m apart; not
  // the manoeuvres (a back-off would walk back along the previous one).
  if (current_ && !current_->manoeuvre()) {
    const Eigen::Vector3d p = takeoverStateLocked(t).position;
    if (flown_.empty() || (p - flown_.back()).norm() >= 0.25) flown_.push_back(p);
    if (flown_.size() > 200) flown_.erase(flown_.begin(), flown_.begin() + 100);
  }
  if (handleStallLocked(t, map, &out)) return out;
  if (config_.global_route) {
    const FsmState before = state_;
    double searched_until = NAN;
    routeLocked(t, map, &lock, &out, now, &searched_until);
    if (out.event || state_ != before) return out;  // given up, or a braking took over meanwhile
    // A long search: plan at the next tick, from then (a plan from t would start late).
    if (searched_until - t > 0.5 * takeover_delay_s_) return out;
  }
  switch (state_) {
    case FsmState::kInit:
      if (inputs_.haveOdometry()) setState(FsmState::kWaitTarget, &out, "odometry received");
      if (goals_pending_ && startGoalsLocked(t, map, &out)) plan(t, map, FsmEvent::Trigger::kNewGoal, &lock, &out, now);
      break;
    case FsmState::kWaitTarget:
      if (goals_pending_ && startGoalsLocked(t, map, &out)) plan(t, map, FsmEvent::Trigger::kNewGoal, &lock, &out, now);
      break;
    case FsmState::kGenNewTraj: {
      // A retry rebuilds the reference from where the vehicle will be, so it starts from its state.
      const bool fresh = goals_pending_;
      if (!fresh && remedies_.failures() > 0 && t < rest_retry_after_s_) break;  // paced retries at rest
      if (!fresh) pending_goals_ = remainingGoalsLocked();
      goals_pending_ = true;
      if (startGoalsLocked(t, map, &out))
        plan(t, map, fresh ? FsmEvent::Trigger::kNewGoal : FsmEvent::Trigger::kRetry, &lock, &out, now);
      else if (!fresh)
        referenceNotRebuiltLocked(t, map, &out);
      break;
    }
    case FsmState::kExecTraj:
    case FsmState::kReplanTraj: {
      if (goals_pending_) {
        const FsmEvent::Trigger trigger = rerouting_ ? FsmEvent::Trigger::kReroute : FsmEvent::Trigger::kNewGoal;
        if (startGoalsLocked(t, map, &out)) plan(t, map, trigger, &lock, &out, now);
        break;
      }
      if (!current_) {
        setState(FsmState::kWaitTarget, &out, "no trajectory");
        break;
      }
      const bool ended = t >= current_->endTime();
      if (current_->ends_at_goal && ended) {
        if ((odom_position_ - goals_.back()).norm() <= config_.goal_tolerance_m) {
          out.goal_reached = true;
          goals_.clear();  // done: a later stop (e.g. an odometry jump at the hover) flies nowhere
          next_goal_ = 0;
          progress_.clear();
          setState(FsmState::kWaitTarget, &out, "goal reached");
        }
        break;
      }
      // A trajectory cut before unknown space is replanned before its stop begins, so a plan on the
      // grown map takes over while the vehicle still cruises; one that ends moving, early enough
      // before it runs out that a failed plan still leaves retries before checkSafety() must brake.
      const bool running_out = !current_->ends_at_goal &&
                               (ended || current_->endTime() - t <= stopTimeLocked(t, config_.brake_acc_mps2) + 0.5 * config_.replan_interval_s ||
                                (current_->stops_before_unknown &&
                                 current_->brake_start_s - t <= takeover_delay_s_ + 0.5 * config_.replan_interval_s));
      const bool periodic = !current_->ends_at_goal && t - current_->start_time_s >= config_.replan_interval_s;
      // The route ahead newly blocked in the map: re-routed at the next tick (a collision ahead or a
      // time jump is planned for first).
      if (!jumped && !collision_ahead_ && !current_->manoeuvre() && routeBlockedLocked(t, map, &out)) break;
      if (jumped) {
        plan(t, map, FsmEvent::Trigger::kTimeJump, &lock, &out, now);
      } else if (collision_ahead_) {
        plan(t, map, remedies_.failures() > 0 ? FsmEvent::Trigger::kRetry : FsmEvent::Trigger::kCollisionAhead,
             &lock, &out, now);
      } else if (running_out || periodic) {
        // Retries of a failed periodic replan are paced while the trajectory flown stays safe for a
        // while (moving_retry_interval_s); when it runs out soon, at every tick.
        if (remedies_.failures() > 0 && !running_out && t < moving_retry_after_s_) break;
        plan(t, map, remedies_.failures() > 0 ? FsmEvent::Trigger::kRetry : FsmEvent::Trigger::kPeriodic, &lock,
             &out, now);
      }
      break;
    }
    case FsmState::kEmergencyStop: {
      const bool stopped = (!current_ || t >= current_->endTime()) && odom_velocity_.norm() < config_.stopped_speed_mps;
      if (!stopped) break;
      // At rest after an odometry jump: the hover is the anchor (the camera cannot see beside and
      // behind it, and the map it flew through was in the old frame).
      if (std::exchange(anchor_at_rest_, false)) known_anchor_ = takeoverStateLocked(t).position;
      // Stopped: a new reference from here through the mission's goals (or the newer ones).
      const bool fresh = goals_pending_;
      if (!fresh) {
        pending_goals_ = remainingGoalsLocked();
        goals_pending_ = !pending_goals_.empty();
      }
      if (!goals_pending_) {
        setState(FsmState::kWaitTarget, &out, "stopped, no mission");
        break;
      }
      bool started = startGoalsLocked(t, map, &out);
      if (!started && fresh && last_goal_status_ != GoalStatus::kReferenceFailed && !remainingGoalsLocked().empty()) {
        // Newer goals refused (out of the map, in an obstacle: said in the message and the goal
        // status) are no reason to drop the mission: it goes on from here, as it would in flight.
        const GoalStatus refused = last_goal_status_;
        pending_goals_ = remainingGoalsLocked();
        goals_pending_ = true;
        started = startGoalsLocked(t, map, &out);
        if (started) last_goal_status_ = refused;
      }
      if (started) {
        // A new reference from rest is a new strategy: it gets its own max_plan_failures tries (the
        // failures of the replans that led here do not count against it).
        remedies_.newStart();
        plan(t, map, FsmEvent::Trigger::kRetry, &lock, &out, now);
      } else {
        referenceNotRebuiltLocked(t, map, &out);
      }
      break;
    }
  }
  return out;
}

void ReplanFsm::emergencyStopLocked(double t, const EsdfMap& map, const std::string& reason, FsmOutput* out,
                                    const FlatState* from, ReplanStatus status) {
  FsmEvent event;
  event.trigger = FsmEvent::Trigger::kEmergency;
  event.state = state_;
  event.status = status;
  event.fallback = "stop";
  std::string report;
  ExecTrajectory brake = brakingTrajectoryLocked(t, map, &report, from);
  if (from) known_anchor_ = from->position;  // a hold where the vehicle is measured (or the server holds)
  brake.id = next_id_++;
  event.position = brake.spline.evaluate(0.0);
  event.message = reason + "; " + report;
  event.published = true;
  replaceCurrentLocked(brake);
  collision_ahead_ = false;
  route_stale_ = true;  // once stopped, the reference is rebuilt along a new route
  ++route_epoch_;
  setState(FsmState::kEmergencyStop, out, event.message);
  out->trajectory = brake;
  out->event = event;
}

FsmOutput ReplanFsm::checkSafety(double t, const EsdfMap& map) {
  std::lock_guard<std::mutex> lock(mutex_);
  FsmOutput out;
  if (!std::isfinite(t)) return out;
  observeClockLocked(t, &out);
  if (inputs_.haveOdometry() && followServerLocked(t, map, &out)) return out;
  if (!current_ || state_ == FsmState::kInit) return out;
  const bool active = t < current_->endTime();
  const double commanded_speed = active ? takeoverStateLocked(t).velocity.norm() : 0.0;
  // Stale inputs: a moving vehicle brakes to a hover (a braking trajectory already does).
  std::string stale;
  if (!inputs_.fresh(t, &stale)) {
    if (!current_->braking && commanded_speed > config_.stopped_speed_mps)
      emergencyStopLocked(t, map, "inputs stale (" + stale + ")", &out, nullptr, ReplanStatus::kInvalidInput);
    return out;
  }
  // Odometry far from where the vehicle was commanded to be at its stamp (a VIO jump, or a vehicle
  // that went its own way while the odometry was away, e.g. a flight controller's failsafe hold):
  // hold from the measured state, moving on with the measured velocity to a stop; replanned from
  // there. (With the commanded velocity instead, a vehicle that came back from a failsafe hold
  // moving the other way left the stop at once and was re-anchored a second time, a setpoint jump.)
  const double odom_t = inputs_.odometryStamp();
  const bool covered = odom_t >= current_->start_time_s || (previous_ && odom_t >= previous_->start_time_s);
  const double tracking_error = covered ? (odom_position_ - takeoverStateLocked(odom_t).position).norm() : 0.0;
  if (tracking_error > config_.max_tracking_error_m) {
    FlatState from = takeoverStateLocked(t);
    from.velocity = odom_velocity_;
    from.position = odom_position_ + from.velocity * std::max(0.0, t - odom_t);
    from.acceleration.setZero();
    from.jerk.setZero();
    char text[160];
    std::snprintf(text, sizeof(text), "odometry %.2f m from the commanded position (limit %.2f m): holding at the "
                  "measured position", tracking_error, config_.max_tracking_error_m);
    emergencyStopLocked(t, map, text, &out, &from, ReplanStatus::kInvalidInput);
    current_->reanchor = out.trajectory->reanchor = true;  // the step to the measured position is deliberate
    out.odometry_jumped = true;
    anchor_at_rest_ = true;
    flown_.clear();  // in the old frame
    stall_zones_.clear();
    route_stale_ = true;
    ++route_epoch_;
    return out;
  }
  // Braking and escapes were checked when made and are not replanned (they end at rest).
  if (current_->manoeuvre()) return out;
  if (t > current_->endTime() && state_ == FsmState::kWaitTarget) return out;
  // Time to stop from the current speed, plus the margin: a collision (or the end of a trajectory
  // that ends moving, past which nothing is planned) closer than that cannot wait for a replan.
  // Before a collision the vehicle may fly on, replanning at every tick, while a stop at the back-up
  // deceleration every committed plan keeps (commit_brake_acc_mps2) still ends before it: a
  // collision seen at the end of a plan cut before unknown space (a tree behind the edge of what
  // was seen, a voxel that turned occupied) is a replan's business, not an emergency stop's.
  const double collision_decel =
      config_.commit_to_known_space ? std::max(config_.brake_acc_mps2, config_.commit_brake_acc_mps2) : config_.brake_acc_mps2;
  const double hit = firstCollisionTime(*current_, t, map, config_.safety_clearance_m, config_.safety_sample_s);
  const double end_speed =
      current_->spline.derivative().evaluate(std::max(0.0, current_->spline.duration() - 1e-6)).norm();
  const bool runs_out = !current_->ends_at_goal && end_speed > config_.stopped_speed_mps &&
                        current_->endTime() - t <= stopTimeLocked(t, config_.brake_acc_mps2);
  if (hit >= 0.0) collision_ahead_ = true;
  if (!runs_out && (hit < 0.0 || hit - t > stopTimeLocked(t, collision_decel))) return out;

  emergencyStopLocked(t, map,
                      hit >= 0.0 ? "collision in " + std::to_string(hit - t) + " s"
                                 : "the trajectory ends moving in " + std::to_string(current_->endTime() - t) +
                                       " s with no replan",
                      &out, nullptr, ReplanStatus::kOptimizationFailed);
  return out;
}

}  // namespace topo_planner
