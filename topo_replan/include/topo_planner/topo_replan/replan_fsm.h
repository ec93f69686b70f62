#pragma once
// The replanning state machine of the paper's system (Sect. V and VI-C: "the local planner
// periodically checks the global reference within the horizon and replans when it collides"), kept
// free of ROS so its transitions are tested without a roscore. The planner node feeds it odometry,
// goals and the map, and publishes what it returns.
//
// States
//   INIT            no odometry yet; goals are refused (kNoOdometry)
//   WAIT_TARGET     hovering, no mission
//   GEN_NEW_TRAJ    a new global reference (minimum snap from the current state through the goals)
//                   is built and the first local trajectory planned on it
//   EXEC_TRAJ       flying the current local trajectory; it is checked against the latest map every
//                   tick, and replanned when it collides ahead, after replan_interval_s of
//                   execution so that the horizon moves along the reference, or when it would run
//                   out (end moving) within the stopping time plus replan_interval_s / 2
//   REPLAN_TRAJ     planning from the state on the current trajectory at the time the new one takes
//                   over (now + a takeover delay that adapts to the planning time); on failure the current one is kept while it is
//                   safe and planning is retried every tick
//   EMERGENCY_STOP  no safe trajectory and a collision closer than the stop at the back-up
//                   deceleration (commit_brake_acc_mps2 with the known-space commitment) needs, a stale
//                   input (depth, odometry), or odometry that jumped away from the commanded state:
//                   a braking trajectory (constant deceleration along the current trajectory's path,
//                   at brake_acc_mps2, harder up to max_brake_acc_mps2 when that would not stop in
//                   time) is executed; once stopped and the inputs are fresh, a new reference from
//                   the stopping point through the goals not yet reached is generated. A vehicle at
//                   rest where the replanner cannot start (closer than its clearance to an obstacle)
//                   first flies a short, slow escape up the distance field, also in this state.
//
// Every trajectory it returns has passed a collision and feasibility check on the map it was
// planned on (the replanner's final check; the braking trajectory is checked too, and its result
// reported, since braking is the last safe action left), and is cut to the known space.
//
// The FSM keeps the states, the transitions and the planning calls; it asks its units and carries
// out what they say. Who decides what:
//
//   unit (header)                       decides / holds
//   Mission (mission.h)                 the goals, the global route (searched with the mutex released,
//                                       re-searched when the goals change, after a stop, when a remedy
//                                       asks, or when RouteWatch sees a wall newly across it ahead), the
//                                       minimum-snap reference, progress, the places stalled at
//   MissionRemedies (mission_remedies.h, owned by Mission)
//                                       which remedy when stuck: re-route, escape, back-off, stall zone,
//                                       give-up (its table); a goal proved unreachable ends the mission too
//   SafetyCheck (safety_check.h)        the safety thread's verdict: brake (stale inputs while moving, a
//                                       collision too close, a trajectory running out), hold at the
//                                       measured position (odometry jump), or replan (collision ahead)
//   InputMonitor (input_monitor.h)      freshness of odometry and depth, stamps out of order, time jumps
//                                       (every stored time moves with the step; the FSM replans)
//   ServerLink (server_link.h)          does the trajectory server follow, diverge (no heartbeat, its
//                                       watchdog stops the vehicle) or hold (re-anchor there); timing re-sync
//   commitPlan (plan_commit.h), KnownSpaceCommitment (known_space_commitment.h)
//                                       a plan made into what may be flown: the commanded start velocity,
//                                       cut to a stop before unknown space (FASTER's committed part)
//   manoeuvres.h                        the braking stop, the escape, the back-off (FlownPath), built and
//                                       checked; the FSM decides when
//
// Stale inputs: goals are refused (kInputsStale), nothing is planned, a moving vehicle brakes to a
// hover; the mission resumes when they are fresh again, and the progress clock pauses meanwhile. At
// rest, failed plans are retried every rest_retry_interval_s; moving on a trajectory that stays safe
// for a while, every moving_retry_interval_s. The give-up's reason is in the event (fallback
// "give_up") and in GoalStatus.
//
// Threads: two callers, both may run at the same time: tick() (the planning thread: state machine
// and planning) and checkSafety() (the safety thread: collision check of the executing trajectory and
// the emergency stop). setOdometry()/setGoals() may come from a third. One mutex guards the state;
// tick() releases it while it plans and commits its result only if no other trajectory (a braking
// one) took over in the meantime. The map passed in must not change during the call (the caller
// holds its read lock). The units are plain objects the FSM owns and calls only under its mutex,
// from whichever of the callers holds it; manoeuvres.h, commitPlan and KnownSpaceCommitment are
// functions of their arguments. The replanner and the route searches (Mission::searchRoute) run on
// the planning thread with the mutex released.

#include <cmath>
#include <cstdint>
#include <functional>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <vector>

#include "topo_planner/path_searching/global_router.h"
#include "topo_planner/plan_env/grid_geometry.h"
#include "topo_planner/topo_replan/exec_trajectory.h"
#include "topo_planner/topo_replan/fsm_output.h"
#include "topo_planner/topo_replan/input_monitor.h"
#include "topo_planner/topo_replan/known_space_commitment.h"
#include "topo_planner/topo_replan/manoeuvres.h"
#include "topo_planner/topo_replan/mission.h"
#include "topo_planner/topo_replan/replan_fsm_config.h"
#include "topo_planner/topo_replan/route_watch.h"
#include "topo_planner/topo_replan/safety_check.h"
#include "topo_planner/topo_replan/server_link.h"
#include "topo_planner/topo_replan/topo_replanner.h"

namespace topo_planner {

class ReplanFsm {
 public:
  /// The longest step back of the clock between two calls taken for their order (InputMonitor) [s].
  static constexpr double kMaxClockDisorderS = InputMonitor::kMaxClockDisorderS;

  /// The FSM's settings (replan_fsm_config.h).
  using Config = ReplanFsmConfig;

  static std::unique_ptr<ReplanFsm> create(const Config& config, std::string* error);
  /// A copy of the settings in use.
  Config config() const;
  /// New settings (e.g. flight limits and clearances from dynamic_reconfigure), validated as those
  /// given to create(): refused (false, the reason in *why) when invalid; otherwise applied at the
  /// next tick(), before it plans: the replanner and the route searches are rebuilt with them, the
  /// trajectory in flight is kept (it was checked under the old ones) and the next plan uses the new.
  bool reconfigure(const Config& config, std::string* why);

  /// Latest vehicle state (position and world-frame velocity) stamped t, received at arrival_s (the
  /// caller's clock; NaN: at t). Non-finite values and stamps older than the last accepted one are
  /// refused (false, with the reason in *why) and the last valid odometry is kept.
  bool setOdometry(double t, const Eigen::Vector3d& position, const Eigen::Vector3d& velocity,
                   double arrival_s = NAN, std::string* why = nullptr);
  /// The mapping fused a depth frame (or cloud) stamped stamp_s, at arrival_s (NaN: at stamp_s).
  /// Passing the same stamp again is a no-op (the caller may poll the mapping's last frame); so is a
  /// stamp older than the newest or more than odom_max_age_s ahead of its arrival.
  void setDepthFused(double stamp_s, double arrival_s = NAN);
  /// Freshness of the inputs at clock t.
  InputHealth inputHealth(double t) const;
  /// The trajectory server's latest setpoint (see the class comment). Non-finite values, setpoints
  /// stamped before the last one and setpoints stamped more than server_timeout_s ahead of their
  /// arrival (another time base, or a forged stamp: taken, it would hide every later one as out of
  /// order) are ignored (false).
  bool setServerSetpoint(const ServerSetpoint& setpoint);
  /// A new mission (replaces the current one): the goals are checked against the map and the
  /// reference is built at the next tick(); the status of that check is returned by tick() in
  /// FsmOutput::message and kept in lastGoalStatus(). Immediate refusal for no odometry, bad input
  /// and goals outside the window of the map last ticked on (kGoalOutOfMap): such goals change
  /// nothing, neither the mission flown nor goals given before and not yet taken up by a tick.
  GoalStatus setGoals(const std::vector<Eigen::Vector3d>& goals);
  /// The same, with each goal also checked at once against `map` (the planner node's, under its
  /// read lock): outside it kGoalOutOfMap, closer than goal_clearance_m to an obstacle
  /// kGoalInObstacle. Such goals change nothing either (a flood of goals inside obstacles replaced
  /// valid goals not yet taken up, and the route searched for each cleared the mission's route).
  /// The next tick checks accepted goals again, on the map it plans on.
  GoalStatus setGoals(const std::vector<Eigen::Vector3d>& goals, const EsdfMap& map);

  /// The planning thread: runs the state machine once at time t on the map. `now`, when given,
  /// is the clock: a plan that finishes after its takeover time (t + takeover_delay_s) is
  /// discarded rather than published late.
  FsmOutput tick(double t, const EsdfMap& map, const std::function<double()>& now = {});
  /// Called by tick() after every replanning call, on the planning thread, outside the FSM's lock,
  /// with the map the plan was made on, the request and the result as the FSM judged it (a plan it
  /// refused, for its start velocity or the known-space commitment, is kOptimizationFailed with the
  /// reason): a diagnostics hook (the planner node saves failed problems with it). Set it before
  /// ticking.
  /// The replanner's config the FSM plans with: config.replanner within the route's height band.
  static TopoReplanner::Config replannerConfig(const Config& config);
  /// The speed the plans aim at (see sensing_range_m): the optimiser's max_vel, or less [m/s].
  static double cruiseSpeed(const Config& config);
  using PlanObserver = std::function<void(const EsdfMap&, const ReplanRequest&, const ReplanResult&)>;
  void setPlanObserver(PlanObserver observer) { plan_observer_ = std::move(observer); }
  /// The safety thread: checks the executing trajectory from t; flags a replan when it collides,
  /// and returns a braking trajectory when the collision is too close to wait for one.
  FsmOutput checkSafety(double t, const EsdfMap& map);

  FsmState state() const;
  GoalStatus lastGoalStatus() const;
  std::optional<ExecTrajectory> current() const;
  PolynomialTrajectory reference() const;
  /// The goals of the mission not reached yet (what a rebuilt reference goes through).
  std::vector<Eigen::Vector3d> remainingGoals() const;
  /// The mission's global route (empty when none: no mission, global_route off, or no route found).
  Path route() const;
  int timeJumps() const;  ///< time jumps seen so far
  int serverResyncs() const;  ///< timing re-synchronisations with the trajectory server so far

 private:
  explicit ReplanFsm(const Config& config, std::unique_ptr<TopoReplanner> replanner);

  // All *Locked functions expect mutex_ held.
  void setState(FsmState s, FsmOutput* out, const std::string& why);
  /// The reference's limits, its speed no more than cruiseSpeed().
  ReferenceConfig referenceConfigLocked() const;
  void applyPendingConfigLocked(FsmOutput* out);
  /// Takes up the mission's pending goals: a new reference (GEN_NEW_TRAJ), or false (refused, said why).
  bool startGoalsLocked(double t, const EsdfMap& map, FsmOutput* out);
  /// setGoals() once the goals passed its checks.
  GoalStatus acceptGoalsLocked(const std::vector<Eigen::Vector3d>& goals);
  /// The commanded state at t_takeover: on the current trajectory, or on the one it replaced when
  /// t_takeover comes before the current one's start.
  FlatState takeoverStateLocked(double t_takeover) const;
  void replaceCurrentLocked(const ExecTrajectory& next);
  /// The trajectory flown at t: the current one, or the one it replaced before its start; null if none.
  const ExecTrajectory* flownAtLocked(double t) const;
  double referenceTimeAtLocked(double t) const;
  /// Time to stop from the commanded speed at t at `deceleration`, plus the emergency margin and the
  /// takeover delay: a collision (or the end of a trajectory that ends moving) closer than this
  /// cannot wait for a replan.
  double stopTimeLocked(double t, double deceleration) const;
  /// The stop from the commanded state at t (manoeuvres.h brakingTrajectory): along the trajectory
  /// flown then, or along the velocity with none; with `from`, from that state along its velocity
  /// (odometry jump), at brake_acc_mps2 only.
  ExecTrajectory brakingTrajectoryLocked(double t, const EsdfMap& map, std::string* report,
                                         const FlatState* from = nullptr) const;
  /// Clock bookkeeping of every entry point: detects a time jump and shifts the stored times.
  void observeClockLocked(double now, FsmOutput* out);
  /// The trajectory server does not follow this FSM's trajectory (see the class comment): true when
  /// the caller must not publish or check; at the server's hold, takes it as the commanded state.
  bool followServerLocked(double t, const EsdfMap& map, FsmOutput* out);
  /// Brakes now for `reason` (stale input, odometry jump): publishes the stop, EMERGENCY_STOP.
  void emergencyStopLocked(double t, const EsdfMap& map, const std::string& reason, FsmOutput* out,
                           const FlatState* from, ReplanStatus status);
  /// The global route for the goals the next reference will go through, when it is stale (mutex
  /// released during the search); gives the mission up when the route proves a goal unreachable.
  /// *searched_until: the clock (now(), or t) when a search ended; untouched when none ran.
  void routeLocked(double t, const EsdfMap& map, std::unique_lock<std::mutex>* lock, FsmOutput* out,
                   const std::function<double()>& now, double* searched_until);
  /// The route check (Config::route_check_length_m) of a moving vehicle: true when the map shows a
  /// part of the route ahead newly blocked; the re-route is then pending (searched at the next tick).
  bool routeBlockedLocked(double t, const EsdfMap& map, FsmOutput* out);
  /// The stall rule (Config::progress_timeout_s), once per tick before the state machine: true when
  /// it acted (re-route, stop, back-off or give-up) and the tick ends there.
  bool handleStallLocked(double t, const EsdfMap& map, FsmOutput* out);
  /// The back-off from the commanded state at t (manoeuvres.h backoffTrajectory), if one is possible.
  std::optional<ExecTrajectory> backoffLocked(double t, const EsdfMap& map, std::string* report,
                                              bool* to_anchor = nullptr) const;
  /// No trajectory runs at t (none, or it has ended) and the vehicle is measured at rest.
  bool atRestLocked(double t) const;
  /// The mission's reference could not be rebuilt (startGoalsLocked refused its remaining goals):
  /// goals now invalid end the mission (give_up, saying why); a reference that failed its limits is
  /// rebuilt from rest (a moving vehicle stops first) instead of dropping the mission.
  void referenceNotRebuiltLocked(double t, const EsdfMap& map, FsmOutput* out);
  /// Publishes a back-off (or escape) manoeuvre: the way back is used up, the route is searched
  /// again from where it ends, EMERGENCY_STOP until it has been flown.
  void startManoeuvreLocked(ExecTrajectory manoeuvre, bool backoff, FsmEvent* event, FsmOutput* out,
                            const std::string& why);
  /// Ends the mission for `why` (braking first when moving), with a give_up event.
  void giveUpLocked(double t, const EsdfMap& map, GoalStatus status, ReplanStatus replan_status, const std::string& why,
                    FsmOutput* out);
  /// What one tick() works with: its time and map, the lock it holds, its output, the clock.
  struct Tick {
    double t;
    const EsdfMap& map;
    std::unique_lock<std::mutex>* lock;
    FsmOutput* out;
    const std::function<double()>& now;
  };
  /// EXEC_TRAJ / REPLAN_TRAJ at a tick: new goals, the goal reached, or a replan when the trajectory
  /// collides ahead, runs out, or is due (replan_interval_s); `jumped`: after a time jump.
  void execTrajLocked(const Tick& tick, bool jumped);
  /// EMERGENCY_STOP at a tick: once at rest, a new reference from there through the goals left.
  void stoppedLocked(const Tick& tick);
  /// One planning call (mutex released while the replanner runs): the plan is committed
  /// (plan_commit.h) and published, or what a failure calls for is done.
  void plan(const Tick& tick, FsmEvent::Trigger trigger);
  /// A committed plan on time: published, unless the holds at the edge of the known space call for
  /// a back-off or the give-up.
  void planSucceededLocked(double t, const EsdfMap& map, const ReplanRequest& request, ExecTrajectory traj,
                           FsmEvent* event, FsmOutput* out);
  /// A failed (or late, or superseded) plan with `status`, finished at `finished`: keep the current
  /// trajectory, retry, escape, back off, re-route or give up (MissionRemedies).
  void planFailedLocked(double t, const EsdfMap& map, ReplanStatus status, FsmEvent::Trigger trigger, bool superseded,
                        double finished, FsmEvent* event, FsmOutput* out);

  Config config_;
  std::optional<Config> pending_config_;  // reconfigure(): applied at the next tick
  std::unique_ptr<TopoReplanner> replanner_;  // used by tick() only, outside the lock
  PlanObserver plan_observer_;                // tick() only, outside the lock

  mutable std::mutex mutex_;
  FsmState state_ = FsmState::kInit;
  InputMonitor inputs_;           // odometry and depth liveness, the clock and its jumps
  std::optional<GridGeometry> map_geometry_;  // the window of the map last ticked on (setGoals)
  bool time_jumped_ = false;      // set by observeClockLocked, consumed by tick (replan)
  double time_jump_clock_s_ = 0.0;  // the clock when the last jump was seen
  bool inputs_reported_ = false;  // the stale-input message was given (once per episode)
  Eigen::Vector3d odom_position_ = Eigen::Vector3d::Zero();
  Eigen::Vector3d odom_velocity_ = Eigen::Vector3d::Zero();
  std::optional<ExecTrajectory> current_;
  std::optional<ExecTrajectory> previous_;  // the one current_ replaced: flown until current_ starts
  int64_t next_id_ = 0;
  ServerLink server_;  // the trajectory server's latest setpoint: does it follow?
  SafetyCheck safety_;  // the safety thread's rules
  bool collision_ahead_ = false;  // set by checkSafety, consumed by tick
  Mission mission_;  // goals, route, reference, progress, stall zones and remedies
  FlownPath flown_;                       // what the back-offs walk back along
  // Where the vehicle hovers without having been flown there by a committed trajectory (a mission's
  // start, a re-anchoring): the known-space commitment counts known_start_radius_m around it as known.
  std::optional<Eigen::Vector3d> known_anchor_;
  // Set by an odometry jump: the stop from the measured position runs on into a map in the new frame
  // (forgotten, or wrong by the jump), so the hover where it ends was not flown to through known
  // space either; the anchor moves there once the vehicle is at rest.
  bool anchor_at_rest_ = false;
  double rest_retry_after_s_ = -INFINITY; // a failed plan at rest is tried again from then
  double moving_retry_after_s_ = -INFINITY;  // a failed periodic replan of a safe trajectory: from then
  double takeover_delay_s_;       // the adaptive takeover delay (tick() only writes it, under the mutex)
};

}  // namespace topo_planner
