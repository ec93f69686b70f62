// The replanning FSM's entry points (replan_fsm.h): construction and settings, the inputs
// (odometry, depth, the trajectory server's setpoints, goals, the clock) and the queries, each under
// the FSM's mutex. The state machine itself is replan_fsm.cpp.
#include <algorithm>
#include <cmath>
#include <cstdio>

#include "topo_planner/topo_replan/replan_fsm.h"

namespace topo_planner {

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

ReplanFsm::ReplanFsm(const Config& config, std::unique_ptr<TopoReplanner> replanner)
    : config_(config),
      replanner_(std::move(replanner)),
      inputs_(config.inputMonitor()),
      server_(config.serverLink()),
      safety_(config.safetyCheck()),
      mission_(config),
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
  if (replanner) {
    config_ = *pending_config_;
    replanner_ = std::move(replanner);
    inputs_.setConfig(config_.inputMonitor());
    server_.setConfig(config_.serverLink());
    safety_.setConfig(config_.safetyCheck());
    mission_.setConfig(config_);
    takeover_delay_s_ = std::max(takeover_delay_s_, config_.takeover_delay_s);
    out->say("new settings applied");
  } else {
    out->say("new settings not applied: " + error);
  }
  pending_config_.reset();
}

FsmState ReplanFsm::state() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return state_;
}

GoalStatus ReplanFsm::lastGoalStatus() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return mission_.status();
}

std::optional<ExecTrajectory> ReplanFsm::current() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return current_;
}

PolynomialTrajectory ReplanFsm::reference() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return mission_.reference();
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
  mission_.passWaypoints(position);  // intermediate goals it came close to are done
  return true;
}

bool ReplanFsm::setServerSetpoint(const ServerSetpoint& setpoint) {
  std::lock_guard<std::mutex> lock(mutex_);
  return server_.set(setpoint);
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
    if (*traj) (*traj)->shift(shift);
  server_.shift(*jump);
  mission_.shift(shift);  // its times are read from this clock
  rest_retry_after_s_ += shift;    // the paced retries keep their pace
  moving_retry_after_s_ += shift;
  time_jumped_ = true;
  time_jump_clock_s_ = now;
  char text[128];
  std::snprintf(text, sizeof(text), "time jump of %+.3f s: timing shifted by %+.3f s, replanning from the current state",
                jump->step_s, shift);
  out->say(text);
}

int ReplanFsm::timeJumps() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return inputs_.timeJumps();
}

std::vector<Eigen::Vector3d> ReplanFsm::remainingGoals() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return mission_.remaining();
}

Path ReplanFsm::route() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return mission_.route();
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
  const GoalStatus on_map = finite ? mission_.check(goals, map, &why) : GoalStatus::kAccepted;
  if (on_map != GoalStatus::kAccepted) return mission_.setStatus(on_map);
  return acceptGoalsLocked(goals);
}

GoalStatus ReplanFsm::acceptGoalsLocked(const std::vector<Eigen::Vector3d>& goals) {
  if (goals.empty()) return mission_.setStatus(GoalStatus::kInvalidInput);
  for (const Eigen::Vector3d& g : goals)
    if (!g.allFinite()) return mission_.setStatus(GoalStatus::kInvalidInput);
  if (!inputs_.haveOdometry()) return mission_.setStatus(GoalStatus::kNoOdometry);
  std::string why;
  if (!inputs_.haveClock() || !inputs_.fresh(inputs_.clock(), &why)) return mission_.setStatus(GoalStatus::kInputsStale);
  // Refused here, not at the next tick: a flood of such goals (any host can publish them) would
  // otherwise replace valid goals not yet taken up, and clear the global route of the mission flown.
  if (map_geometry_)
    for (const Eigen::Vector3d& g : goals)
      if (!map_geometry_->inWindow(g)) return mission_.setStatus(GoalStatus::kGoalOutOfMap);
  mission_.give(goals);
  return GoalStatus::kAccepted;
}

}  // namespace topo_planner
