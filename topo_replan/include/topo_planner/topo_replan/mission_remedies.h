#pragma once
// The mission's remedies when it is stuck, and the counts they go by, in one place. The replanning
// FSM (replan_fsm.h) asks which remedy comes next and carries it out (a manoeuvre of manoeuvres.h,
// a re-route, a give-up); it counts no failures or stalls itself. With the global route:
//
//   situation                                          remedy                                   rule
//   a plan fails; the way looks blocked (kNoPath,     re-route at once (once until a plan      rerouteAfterFailure
//     kGoalInCollision)                                succeeds)
//   plans keep failing                                 re-route every reroute_after_failures    rerouteAfterFailure
//   at rest, the replanner cannot start               escape up the distance field; with       afterFailure
//     (kStartInCollision)                              none, back off
//   at rest, max_plan_failures failed plans in a row  back off along the flown path (at most   afterFailure
//                                                      max_backoffs a mission)
//   ... with no back-off left (or none possible)      the stall remedy at once                 forceStallAfterFailure
//   plans cut to a hold at one place max_look_holds   back off                                 lookHoldBackoffDue
//     times, for look_hold_min_s
//   no progress for progress_timeout_s (times the     a zone ahead and a re-route; every       stall, stallBacksOff
//     stalls since the last gain)                      second stall, stop and back off
//   no successful plan (or progress) for the          give up                                  afterFailure, stall,
//     mission's time limit                                                                     noPlanForTheLimit
// Without the global route: give up after max_plan_failures failed first plans.
//
// Not thread-safe: the FSM calls it under its mutex.

#include <optional>
#include <string>

#include <Eigen/Core>

#include "topo_planner/topo_replan/topo_replanner.h"

namespace topo_planner {

class MissionRemedies {
 public:
  struct Config {
    bool global_route = true;          ///< false: no remedies but the give-up after max_plan_failures
    int max_plan_failures = 30;        ///< failed first plans at rest before a back-off (or the give-up)
    int reroute_after_failures = 3;    ///< re-route every this many failed plans in a row
    int max_backoffs = 3;              ///< back-offs per mission
    int max_look_holds = 5;            ///< holds at one place in a row before a back-off ...
    double look_hold_min_s = 2.5;      ///< ... held for at least this long [s]
    double progress_timeout_s = 10.0;  ///< a stall: no progress for this long [s]
    /// No successful plan (or progress) for this long gives the mission up [s]; 0: 60 s or 4 times
    /// the duration of its first reference, whichever is longer.
    double mission_timeout_s = 0.0;
  };

  /// What a failed plan calls for (afterFailure).
  struct AfterFailure {
    std::optional<std::string> give_up;  ///< give the mission up, for this reason
    bool escape = false;                 ///< try an escape up the distance field first
    bool backoff = false;                ///< with no escape, try a back-off along the flown path
  };

  /// The stall rule's verdict at a tick (stall).
  enum class Stall { kNone, kGiveUp, kRemedy };

  explicit MissionRemedies(const Config& config) : config_(config) {}
  void setConfig(const Config& config) { config_ = config; }

  // The counts.
  /// A new mission starting at t whose first reference lasts reference_s: its time limit, no
  /// back-offs or stalls yet.
  void newMission(double t, double reference_s);
  /// A reference (re)built; `last_gain_s` is its progress tracker's last gain.
  void referenceStarted(double last_gain_s) { stall_gain_s_ = last_gain_s; }
  /// A new start (a manoeuvre, a reference from rest): the failed plans are counted anew.
  void newStart();
  void planFailed() { ++failures_; }
  /// New goals: a blocked way may be re-routed at once again.
  void goalsGiven() { rerouted_since_success_ = false; }
  /// A plan published at t; a hold at the edge of the known space is no progress.
  void planSucceeded(double t, bool hold);
  /// A route search ended: the failures that call for the next re-route are counted from here.
  void routeSearched() { failures_at_reroute_ = failures_; }
  void backedOff();
  void missionEnded();
  /// A time jump: the times of the old clock move with it.
  void shift(double dt);
  int failures() const { return failures_; }
  double missionLimit() const { return mission_limit_s_; }

  // Which remedy.
  /// A plan failed (counted: planFailed) with `status`: a first plan (GEN_NEW_TRAJ: no trajectory of
  /// the mission to keep) or a replan, the vehicle at rest or not.
  AfterFailure afterFailure(double t, ReplanStatus status, bool first_plan, bool at_rest) const;
  /// After a failed first plan at rest that led to no manoeuvre: true (and counted) when the
  /// failures call for the stall remedy now (no back-off left, or none possible).
  bool forceStallAfterFailure();
  /// After a failed plan that led to no manoeuvre nor give-up: true (and counted) when it calls for
  /// a re-route.
  bool rerouteAfterFailure(ReplanStatus status);
  /// A published plan from `start` (at t) that holds at the edge of the known space, or not.
  void countLookHold(bool hold, const Eigen::Vector3d& start, double t);
  /// The holds at one place call for a back-off.
  bool lookHoldBackoffDue(double t) const;
  const Eigen::Vector3d& lookHoldPosition() const { return look_hold_position_; }
  /// No successful plan (or only holds) for the mission's time limit.
  bool noPlanForTheLimit(double t) const { return t - last_progress_s_ > mission_limit_s_; }
  /// Progress measured (MissionProgress::lastGain()): a gain starts the stall remedies over.
  void progressMeasured(double last_gain_s);
  /// A stop begun as a stall remedy has ended at rest: back off now (true, once).
  bool backoffNowStopped(bool stopped);
  /// The stall rule at a tick, `since_gain_s` after the last gain of progress: give up, a remedy
  /// (counted; *forced when failures at rest asked for it), or nothing now (a manoeuvre under way,
  /// new goals pending, a stop before a back-off).
  Stall stall(double since_gain_s, bool manoeuvring, bool goals_pending, bool* forced);
  /// The remedy of the stall just counted backs off (true; stop first when moving) or re-routes.
  bool stallBacksOff() const { return stalls_ % 2 == 0 && backoffs_ < config_.max_backoffs; }
  /// A moving vehicle stops for the stall's back-off; it backs off once stopped.
  void stopThenBackOff() { backoff_when_stopped_ = true; }

 private:
  Config config_;
  int failures_ = 0;              // failed plans in a row
  int failures_at_stall_ = 0;     // failures_ when the failures last forced the stall remedy
  int failures_at_reroute_ = 0;   // failures_ at the last route search
  bool rerouted_since_success_ = false;  // an immediate re-route was done since the last published plan
  int backoffs_ = 0;              // in this mission
  int look_holds_ = 0;            // plans cut to a hold at look_hold_position_ in a row
  Eigen::Vector3d look_hold_position_ = Eigen::Vector3d::Zero();
  double look_hold_since_s_ = 0.0;  // the first hold there [s]
  double last_progress_s_ = 0.0;    // the mission's start or its last successful plan (not a hold) [s]
  double mission_limit_s_ = INFINITY;
  int stalls_ = 0;                  // stall remedies since the last gain of progress
  bool force_stall_ = false;        // failures at rest asked for the stall remedy now
  double stall_gain_s_ = 0.0;       // the progress tracker's last gain when stalls_ was last reset
  bool backoff_when_stopped_ = false;  // a stall remedy: back off once the stop it began has ended
};

}  // namespace topo_planner
