// The replanning state machine (replan_fsm.h): its states and transitions (tick()), the planning
// calls and what their results call for, the safety thread's reactions (checkSafety()), and the
// manoeuvres it starts. The entry points (settings, inputs, queries) are replan_fsm_inputs.cpp.
#include "topo_planner/topo_replan/replan_fsm.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <utility>

namespace topo_planner {

bool ReplanFsm::followServerLocked(double t, const EsdfMap& map, FsmOutput* out) {
  const ServerLink::Verdict v = server_.judge(t, current_ ? &*current_ : nullptr, previous_ ? &*previous_ : nullptr,
                                              [this](double s) { return takeoverStateLocked(s); });
  switch (v.kind) {
    case ServerLink::Verdict::Kind::kFollows:
      if (v.resync_s != 0.0) {
        for (std::optional<ExecTrajectory>* traj : {&current_, &previous_})
          if (*traj) (*traj)->shift(-v.resync_s);
        char text[160];
        std::snprintf(text, sizeof(text), "timing re-synchronised with the trajectory server by %+.3f s", -v.resync_s);
        out->say(text);
      }
      return false;
    case ServerLink::Verdict::Kind::kDiverged:
      out->server_diverged = true;
      if (v.first_report) {
        out->say("the trajectory server does not follow the commanded trajectory (" + v.why +
                        "): waiting for its hold (no heartbeat meanwhile, so its watchdog stops the vehicle)");
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

void ReplanFsm::setState(FsmState s, FsmOutput* out, const std::string& why) {
  if (s == state_) return;
  out->say(std::string(toString(state_)) + " -> " + toString(s) + (why.empty() ? "" : " (" + why + ")"));
  state_ = s;
}

void ReplanFsm::replaceCurrentLocked(const ExecTrajectory& next) {
  // The one it replaces is still flown until the new one's start time (a planned trajectory takes
  // over takeover_delay_s after planning began): the state before then is on it.
  if (current_) previous_ = current_;
  current_ = next;
}

const ExecTrajectory* ReplanFsm::flownAtLocked(double t) const {
  return current_ ? &flownAt(*current_, previous_ ? &*previous_ : nullptr, t) : nullptr;
}

FlatState ReplanFsm::takeoverStateLocked(double t_takeover) const {
  if (!current_) {
    // Not commanded yet: the trajectory server holds (a restarted planner: where its stop ended), or
    // the controller holds the position where it started.
    if (const std::optional<Eigen::Vector3d> hold = server_.holdAt(t_takeover)) return FlatState::atRest(*hold);
    return FlatState::atRest(odom_position_);
  }
  return flownAtLocked(t_takeover)->stateAt(t_takeover);
}

double ReplanFsm::referenceTimeAtLocked(double t) const {
  return current_ ? current_->referenceTimeAt(t, mission_.reference()) : 0.0;
}

double ReplanFsm::stopTimeLocked(double t, double deceleration) const {
  return safety_.stopTime(takeoverStateLocked(t).velocity.norm(), deceleration, takeover_delay_s_);
}

ExecTrajectory ReplanFsm::brakingTrajectoryLocked(double t, const EsdfMap& map, std::string* report,
                                                  const FlatState* from) const {
  FlatState s0 = from ? *from : takeoverStateLocked(t);
  if (!current_ && !from) s0.velocity = odom_velocity_;
  // Along the trajectory flown at t (a plan waiting for its takeover is not flown yet). From another
  // state (a re-anchoring after an odometry jump), along its velocity and never harder than
  // brake_acc_mps2: the map is in the old frame.
  return brakingTrajectory(s0, from ? nullptr : flownAtLocked(t), t, map, config_.manoeuvres(), !from, report);
}

ReferenceConfig ReplanFsm::referenceConfigLocked() const {
  ReferenceConfig r = config_.reference;
  r.max_vel_mps = std::min(r.max_vel_mps, cruiseSpeed(config_));
  return r;
}

void ReplanFsm::referenceNotRebuiltLocked(double t, const EsdfMap& map, FsmOutput* out) {
  if (mission_.status() != GoalStatus::kReferenceFailed) {
    // The map shows a goal of the mission in an obstacle (or out of the map window): it ends, saying why.
    giveUpLocked(t, map, mission_.status(), ReplanStatus::kGoalInCollision,
                 std::string("the mission's goals are no longer valid (") + toString(mission_.status()) + ")", out);
    return;
  }
  // The minimum-snap reference could not be built from the state it starts from (its limits, from a
  // fast or turning state): the goals are still valid. A moving vehicle stops and rebuilds it from
  // rest; at rest it is tried again at the next tick (the mission's time limit bounds the tries).
  mission_.setStatus(GoalStatus::kAccepted);
  const bool moving = current_ && !current_->manoeuvre() && t < current_->endTime();
  if (moving) {
    emergencyStopLocked(t, map, "the mission's reference could not be rebuilt from the moving state: stopping to "
                        "rebuild it from rest", out, nullptr, ReplanStatus::kInvalidInput);
    return;
  }
  mission_.remedies().planFailed();
  if (state_ != FsmState::kGenNewTraj && state_ != FsmState::kEmergencyStop)
    setState(FsmState::kGenNewTraj, out, "the mission's reference could not be rebuilt: trying again");
}

void ReplanFsm::startManoeuvreLocked(ExecTrajectory manoeuvre, bool backoff, FsmEvent* event, FsmOutput* out,
                                     const std::string& why) {
  if (backoff) {
    mission_.remedies().backedOff();
    flown_.useUpTo(manoeuvre.spline.evaluate(manoeuvre.spline.duration()));  // the way back is used up
  }
  manoeuvre.id = next_id_++;
  replaceCurrentLocked(manoeuvre);
  mission_.remedies().newStart();  // the tries after it are counted anew
  mission_.invalidateRoute();      // searched again from where it ends
  collision_ahead_ = false;
  event->published = true;
  event->fallback = backoff ? "back_off" : "escape";
  out->trajectory = manoeuvre;
  setState(FsmState::kEmergencyStop, out, why);
}

std::optional<ExecTrajectory> ReplanFsm::backoffLocked(double t, const EsdfMap& map, std::string* report,
                                                       bool* to_anchor) const {
  return backoffTrajectory(takeoverStateLocked(t), t, map, flown_.points(), known_anchor_, config_.manoeuvres(), report,
                           to_anchor);
}

bool ReplanFsm::atRestLocked(double t) const {
  return (!current_ || t >= current_->endTime()) && odom_velocity_.norm() < config_.stopped_speed_mps;
}

bool ReplanFsm::handleStallLocked(double t, const EsdfMap& map, FsmOutput* out) {
  const bool flying = state_ == FsmState::kGenNewTraj || state_ == FsmState::kExecTraj ||
                      state_ == FsmState::kReplanTraj || state_ == FsmState::kEmergencyStop;
  if (!flying || !mission_.checksProgress()) return false;
  const FlatState here = takeoverStateLocked(t);
  const bool at_rest = atRestLocked(t);
  const bool manoeuvring = current_ && current_->manoeuvre() && t < current_->endTime();
  const Mission::Stall stall =
      mission_.checkProgress(t, here.position, state_ == FsmState::kEmergencyStop && at_rest, manoeuvring);
  if (stall.kind == Mission::Stall::Kind::kNone) return false;
  if (stall.kind == Mission::Stall::Kind::kGiveUp) {
    giveUpLocked(t, map, GoalStatus::kGivenUp, ReplanStatus::kSuccess, stall.why, out);
    return true;
  }
  FsmEvent event;
  event.trigger = FsmEvent::Trigger::kReroute;
  event.state = state_;
  event.status = ReplanStatus::kSuccess;
  event.position = here.position;
  std::string report;
  if (stall.kind == Mission::Stall::Kind::kBackOffNow) {
    // A stop begun as a remedy has ended: back off from there.
    if (std::optional<ExecTrajectory> backoff = backoffLocked(t, map, &report)) {
      event.message = "no progress: " + report;
      startManoeuvreLocked(*backoff, true, &event, out, report);
      out->event = event;
      return true;
    }
    // None: the stopped vehicle plans anew from where it is (EMERGENCY_STOP's own rule).
    out->say(report);
    return false;
  }
  // A stall: back off (stopping first when moving), or re-route.
  event.message = stall.why;
  if (stall.backs_off) {
    if (!at_rest) {
      // Stop first (the back-off starts from rest), then back off (kBackOffNow).
      emergencyStopLocked(t, map, stall.why + ": stopping to back off", out, nullptr, ReplanStatus::kSuccess);
      out->event->trigger = FsmEvent::Trigger::kReroute;
      mission_.remedies().stopThenBackOff();
      return true;
    }
    std::optional<ExecTrajectory> backoff = backoffLocked(t, map, &report);
    event.message += "; " + report;
    if (backoff) {
      startManoeuvreLocked(*backoff, true, &event, out, report);
      out->event = event;
      return true;
    }
  }
  // Re-route from where the vehicle is (at the next tick), around the places it stalled at.
  if (state_ == FsmState::kExecTraj || state_ == FsmState::kReplanTraj) mission_.pendRemaining(true);
  event.fallback = "reroute";
  event.message += "; re-routing around where it stalled";
  out->event = event;
  out->say(event.message);
  return true;
}

void ReplanFsm::giveUpLocked(double t, const EsdfMap& map, GoalStatus status, ReplanStatus replan_status,
                             const std::string& why, FsmOutput* out) {
  const std::string reason = "mission given up: " + why;
  mission_.end(status, map);
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
  std::string text;
  if (!mission_.routeCheckDue(t) || !mission_.routeBlocked(t, takeoverStateLocked(t).position, map, &text))
    return false;
  out->say(text);
  return true;
}

void ReplanFsm::routeLocked(double t, const EsdfMap& map, std::unique_lock<std::mutex>* lock, FsmOutput* out,
                            const std::function<double()>& now, double* searched_until) {
  // Does this tick start (or rebuild) a reference?
  bool starts = false;
  switch (state_) {
    case FsmState::kInit: starts = mission_.pending() && inputs_.haveOdometry(); break;
    case FsmState::kWaitTarget:
    case FsmState::kExecTraj:
    case FsmState::kReplanTraj: starts = mission_.pending(); break;
    case FsmState::kGenNewTraj: starts = true; break;
    case FsmState::kEmergencyStop: starts = atRestLocked(t) && (mission_.pending() || !mission_.empty()); break;
  }
  if (!starts) return;
  std::optional<Mission::RouteSearch> search = mission_.prepareRouteSearch(map);
  if (!search) return;
  search->start = takeoverStateLocked(t + takeover_delay_s_).position;
  // The search, with the mutex released: the safety thread and the inputs go on meanwhile.
  lock->unlock();
  Mission::RouteFound found = mission_.searchRoute(map, *search);
  *searched_until = now ? now() : t;  // the clock, read without the mutex
  lock->lock();
  std::string text;
  switch (mission_.applyRoute(*search, std::move(found), map, &text)) {
    case Mission::RouteOutcome::kOvertaken: return;
    case Mission::RouteOutcome::kUnreachable:
      giveUpLocked(t, map, GoalStatus::kUnreachable, ReplanStatus::kNoPath, text, out);
      return;
    case Mission::RouteOutcome::kFound:
    case Mission::RouteOutcome::kNone: out->new_route = true; break;
    case Mission::RouteOutcome::kRefused: break;
  }
  out->say(text);
}

bool ReplanFsm::startGoalsLocked(double t, const EsdfMap& map, FsmOutput* out) {
  // The reference starts from the state at which the first trajectory on it will take over.
  const FlatState start = takeoverStateLocked(t + takeover_delay_s_);
  const Mission::Started started = mission_.start(t, start, map, referenceConfigLocked());
  // A mission from a hover starts where the vehicle is known to be (the known-space commitment).
  if (started.goals_valid && (state_ == FsmState::kInit || state_ == FsmState::kWaitTarget || !known_anchor_))
    known_anchor_ = start.position;
  if (!started.ok) {
    out->say("goal refused: " + started.summary);
    return false;
  }
  out->new_reference = true;
  setState(FsmState::kGenNewTraj, out, started.summary);
  return true;
}

void ReplanFsm::plan(const Tick& tick, FsmEvent::Trigger trigger) {
  const double t = tick.t;
  const EsdfMap& map = tick.map;
  FsmOutput* out = tick.out;
  const bool generating = state_ == FsmState::kGenNewTraj;
  const double t_take = t + takeover_delay_s_;
  ReplanRequest request;
  request.start = takeoverStateLocked(t_take);
  request.reference_time_s = generating ? 0.0 : referenceTimeAtLocked(t_take);
  request.attempt = uint32_t(mission_.remedies().failures());  // a retry draws another roadmap
  // An intermediate goal not reached yet bounds the local goal where the reference passes it: the
  // plans go through it (within waypoint_reached_radius_m, when it counts as reached) instead of
  // cutting its corner (1.4 m off a waypoint at the end of a wall in fault_hidden_corner).
  const double t_pass = mission_.localGoalLimit(request.reference_time_s);
  if (std::isfinite(t_pass)) request.max_local_goal_time_s = t_pass;
  const PolynomialTrajectory reference = mission_.reference();
  request.reference = &reference;
  const int64_t current_id = current_ ? current_->id : -1;
  FsmEvent event;
  event.trigger = trigger;
  event.state = state_;
  event.position = request.start.position;
  if (!generating) setState(FsmState::kReplanTraj, out, toString(trigger));

  tick.lock->unlock();
  ReplanResult result = replanner_->replan(map, request);
  const double finished = tick.now ? tick.now() : t;
  tick.lock->lock();

  ExecTrajectory traj;
  if (result.status == ReplanStatus::kSuccess)
    commitPlan(request, t_take, map, known_anchor_, config_.planCommit(), &result, &traj);
  event.status = result.status;
  event.message = result.message;
  const std::string reroute_reason = mission_.takeRerouteReason();
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
  if (result.status == ReplanStatus::kSuccess && !superseded && finished <= t_take)
    planSucceededLocked(t, map, request, std::move(traj), &event, out);
  else
    planFailedLocked(t, map, result.status, trigger, superseded, finished, &event, out);
  out->event = event;
  // The observer sees what the FSM made of the plan (its start-velocity and known-space checks),
  // outside the lock; the tick ends here.
  if (plan_observer_) {
    tick.lock->unlock();
    plan_observer_(map, request, result);
    tick.lock->lock();
  }
  out->plan = std::move(result);
}

void ReplanFsm::planSucceededLocked(double t, const EsdfMap& map, const ReplanRequest& request, ExecTrajectory traj,
                                    FsmEvent* event, FsmOutput* out) {
  MissionRemedies& remedies = mission_.remedies();
  traj.id = next_id_++;
  // A plan cut to a hold where the vehicle is (unknown space right ahead), again and again at the
  // same place: turning to look has not shown the way (it may lie above or below the camera's
  // view). Back off along the flown path, where the camera sees more, and re-route from there.
  // (A hold, or a stop a few centimetres on: the cut plans of a vehicle that hovers at the edge.)
  const bool look_hold = traj.stops_before_unknown && request.start.velocity.norm() < config_.stopped_speed_mps &&
                         (traj.spline.evaluate(traj.spline.duration()) - traj.spline.evaluate(0.0)).norm() < 0.3;
  remedies.countLookHold(look_hold, request.start.position, t);
  std::optional<ExecTrajectory> backoff;
  std::string backoff_report;
  bool to_anchor = false;
  if (remedies.lookHoldBackoffDue(t)) {
    // From the takeover time, as the plan it replaces (the hold published last tick may start
    // between now and then: taking over at t would leave it out).
    backoff = backoffLocked(traj.start_time_s, map, &backoff_report, &to_anchor);
    if (backoff && backoff->has_heading_target) backoff.reset();  // a look again: no use
  }
  // Holding there is no progress: it does not restart the mission's time limit, and ends the
  // mission when that passes.
  if (look_hold && !backoff && config_.global_route && remedies.noPlanForTheLimit(t)) {
    char text[160];
    std::snprintf(text, sizeof(text), "held at the edge of the known space, no way on for the mission's time limit of %.0f s",
                  remedies.missionLimit());
    giveUpLocked(t, map, GoalStatus::kGivenUp, ReplanStatus::kSuccess, text, out);
    event->fallback = "give_up";
    event->message += (event->message.empty() ? "" : "; ") + out->event->message;
    return;
  }
  if (backoff) {
    // Holding there did not show the way on: a stall. The route rebuilt after the back-off weighs
    // against the place (another opening, another side), as the progress remedy's routes do. (Not
    // after a back-off to the anchor: the camera's blind zone held it there, not the way.)
    if (!to_anchor) mission_.stalledAtHold();
    event->message += (event->message.empty() ? "" : "; ") + std::string("held at the edge of the known space ") +
                      std::to_string(config_.max_look_holds) + " times; " + backoff_report;
    startManoeuvreLocked(*backoff, true, event, out, backoff_report);
    return;
  }
  replaceCurrentLocked(traj);
  collision_ahead_ = false;
  remedies.planSucceeded(t, look_hold);
  if (traj.stops_before_unknown) {  // in the event log: where the vehicle waits on its map
    char text[96];
    std::snprintf(text, sizeof(text), "stops before unknown space, braking from +%.2f s",
                  traj.brake_start_s - traj.start_time_s);
    event->message = text;
  }
  event->published = true;
  out->trajectory = traj;
  setState(FsmState::kExecTraj, out, "");
}

void ReplanFsm::planFailedLocked(double t, const EsdfMap& map, ReplanStatus status, FsmEvent::Trigger trigger,
                                 bool superseded, double finished, FsmEvent* event, FsmOutput* out) {
  MissionRemedies& remedies = mission_.remedies();
  const bool generating = state_ == FsmState::kGenNewTraj;
  remedies.planFailed();
  // What the vehicle does now (MissionRemedies); a discarded plan keeps its label unless it ends the
  // mission. A braking trajectory that took over while planning (superseded) owns the state now.
  const bool late = status == ReplanStatus::kSuccess;
  if (late) event->fallback = superseded ? "discarded_superseded" : "discarded_late";
  const bool at_rest = !current_ || t >= current_->endTime();
  MissionRemedies::AfterFailure remedy;
  if (!superseded) remedy = remedies.afterFailure(t, status, generating, at_rest);
  const bool giving_up = remedy.give_up.has_value();
  if (giving_up) {
    event->fallback = "give_up";
  } else if (!superseded && !late) {
    const bool moving = current_ && !current_->manoeuvre() && t < current_->endTime();
    event->fallback = generating && !moving ? "hover_retry" : "keep_current";
  }
  // At rest too close to an obstacle for the replanner to start: a slow escape first, then (as
  // after braking) a new reference from where it ends; with none, or when first plans keep failing
  // from rest, a back-off along the flown path, and a re-route from there.
  std::string escape_report;
  std::optional<ExecTrajectory> escape;
  if (remedy.escape) escape = escapeTrajectory(takeoverStateLocked(t), t, map, config_.manoeuvres(), &escape_report);
  bool backoff = false;
  if (!escape && remedy.backoff) {
    std::string report;
    escape = backoffLocked(t, map, &report);
    backoff = escape.has_value();
    escape_report += (escape_report.empty() ? "" : "; ") + report;
  }
  if (!escape && !escape_report.empty()) event->message += "; " + escape_report;
  // Still failing at rest with no back-off left: the stall remedy (a zone ahead, a re-route) now,
  // not when the progress clock runs out.
  if (!escape && !superseded && generating && at_rest && !giving_up) remedies.forceStallAfterFailure();
  if (event->fallback == "hover_retry") rest_retry_after_s_ = finished + config_.rest_retry_interval_s;
  if (event->fallback == "keep_current") moving_retry_after_s_ = finished + config_.moving_retry_interval_s;
  if (!superseded && !giving_up && !escape && remedies.rerouteAfterFailure(status)) {
    mission_.markRouteStale();
    // A moving vehicle: a new reference from the takeover state, next tick (unless new goals
    // arrived while planning: they are flown instead).
    if (!generating && !mission_.pending()) mission_.pendRemaining(true);
  }
  if (escape) {
    event->message += "; " + escape_report;
    startManoeuvreLocked(*escape, backoff, event, out, escape_report);
  } else if (giving_up) {
    giveUpLocked(t, map, GoalStatus::kGivenUp, status, *remedy.give_up, out);
    event->published = out->trajectory.has_value();  // the stop of a moving vehicle
    event->message += "; " + out->event->message;
  } else if (!superseded && !generating) {
    setState(FsmState::kExecTraj, out, "");
    collision_ahead_ = collision_ahead_ || trigger == FsmEvent::Trigger::kCollisionAhead;
  }
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
    mission_.pauseProgress(t);
    if (mission_.pending() && state_ == FsmState::kWaitTarget) mission_.refusePending(GoalStatus::kInputsStale);
    if (!inputs_reported_) {
      inputs_reported_ = true;
      out.say("inputs stale (" + stale + "): not planning");
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
    out.say("inputs fresh again");
  }
  if (current_ && !current_->manoeuvre()) flown_.record(takeoverStateLocked(t).position);  // for back-offs
  if (handleStallLocked(t, map, &out)) return out;
  if (config_.global_route) {
    const FsmState before = state_;
    double searched_until = NAN;
    routeLocked(t, map, &lock, &out, now, &searched_until);
    if (out.event || state_ != before) return out;  // given up, or a braking took over meanwhile
    // A long search: plan at the next tick, from then (a plan from t would start late).
    if (searched_until - t > 0.5 * takeover_delay_s_) return out;
  }
  const Tick tick{t, map, &lock, &out, now};
  switch (state_) {
    case FsmState::kInit:
      if (inputs_.haveOdometry()) setState(FsmState::kWaitTarget, &out, "odometry received");
      if (mission_.pending() && startGoalsLocked(t, map, &out)) plan(tick, FsmEvent::Trigger::kNewGoal);
      break;
    case FsmState::kWaitTarget:
      if (mission_.pending() && startGoalsLocked(t, map, &out)) plan(tick, FsmEvent::Trigger::kNewGoal);
      break;
    case FsmState::kGenNewTraj: {
      // A retry rebuilds the reference from where the vehicle will be, so it starts from its state.
      const bool fresh = mission_.pending();
      if (!fresh && mission_.remedies().failures() > 0 && t < rest_retry_after_s_) break;  // paced retries at rest
      if (!fresh) mission_.pendRemaining(false);
      if (startGoalsLocked(t, map, &out))
        plan(tick, fresh ? FsmEvent::Trigger::kNewGoal : FsmEvent::Trigger::kRetry);
      else if (!fresh)
        referenceNotRebuiltLocked(t, map, &out);
      break;
    }
    case FsmState::kExecTraj:
    case FsmState::kReplanTraj: execTrajLocked(tick, jumped); break;
    case FsmState::kEmergencyStop: stoppedLocked(tick); break;
  }
  return out;
}

void ReplanFsm::execTrajLocked(const Tick& tick, bool jumped) {
  const double t = tick.t;
  if (mission_.pending()) {
    const FsmEvent::Trigger trigger = mission_.rerouting() ? FsmEvent::Trigger::kReroute : FsmEvent::Trigger::kNewGoal;
    if (startGoalsLocked(t, tick.map, tick.out)) plan(tick, trigger);
    return;
  }
  if (!current_) {
    setState(FsmState::kWaitTarget, tick.out, "no trajectory");
    return;
  }
  const bool ended = t >= current_->endTime();
  if (current_->ends_at_goal && ended) {
    if (mission_.atLastGoal(odom_position_)) {
      tick.out->goal_reached = true;
      mission_.reached();  // done: a later stop (e.g. an odometry jump at the hover) flies nowhere
      setState(FsmState::kWaitTarget, tick.out, "goal reached");
    }
    return;
  }
  // A trajectory cut before unknown space is replanned before its stop begins, so a plan on the
  // grown map takes over while the vehicle still cruises; one that ends moving, early enough
  // before it runs out that a failed plan still leaves retries before checkSafety() must brake.
  const double half_interval = 0.5 * config_.replan_interval_s;
  const bool running_out =
      !current_->ends_at_goal &&
      (ended || current_->endTime() - t <= stopTimeLocked(t, config_.brake_acc_mps2) + half_interval ||
       (current_->stops_before_unknown && current_->brake_start_s - t <= takeover_delay_s_ + half_interval));
  const bool periodic = !current_->ends_at_goal && t - current_->start_time_s >= config_.replan_interval_s;
  // The route ahead newly blocked in the map: re-routed at the next tick (a collision ahead or a
  // time jump is planned for first).
  if (!jumped && !collision_ahead_ && !current_->manoeuvre() && routeBlockedLocked(t, tick.map, tick.out)) return;
  const bool retry = mission_.remedies().failures() > 0;
  if (jumped) {
    plan(tick, FsmEvent::Trigger::kTimeJump);
  } else if (collision_ahead_) {
    plan(tick, retry ? FsmEvent::Trigger::kRetry : FsmEvent::Trigger::kCollisionAhead);
  } else if (running_out || periodic) {
    // Retries of a failed periodic replan are paced while the trajectory flown stays safe for a
    // while (moving_retry_interval_s); when it runs out soon, at every tick.
    if (retry && !running_out && t < moving_retry_after_s_) return;
    plan(tick, retry ? FsmEvent::Trigger::kRetry : FsmEvent::Trigger::kPeriodic);
  }
}

void ReplanFsm::stoppedLocked(const Tick& tick) {
  const double t = tick.t;
  if (!atRestLocked(t)) return;
  // At rest after an odometry jump: the hover is the anchor (the camera cannot see beside and
  // behind it, and the map it flew through was in the old frame).
  if (std::exchange(anchor_at_rest_, false)) known_anchor_ = takeoverStateLocked(t).position;
  // Stopped: a new reference from here through the mission's goals (or the newer ones).
  const bool fresh = mission_.pending();
  if (!fresh) mission_.pendRemaining(false);
  if (!mission_.pending()) {
    setState(FsmState::kWaitTarget, tick.out, "stopped, no mission");
    return;
  }
  bool started = startGoalsLocked(t, tick.map, tick.out);
  if (!started && fresh && mission_.status() != GoalStatus::kReferenceFailed && !mission_.empty()) {
    // Newer goals refused (out of the map, in an obstacle: said in the message and the goal
    // status) are no reason to drop the mission: it goes on from here, as it would in flight.
    const GoalStatus refused = mission_.status();
    mission_.pendRemaining(false);
    started = startGoalsLocked(t, tick.map, tick.out);
    if (started) mission_.setStatus(refused);
  }
  if (!started) {
    referenceNotRebuiltLocked(t, tick.map, tick.out);
    return;
  }
  // A new reference from rest is a new strategy: it gets its own max_plan_failures tries (the
  // failures of the replans that led here do not count against it).
  mission_.remedies().newStart();
  plan(tick, FsmEvent::Trigger::kRetry);
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
  mission_.invalidateRoute();  // once stopped, the reference is rebuilt along a new route
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
  std::string stale;
  const bool fresh = inputs_.fresh(t, &stale);
  const SafetyCheck::Verdict v =
      safety_.check(t, {&*current_, previous_ ? &*previous_ : nullptr, takeover_delay_s_, state_ == FsmState::kWaitTarget},
                    {inputs_.odometryStamp(), odom_position_, odom_velocity_}, fresh ? nullptr : &stale, map);
  if (v.collision_ahead) collision_ahead_ = true;
  switch (v.action) {
    case SafetyCheck::Verdict::Action::kNone: break;
    case SafetyCheck::Verdict::Action::kBrake: emergencyStopLocked(t, map, v.why, &out, nullptr, v.status); break;
    case SafetyCheck::Verdict::Action::kHoldAtMeasured:
      emergencyStopLocked(t, map, v.why, &out, &v.from, v.status);
      current_->reanchor = out.trajectory->reanchor = true;  // the step to the measured position is deliberate
      out.odometry_jumped = true;
      anchor_at_rest_ = true;
      flown_.clear();  // in the old frame
      mission_.forgetStallZones();
      mission_.invalidateRoute();
      break;
  }
  return out;
}

}  // namespace topo_planner
