#pragma once
// The mission: its goals (given, pending, reached), its global route and the minimum-snap reference
// through them, the progress along its way, the places it stalled at, and which remedy comes next
// when it is stuck (MissionRemedies, which it owns). The replanning FSM (replan_fsm.h) decides when
// (its states) and flies what follows (plans, manoeuvres, stops); the mission holds what is asked
// of the flight and answers questions about it.
//
//   goals       setGoals() -> give() -> pending -> start(): the reference (through the route when
//               there is one for these goals) -> passWaypoints() -> atLastGoal() -> reached()
//   route       prepareRouteSearch() -> searchRoute() -> applyRoute(): searched when the goals
//               change, after a stop (invalidateRoute), when a remedy marks it stale, or when
//               routeBlocked() sees a wall newly across it ahead; a search overtaken meanwhile (new
//               goals, a stop: the route epoch moved on) is dropped
//               The route is path_searching's GlobalRouter (A* over the whole map window at the
//               guide search's clearance, unknown space free, shortened): the reference goes along
//               it, so the local search, which samples around the reference, looks along it. A goal
//               is unreachable when no route reaches it in the height band at that clearance, not
//               even with the region within max_backoff_length_m + 1 m of the vehicle relaxed (a
//               narrow slot it braked in)
//   stalls      checkProgress(): no progress along the way for progress_timeout_s is a stall; each
//               one marks a zone ahead that later route searches avoid
//   the end     reached(), or end() (given up, unreachable)
//
// Not thread-safe: ReplanFsm calls it under its mutex, except searchRoute(), which it calls on the
// planning thread with the mutex released: that touches only the route searches, which only the
// planning thread uses (setConfig(), which replaces them, is called from tick() too).

#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "topo_planner/path_searching/global_router.h"
#include "topo_planner/plan_env/esdf_map.h"
#include "topo_planner/topo_replan/mission_progress.h"
#include "topo_planner/topo_replan/mission_remedies.h"
#include "topo_planner/topo_replan/polynomial_trajectory.h"
#include "topo_planner/topo_replan/replan_fsm_config.h"
#include "topo_planner/topo_replan/route_watch.h"

namespace topo_planner {

enum class GoalStatus {
  kAccepted,
  kNoOdometry,      ///< no (valid) odometry yet
  kInvalidInput,    ///< empty list, NaN/inf coordinates
  kGoalInObstacle,  ///< a goal is closer than goal_clearance_m to a known obstacle
  kGoalOutOfMap,    ///< a goal lies outside the map window
  kReferenceFailed, ///< no minimum-snap reference through the goals
  kInputsStale,     ///< depth or odometry is stale or has never arrived (see InputHealth)
  kUnreachable,     ///< the global route search proves a goal unreachable in the known map
  kGivenUp,         ///< the mission was given up: no trajectory within its time limit (or tries)
};
const char* toString(GoalStatus status);

class Mission {
 public:
  /// The FSM's settings: the mission reads its goal, route, progress and remedy fields.
  using Config = ReplanFsmConfig;
  /// The most places stalled at that the route searches avoid (the oldest dropped beyond).
  static constexpr size_t kMaxStallZones = 32;

  explicit Mission(const Config& config);
  /// New settings: the route searches are rebuilt and the route searched again at the next reference.
  void setConfig(const Config& config);

  // --- Goals -----------------------------------------------------------------------------------
  /// Goals against the map: kAccepted, or kGoalOutOfMap / kGoalInObstacle with why (the goal's index).
  GoalStatus check(const std::vector<Eigen::Vector3d>& goals, const EsdfMap& map, std::string* why) const;
  /// New goals that passed the FSM's checks: pending until start(); a new mission.
  void give(const std::vector<Eigen::Vector3d>& goals);
  bool pending() const { return goals_pending_; }
  /// The pending goals are a re-route of the mission flown, not new goals.
  bool rerouting() const { return rerouting_; }
  /// The goals not reached yet become the pending ones (for a rebuilt reference; a re-route when
  /// `reroute`).
  void pendRemaining(bool reroute);
  /// The pending goals are refused for `status` (e.g. stale inputs): they change nothing.
  void refusePending(GoalStatus status);
  /// The goals of the mission not reached yet (the last one stays until the mission ends).
  std::vector<Eigen::Vector3d> remaining() const;
  bool empty() const { return goals_.empty(); }
  /// The vehicle at `position`: intermediate goals it came within waypoint_reached_radius_m of are done.
  void passWaypoints(const Eigen::Vector3d& position);
  /// The vehicle at `position` is within goal_tolerance_m of the last goal.
  bool atLastGoal(const Eigen::Vector3d& position) const;
  /// The last goal was reached: the mission is over (a later stop flies nowhere).
  void reached();
  /// The mission ends for `status` (given up, unreachable): goals, route and progress cleared;
  /// goals given since stay pending.
  void end(GoalStatus status, const EsdfMap& map);
  /// The status of the last goals given, or of the mission's end.
  GoalStatus status() const { return status_; }
  GoalStatus setStatus(GoalStatus status) { return status_ = status; }

  // --- The reference ---------------------------------------------------------------------------
  /// What start() did.
  struct Started {
    bool ok = false;           ///< a reference was built; the pending goals are the mission's
    bool goals_valid = false;  ///< the goals passed their checks on the map (the reference may still fail)
    std::string summary;       ///< ok: "new reference, 2 goal(s), along the global route"; else why refused
  };
  /// Takes up the pending goals at time t: checks them on `map` and builds the reference from
  /// `start` (the state the first plan on it takes over at) through the route when there is one for
  /// these goals, else straight through them, within `limits`. A new mission starts its time limit
  /// and its progress; a rebuilt one re-bases the progress. Refused: the status says why.
  Started start(double t, FlatState start, const EsdfMap& map, const ReferenceConfig& limits);
  const PolynomialTrajectory& reference() const { return reference_; }
  /// The reference time at which it passes the next intermediate goal (within
  /// waypoint_reached_radius_m), after `from_s`: the local goal stays before it. Not finite: none.
  double localGoalLimit(double from_s) const;

  // --- The global route ------------------------------------------------------------------------
  /// One route search: its question, and the epoch it was asked in.
  struct RouteSearch {
    std::vector<Eigen::Vector3d> goals;
    Eigen::Vector3d start = Eigen::Vector3d::Zero();  ///< filled in by the caller
    uint64_t epoch = 0;
    bool rerouting = false;
  };
  /// Its answer.
  struct RouteFound {
    Path route;
    SearchStatus status = SearchStatus::kSuccess;
    size_t failed_leg = 0;
    int expansions = 0;
    bool near_start = false;  ///< some leg has a route only with the start region relaxed
  };
  /// What applyRoute() made of it.
  enum class RouteOutcome {
    kOvertaken,    ///< new goals, a stop or an odometry jump meanwhile: dropped
    kFound,        ///< a new route
    kNone,         ///< no proof either way: references go straight through the goals
    kRefused,      ///< new goals proved unreachable: refused (the mission flown goes on)
    kUnreachable,  ///< the mission's goals proved unreachable: give it up
  };
  /// A search is due for the goals the next reference goes through (the pending ones, else those
  /// left): nullopt when the route for them is fresh, or when start() will refuse them. Sets the
  /// places stalled at on the searches. Call with the lock held.
  std::optional<RouteSearch> prepareRouteSearch(const EsdfMap& map);
  /// The search (each leg at the route's clearance; the first, failing, again with the region
  /// around the vehicle relaxed). Call without the lock (see the file comment).
  RouteFound searchRoute(const EsdfMap& map, const RouteSearch& search) const;
  /// Takes the answer (with the lock held again); *text says what came of it, for the log.
  RouteOutcome applyRoute(const RouteSearch& search, RouteFound found, const EsdfMap& map, std::string* text);
  /// The route must be searched again, and a search under way answers an old question (a stop,
  /// a manoeuvre, an odometry jump).
  void invalidateRoute();
  /// The route is searched again at the next reference.
  void markRouteStale() { route_stale_ = true; }
  const Path& route() const { return route_; }
  /// The route check is due at t (route_check_length_m on, a route for the goals left, and
  /// route_check_interval_s since the last one): the caller works out the position only then.
  bool routeCheckDue(double t) const;
  /// The route check of the vehicle at `position` at time t (when due): true when the map shows a
  /// part of the route ahead newly blocked; the re-route is then pending, its reason in *text and in
  /// takeRerouteReason().
  bool routeBlocked(double t, const Eigen::Vector3d& position, const EsdfMap& map, std::string* text);
  /// Why the pending re-route (said once, in its planning call's event); empty when none.
  std::string takeRerouteReason();

  // --- Progress and stalls ---------------------------------------------------------------------
  /// The stall rule's verdict at a tick (checkProgress).
  struct Stall {
    enum class Kind {
      kNone,         ///< nothing to do
      kBackOffNow,   ///< a stop begun as a stall remedy has ended: back off now
      kGiveUp,       ///< no progress for the mission's time limit: give it up (why)
      kRemedy,       ///< a stall (counted, its zone marked, the route stale): back off or re-route
    };
    Kind kind = Kind::kNone;
    std::string why;
    bool backs_off = false;  ///< kRemedy: back off (stopping first when moving), else re-route
  };
  /// The stall rule applies (global_route, progress_timeout_s on, a mission being tracked): the
  /// caller works out the position only then.
  bool checksProgress() const;
  /// The stall rule (progress_timeout_s) with the vehicle flying at `position` at time t: measures
  /// the progress and says which remedy is due. `stopped` when the vehicle is at rest in a stop,
  /// `manoeuvring` when a manoeuvre is under way.
  Stall checkProgress(double t, const Eigen::Vector3d& position, bool stopped, bool manoeuvring);
  /// Held at the edge of the known space until a back-off: a stall there (a zone ahead along the
  /// way, or around the hold, and a re-route).
  void stalledAtHold();
  /// Nothing is planned (stale inputs) until t: no stall, the progress clock pauses.
  void pauseProgress(double t);
  /// The places stalled at are in an old frame (odometry jump): forgotten.
  void forgetStallZones() { stall_zones_.clear(); }
  const std::vector<GlobalRouter::Zone>& stallZones() const { return stall_zones_; }
  /// A time jump: every time of the old clock moves by dt.
  void shift(double dt);
  MissionRemedies& remedies() { return remedies_; }

 private:
  void addStallZone(const Eigen::Vector3d& center);

  Config config_;
  // Goals.
  std::vector<Eigen::Vector3d> goals_;          // the current mission
  size_t next_goal_ = 0;                        // goals_[next_goal_..] are not reached yet
  std::vector<Eigen::Vector3d> pending_goals_;  // given (or pended), taken up by start()
  bool goals_pending_ = false;
  bool rerouting_ = false;                      // the pending goals are a re-route of the mission
  bool new_mission_ = false;                    // the next start() begins a mission
  GoalStatus status_ = GoalStatus::kAccepted;
  PolynomialTrajectory reference_;
  // The global route.
  std::unique_ptr<GlobalRouter> router_;
  std::unique_ptr<GlobalRouter> start_router_;  // ... relaxed farther from the start: the proof of unreachability
  Path route_;                                  // through route_goals_; empty: straight references
  std::vector<Eigen::Vector3d> route_goals_;
  RouteWatch route_watch_;                      // the route check of route_ (reset with it)
  bool route_stale_ = true;
  uint64_t route_epoch_ = 0;                    // a route searched in an earlier epoch is stale
  double route_checked_s_ = -INFINITY;
  std::string reroute_reason_;
  // Progress and remedies.
  MissionProgress progress_;                    // the distance left along the mission's way
  double progress_tick_s_ = NAN;                // the last tick that measured progress (or paused it) [s]
  std::vector<GlobalRouter::Zone> stall_zones_; // where missions stalled: later route searches avoid them
  MissionRemedies remedies_;
};

}  // namespace topo_planner
