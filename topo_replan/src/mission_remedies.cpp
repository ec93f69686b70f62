#include "topo_planner/topo_replan/mission_remedies.h"

#include <algorithm>
#include <cstdio>
#include <utility>

namespace topo_planner {

void MissionRemedies::newMission(double t, double reference_s) {
  last_progress_s_ = t;
  mission_limit_s_ = config_.mission_timeout_s > 0.0 ? config_.mission_timeout_s : std::max(60.0, 4.0 * reference_s);
  backoffs_ = 0;
  stalls_ = 0;
  force_stall_ = false;
  backoff_when_stopped_ = false;
}

void MissionRemedies::newStart() {
  failures_ = 0;
  failures_at_stall_ = 0;
  failures_at_reroute_ = 0;
}

void MissionRemedies::planSucceeded(double t, bool hold) {
  failures_ = 0;
  failures_at_stall_ = 0;
  force_stall_ = false;
  rerouted_since_success_ = false;
  failures_at_reroute_ = 0;
  if (!hold) last_progress_s_ = t;
}

void MissionRemedies::backedOff() {
  ++backoffs_;
  look_holds_ = 0;
}

void MissionRemedies::missionEnded() {
  rerouted_since_success_ = false;
  failures_ = 0;
  failures_at_stall_ = 0;
  backoff_when_stopped_ = false;
}

void MissionRemedies::shift(double dt) {
  last_progress_s_ += dt;
  look_hold_since_s_ += dt;
}

MissionRemedies::AfterFailure MissionRemedies::afterFailure(double t, ReplanStatus status, bool first_plan,
                                                            bool at_rest) const {
  AfterFailure r;
  if (first_plan) {
    char text[160];
    if (!config_.global_route && failures_ >= config_.max_plan_failures) {
      r.give_up = "no trajectory after " + std::to_string(failures_) + " tries";
    } else if (config_.global_route && noPlanForTheLimit(t)) {
      std::snprintf(text, sizeof(text), "no trajectory for the mission's time limit of %.0f s (%d tries in a row failed)",
                    mission_limit_s_, failures_);
      r.give_up = text;
    }
  }
  if (r.give_up) return r;
  // At rest too close to an obstacle for the replanner to start: a slow escape first.
  r.escape = status == ReplanStatus::kStartInCollision && at_rest;
  // First plans keep failing from rest (or it cannot start and has no way up the distance field):
  // back off along the flown path, and re-route from there.
  r.backoff = config_.global_route && first_plan && at_rest && backoffs_ < config_.max_backoffs &&
              (status == ReplanStatus::kStartInCollision || failures_ >= config_.max_plan_failures);
  return r;
}

bool MissionRemedies::forceStallAfterFailure() {
  if (!config_.global_route || failures_ - failures_at_stall_ < config_.max_plan_failures) return false;
  force_stall_ = true;
  failures_at_stall_ = failures_;
  return true;
}

bool MissionRemedies::rerouteAfterFailure(ReplanStatus status) {
  // The way looks blocked (no guide path, no free local goal) or plans keep failing.
  const bool blocked = status == ReplanStatus::kNoPath || status == ReplanStatus::kGoalInCollision;
  if (!config_.global_route ||
      !((blocked && !rerouted_since_success_) || failures_ - failures_at_reroute_ >= config_.reroute_after_failures))
    return false;
  rerouted_since_success_ = true;
  failures_at_reroute_ = failures_;
  return true;
}

void MissionRemedies::countLookHold(bool hold, const Eigen::Vector3d& start, double t) {
  // (A hold, or a stop a few centimetres on: the cut plans of a vehicle that hovers at the edge.)
  const bool same_place = look_holds_ > 0 && (start - look_hold_position_).norm() < 0.3;
  look_holds_ = hold ? (same_place ? look_holds_ + 1 : 1) : 0;
  if (hold && !same_place) {
    look_hold_position_ = start;
    look_hold_since_s_ = t;
  }
}

bool MissionRemedies::lookHoldBackoffDue(double t) const {
  // (Held for look_hold_min_s too: the plans of a hold come every tick, and the camera turning
  // round towards the way on needs its time; 5 holds in 0.25 s backed a vehicle off that had just
  // reached a goal and turned to the next one behind it.)
  return config_.global_route && look_holds_ >= config_.max_look_holds &&
         t - look_hold_since_s_ >= config_.look_hold_min_s && backoffs_ < config_.max_backoffs;
}

void MissionRemedies::progressMeasured(double last_gain_s) {
  if (last_gain_s == stall_gain_s_) return;
  stall_gain_s_ = last_gain_s;
  stalls_ = 0;
}

bool MissionRemedies::backoffNowStopped(bool stopped) {
  if (!backoff_when_stopped_ || !stopped) return false;
  backoff_when_stopped_ = false;
  return true;
}

MissionRemedies::Stall MissionRemedies::stall(double since_gain_s, bool manoeuvring, bool goals_pending, bool* forced) {
  if (since_gain_s > mission_limit_s_) return Stall::kGiveUp;
  *forced = std::exchange(force_stall_, false);
  if ((since_gain_s < (stalls_ + 1) * config_.progress_timeout_s && !*forced) || manoeuvring || goals_pending ||
      backoff_when_stopped_)
    return Stall::kNone;
  ++stalls_;
  return Stall::kRemedy;
}

}  // namespace topo_planner
