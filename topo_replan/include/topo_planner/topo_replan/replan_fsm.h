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
// reported, since braking is the last safe action left).
//
// Global guidance (global_route). Every reference (a new mission, a rebuild after a stop, a retry)
// goes through the mission's global route (path_searching GlobalRouter: A* over the whole map
// window at the guide search's clearance, unknown space free, shortened), so the local search,
// which samples around the reference segment, looks along it. The route is recomputed when the
// goals change, after a stop, and when plans keep failing: at once on kNoPath or kGoalInCollision
// (the map shows the way blocked), and every reroute_after_failures failed plans; on a moving
// vehicle the rebuilt reference starts from the state the next trajectory takes over at. Moving, the
// route ahead is checked against the map (route_check_length_m): a wall newly seen across it, with
// no way past on its face within the local search's reach, re-routes before the local plans fail. The
// search runs in tick() with the mutex released (it may take tens of milliseconds).
//
// No silent give-up (with global_route). A mission is given up only when the route search proves
// a goal unreachable (no route through known and unknown space in its height band at its
// clearance, not even with the region within max_backoff_length_m + 1 m of the vehicle passable
// at the route's end clearance, e.g. out of a narrow slot it braked in; with unknown space free to
// the route; the FSM brakes if moving) or when the mission has had no successful plan for its
// time limit; the
// reason is in the event (fallback "give_up") and in GoalStatus. Before that, at rest, it changes
// strategy: re-route (above), and after max_plan_failures failed plans, or when it cannot start
// and no escape up the distance field exists, or when its plans have been cut to a hold at the same
// place max_look_holds times (the way on lies in unknown space the camera does not see by turning),
// back off along the flown path (at most max_backoffs times per mission) and re-route from there;
// with no back-off left, max_plan_failures failures at rest call the stall remedy below at once.
// At rest, failed plans are retried every rest_retry_interval_s, not at every tick; moving on a
// trajectory that stays safe for a while, every moving_retry_interval_s.
// Stalls with every plan succeeding (hovering at the edge of the known space, creeping, shuttling)
// are caught by progress, not by failures: the distance left along the mission's way
// (MissionProgress) must shrink by progress_min_gain_m within progress_timeout_s; each time it does
// not, the FSM marks the place (a zone the route searches avoid, GlobalRouter::setAvoided) and
// re-routes from where the vehicle is, or, every second time while back-offs are left, stops and
// backs off; the mission is given up when it has made no progress for its time limit (event
// fallback "reroute" / "back_off" / "give_up", the distance left in the message). The clock pauses
// while the inputs are stale. Without global_route, the mission is given up after
// max_plan_failures failed first plans.
//
// Known-space commitment (commit_to_known_space, FASTER's safe/committed split done along the
// path). The replanner plans optimistically: unknown space counts as free, so it explores. What the
// FSM publishes is cut to what is known: the plan is flown as planned while, at every instant, a
// stop along its path at brake_acc_mps2 would end before the first point of the path that is not
// observed free with all the voxels within safety_clearance_m of it observed (the ESDF counts only
// observed obstacles: a point in seen air beside a face the camera never saw, below or beside its
// view, would pass on distance alone), or comes within safety_clearance_m of an obstacle; from the last such instant
// (brake_start_s) the published trajectory brakes along the same path to rest. So at every instant
// of every published trajectory the vehicle can stop, at the planning deceleration, in space the
// map has observed free; if no later plan comes, it does stop there. The height band of the route
// (route.min_z_m, max_z_m) is a geofence for the committed part too: no farther out of it than the
// plan's start (a take-off from below climbs in; a plan from inside stays inside). A new plan takes over before
// the braking starts while the map keeps growing ahead (the FSM replans early enough), so normal
// flight does not slow down; it slows where the camera has not seen far enough.
//
// Input liveness. Odometry is fresh when it arrived within odom_timeout_s and its stamp is within
// odom_max_age_s of the clock; depth when the last fused frame's stamp is within depth_timeout_s.
// Stale inputs: goals are refused (kInputsStale), nothing is planned, and a moving vehicle brakes to
// a hover; the mission resumes when they are fresh again. Odometry stamped before the last one is
// refused. Odometry farther than max_tracking_error_m from the commanded position at its stamp (a
// VIO jump or relocalisation) makes the FSM hold at the measured position and replan from there.
//
// The trajectory server. The commanded state is the FSM's trajectory as long as the trajectory server
// follows it. When the server's published setpoint (setServerSetpoint, fresh within
// server_timeout_s) shows that it does not (it stopped on its own: watchdog, a trajectory that ended
// moving; it refused a trajectory that was not continuous; it holds while the FSM's trajectory
// moves or away from the commanded position; or a restarted planner finds it on another session's
// trajectory), the FSM publishes nothing, skips its own checks and asks the caller to send no
// heartbeat (FsmOutput::server_diverged: the server's watchdog then stops the vehicle along its
// path) until the server holds, then takes the hold as its commanded state (a trajectory at rest
// there) and replans from it. Before its first trajectory the FSM starts from the server's hold
// rather than from odometry. While the server follows the FSM's trajectory, the FSM keeps its
// timing in step with the server's setpoint (after a clock step each side saw at another moment).
// Without server setpoints, the FSM's trajectory is the commanded state.
//
// Time. A clock that steps forwards by more than time_jump_threshold_s, or backwards by more than
// kMaxClockDisorderS (or the threshold if smaller), between two calls (setOdometry's arrival
// time, tick, checkSafety) is a time jump: every stored time (the
// trajectory's start, the inputs' stamps) is shifted by the step so the commanded motion goes on
// without a jump, and the FSM replans from the current state.
//
// Threads: two callers, both may run at the same time: tick() (the planning thread: state machine
// and planning) and checkSafety() (the safety thread: collision check of the executing trajectory and
// the emergency stop). setOdometry()/setGoals() may come from a third. One mutex guards the state;
// tick() releases it while it plans and commits its result only if no other trajectory (a braking
// one) took over in the meantime. The map passed in must not change during the call (the caller
// holds its read lock).

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
#include "topo_planner/topo_replan/known_space_commitment.h"
#include "topo_planner/topo_replan/mission_progress.h"
#include "topo_planner/topo_replan/topo_replanner.h"

namespace topo_planner {

enum class FsmState { kInit, kWaitTarget, kGenNewTraj, kExecTraj, kReplanTraj, kEmergencyStop };
const char* toString(FsmState state);

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

/// A trajectory the vehicle executes: a B-spline from start_time_s.
struct ExecTrajectory {
  int64_t id = -1;
  double start_time_s = 0.0;   ///< when it takes over [s, caller's clock]
  UniformBspline spline;
  double reference_start_s = 0.0;  ///< reference time at its start ...
  double reference_end_s = 0.0;    ///< ... and where it rejoins the reference
  bool ends_at_goal = false;       ///< rejoins the reference at its end (the last goal, at rest)
  bool braking = false;            ///< an emergency braking trajectory
  bool escape = false;             ///< a slow manoeuvre out of an obstacle's clearance, from rest to rest
  /// Known-space commitment: the planned (optimistic) trajectory is flown until this time, then the
  /// vehicle stops along its path within the space the map has observed free. Equal to endTime()
  /// when the whole plan lies in known-free space [s, caller's clock].
  double brake_start_s = 0.0;
  bool stops_before_unknown = false;  ///< the plan was cut: it ends at rest before unknown space
  /// Where the camera should look when the trajectory's own displacement gives no heading (a stop
  /// at the edge of the known space): a point ahead on the planned (optimistic) path.
  bool has_heading_target = false;
  Eigen::Vector3d heading_target = Eigen::Vector3d::Zero();
  /// Deliberately starts away from the commanded state (the hold at the measured position after an
  /// odometry jump): the trajectory server accepts the step.
  bool reanchor = false;
  double endTime() const { return start_time_s + spline.duration(); }
  /// Braking or escape: checked when made, ends at rest, not on the reference, not replanned.
  bool manoeuvre() const { return braking || escape; }
};

/// What one call did, for logging and the ReplanEvent message.
struct FsmEvent {
  enum class Trigger { kNewGoal, kCollisionAhead, kPeriodic, kRetry, kEmergency, kTimeJump, kReroute };
  Trigger trigger = Trigger::kNewGoal;
  FsmState state = FsmState::kInit;     ///< state when it started
  bool published = false;               ///< a new trajectory was returned
  ReplanStatus status = ReplanStatus::kSuccess;
  /// none | keep_current | hover_retry | stop | escape | back_off | reroute | give_up | discarded_late |
  /// discarded_superseded
  std::string fallback = "none";
  std::string message;
  Eigen::Vector3d position = Eigen::Vector3d::Zero();  ///< start of the planned trajectory
  ReplanStats stats;
};
const char* toString(FsmEvent::Trigger trigger);

/// The setpoint the trajectory server commands (its published position command).
struct ServerSetpoint {
  enum class Mode { kBeforeFirst, kTrajectory, kStopping, kHold };
  double stamp_s = 0.0;  ///< [s, caller's clock]
  double arrival_s = NAN;  ///< when it arrived [s, caller's clock]; NaN: at stamp_s
  Eigen::Vector3d position = Eigen::Vector3d::Zero();
  Eigen::Vector3d velocity = Eigen::Vector3d::Zero();
  Mode mode = Mode::kTrajectory;  ///< kStopping: a stop of its own (watchdog, or a trajectory that ended moving)
  bool own_session = false;       ///< the trajectory it follows (or followed) is of this planner session
  int64_t trajectory_id = -1;     ///< ... and has this id
};

/// Freshness of the inputs at a time, for the heartbeat, the diagnostics and the log.
struct InputHealth {
  bool ok = false;            ///< every input is fresh
  std::string why;            ///< what is stale, when not ok
  double depth_age_s = -1.0;  ///< clock - stamp of the last fused depth frame [s]; -1 = never
  double odom_age_s = -1.0;   ///< clock - stamp of the last odometry [s]; -1 = never
};

struct FsmOutput {
  std::optional<ExecTrajectory> trajectory;       ///< publish this (already checked)
  std::optional<FsmEvent> event;                  ///< a planning call happened
  std::optional<ReplanResult> plan;               ///< its full result (candidates etc., for rviz)
  bool new_reference = false;                     ///< reference() changed
  bool new_route = false;                         ///< route() changed
  bool goal_reached = false;                      ///< the last goal of the mission was reached
  /// Odometry jumped away from the commanded state (a VIO relocalisation): the map built in the old
  /// frame no longer lines up with the new one; the caller may forget it.
  bool odometry_jumped = false;
  /// The trajectory server does not follow the commanded trajectory: the caller sends no heartbeat
  /// (the server's watchdog then stops the vehicle) until the FSM has re-anchored on its hold.
  bool server_diverged = false;
  std::string message;                            ///< a notable transition, for the log
};

class ReplanFsm {
 public:
  /// The longest step back of the clock between two calls taken for their order (the callers read
  /// the clock before they take the lock), not for a time jump [s].
  static constexpr double kMaxClockDisorderS = 0.15;

  struct Config {
    TopoReplanner::Config replanner;  ///< search, optimiser and horizon (horizon_m)
    ReferenceConfig reference;        ///< limits of the global reference (keep <= the optimiser's)
    double takeover_delay_s = 0.1;    ///< a new trajectory takes over this long after planning starts [s]
    /// The delay adapts to the planning time (1.5 x the last one, when longer), up to this [s].
    double max_takeover_delay_s = 0.5;
    double replan_interval_s = 1.0;   ///< replan after executing the current one this long [s]
    double safety_clearance_m = 0.2;  ///< the executing trajectory collides below this ESDF distance [m]
    double safety_sample_s = 0.02;    ///< time step of the safety check [s]
    double brake_acc_mps2 = 2.5;      ///< deceleration of the braking trajectory [m/s^2]
    /// When braking at brake_acc_mps2 would come within the safety clearance (an obstacle seen late),
    /// the braking trajectory decelerates harder, in steps of 1.25x up to this: the vehicle's limit,
    /// not the planner's (the simulated controller's 0.7 rad tilt allows 8 m/s^2) [m/s^2].
    double max_brake_acc_mps2 = 5.0;
    double emergency_margin_s = 0.3;  ///< stop when the collision is closer than the braking time plus this [s]
    double goal_clearance_m = 0.3;    ///< goals closer to a known obstacle are refused [m]
    double goal_tolerance_m = 0.3;    ///< the mission ends when the trajectory has ended and the vehicle is this close [m]
    double stopped_speed_mps = 0.2;   ///< below this the vehicle counts as stopped after braking [m/s]
    /// Consecutive failed plans in GEN_NEW_TRAJ: without global_route the mission is then given up;
    /// with it, at rest, the FSM changes strategy (a back-off while back-offs are left, else the stall
    /// remedy at once: a zone ahead and a re-route), every this many failures.
    int max_plan_failures = 30;
    /// At rest, a failed plan is tried again this long after it ended (each try draws another
    /// roadmap; the map and the start do not change faster) rather than at every tick; 0: every
    /// tick [s].
    double rest_retry_interval_s = 0.0;
    /// Moving on a trajectory that stays safe (no collision ahead, its end or its brake point not
    /// near), a failed periodic replan is tried again this long after it ended rather than at every
    /// tick (the trajectory flown is fine; each try costs a planning call); with a collision ahead
    /// or the trajectory running out, at every tick. 0: every tick [s].
    double moving_retry_interval_s = 0.0;
    /// A vehicle at rest that the replanner refuses as kStartInCollision first moves up the distance
    /// field (plan_env ascendDistance) until it is this far from obstacles (interpolated ESDF) [m].
    double escape_clearance_m = 0.45;
    /// A walk that stops short of escape_clearance_m (a ridge between obstacles) is flown when it
    /// ends at least this far from obstacles (above the replanner's start clearances) [m].
    double escape_min_clearance_m = 0.35;
    double escape_speed_mps = 0.5;    ///< peak speed of the escape [m/s]
    double max_escape_length_m = 1.0; ///< no escape when the way out is longer than this [m]; 0: never

    // Known-space commitment (see the class comment).
    bool commit_to_known_space = true;  ///< false: publish plans through unknown space as planned (optimistic)
    /// Path points this close to where a mission started from a hover (or the vehicle was re-anchored)
    /// count as known, with their clearance balls: the vehicle is there, though the camera cannot see
    /// its own position nor beside it. Not around every plan's start: plans would creep into
    /// unobserved space by this much each [m].
    double known_start_radius_m = 0.3;
    /// The committed stop ends this far before unknown space [m]. At least a voxel more than 0.1 m:
    /// the interpolated ESDF reads an obstacle up to half a voxel's diagonal closer than its voxel, so
    /// one seen just past the edge of the known space came within the safety clearance of a stop
    /// that ended 0.1 m before it (a collision ahead, and an emergency stop, at every such tree).
    double commit_margin_m = 0.2;
    /// The deceleration of the committed stop (the back-up every published plan keeps): how late a
    /// plan may start stopping before unknown space. Up to max_brake_acc_mps2, the vehicle's limit;
    /// it is flown only when no new plan takes over in time [m/s^2].
    double commit_brake_acc_mps2 = 2.5;
    /// How far ahead the map learns the space from the camera (the mapping's max_ray_length_m): the
    /// reference and the local plans aim at no more than the speed from which the vehicle can stop,
    /// at commit_brake_acc_mps2, within that depth after its reaction (cruiseSpeed()). Planned
    /// faster, every plan is cut before unknown space and the turns it must make at that speed
    /// stretch it whole: at max_vel 7 the vehicle flew slower than at 5. 0: max_vel [m].
    double sensing_range_m = 0.0;

    // Input liveness (see the class comment).
    double depth_timeout_s = 0.5;       ///< depth older than this is stale; 0: depth is not required [s]
    double odom_timeout_s = 0.25;       ///< odometry that has not arrived for this long is stale [s]
    double odom_max_age_s = 0.5;        ///< odometry stamped longer ago than this is stale [s]
    double max_tracking_error_m = 0.6;  ///< odometry this far from the commanded position: hold and replan [m]
    double time_jump_threshold_s = 1.0; ///< a clock step forwards larger than this between calls is a time jump [s]
    /// An intermediate goal counts as reached (and is left out of rebuilt references) once the vehicle
    /// came this close to it [m].
    double waypoint_reached_radius_m = 1.0;

    // Global guidance and strategies (see the class comment).
    bool global_route = true;           ///< false: straight references through the goals, old give-up rule
    GlobalRouter::Config route;         ///< the route search (its clearance: keep the guide search's)
    int reroute_after_failures = 3;     ///< re-route every this many consecutive failed plans
    /// Moving, the route ahead is checked against the map every route_check_interval_s, up to this
    /// far along it from the vehicle: a part of it that was clear when it was searched and now lies
    /// within safety_clearance_m of a known obstacle, with no point at the route's clearance on the
    /// obstacle's face within 3 m of it (a wall seen across the route; a tree, a pillar or a window
    /// close by is the local planner's), re-routes at once, while the vehicle can still turn to a
    /// known opening or to the wall's unseen part, rather than when the local plans fail at the
    /// wall. 0: off [m].
    double route_check_length_m = 12.0;
    double route_check_interval_s = 0.5;  ///< [s]
    double backoff_length_m = 1.5;      ///< a back-off flies at least this far back along the flown path [m] ...
    double max_backoff_length_m = 3.0;  ///< ... and on until escape_clearance_m from obstacles, up to this [m]
    double backoff_speed_mps = 1.0;     ///< peak speed of a back-off (the flown path is known free) [m/s]
    int max_backoffs = 3;               ///< back-offs per mission
    /// Plans cut to a hold at the same place (unknown space right ahead that turning to look does not
    /// reveal) this many times in a row: back off along the flown path, where the camera sees more.
    int max_look_holds = 5;
    /// ... and held there for at least this long: time for the camera to turn round (pi at the
    /// trajectory server's yaw rate) and see where the plan goes [s].
    double look_hold_min_s = 2.5;
    /// A mission with no successful plan for this long (since it started or since its last one) is
    /// given up [s]; 0: 60 s or 4 times the duration of its first reference, whichever is longer.
    double mission_timeout_s = 0.0;
    /// Progress (MissionProgress): the distance left along the mission's way must shrink by
    /// progress_min_gain_m within progress_timeout_s, whether plans succeed or not. Each time it does
    /// not (a stall: hovering at the edge of the known space, creeping, shuttling), the FSM changes
    /// strategy: first a re-route from where the vehicle is, then a back-off along the flown path
    /// (stopping first when moving), alternating while back-offs are left; the mission is given up
    /// when it has made no progress for its time limit. 0: off [s].
    double progress_timeout_s = 10.0;
    double progress_min_gain_m = 0.5;  ///< [m]
    /// Each stall adds a zone of this radius around where the vehicle was to the mission's route
    /// searches (GlobalRouter::setAvoided): the re-route prefers another way [m].
    double stall_zone_radius_m = 1.5;
    /// A plan whose start velocity differs from the commanded one by more than this (the replanner
    /// could not restore it after time reallocation) is not published: setpoints never step [m/s].
    double max_start_velocity_step_mps = 0.1;
    /// The trajectory server's setpoint counts while this fresh (its stamp vs the clock) [s].
    double server_timeout_s = 0.25;
    /// The server is on a trajectory of this planner's that has started this long (message latency) [s].
    double server_grace_s = 0.15;
    /// A server hold farther than this from the commanded position is not the commanded hold [m].
    double server_position_tolerance_m = 0.1;

    bool validate(std::string* why) const;
  };

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
  /// The known-space commitment's settings of a config (its clearance, margin, back-up deceleration, band).
  static KnownSpaceCommitment::Config commitmentConfig(const Config& config);
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
  bool startGoalsLocked(double t, const EsdfMap& map, FsmOutput* out);
  /// Goals against the map: kAccepted, or kGoalOutOfMap / kGoalInObstacle with why (goal index).
  GoalStatus checkGoalsLocked(const std::vector<Eigen::Vector3d>& goals, const EsdfMap& map, std::string* why) const;
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
  /// First time >= t at which the trajectory comes closer than safety_clearance_m; -1 if none.
  double firstCollisionTime(const ExecTrajectory& traj, double t, const EsdfMap& map) const;
  /// Stops from the state at t: along the current trajectory's path (checked space) when there is one,
  /// else along the velocity; at brake_acc_mps2, harder when that comes within the safety clearance.
  /// With `from`, the stop starts from that state instead, along its velocity (odometry jump).
  ExecTrajectory brakingTrajectory(double t, const EsdfMap& map, std::string* report,
                                   const FlatState* from = nullptr) const;
  /// The known-space commitment of a plan starting at t0 (KnownSpaceCommitment): fills traj->spline,
  /// brake_start_s, stops_before_unknown and the heading target; false (with why) when the cut
  /// trajectory cannot be built or fails its check.
  bool commitToKnownSpace(const UniformBspline& plan, double t0, const EsdfMap& map, ExecTrajectory* traj,
                          std::string* why) const;
  /// Clock bookkeeping of every entry point: detects a time jump and shifts the stored times.
  void observeClockLocked(double now, FsmOutput* out);
  bool inputsFreshLocked(double now, std::string* why) const;
  /// The trajectory server does not follow this FSM's trajectory (see the class comment): true when
  /// the caller must not publish or check; at the server's hold, takes it as the commanded state.
  bool followServerLocked(double t, const EsdfMap& map, FsmOutput* out);
  /// Brakes now for `reason` (stale input, odometry jump): publishes the stop, EMERGENCY_STOP.
  void emergencyStopLocked(double t, const EsdfMap& map, const std::string& reason, FsmOutput* out,
                           const FlatState* from, ReplanStatus status);
  std::vector<Eigen::Vector3d> remainingGoalsLocked() const;
  /// From the commanded position at rest, up the distance field to escape_clearance_m, checked to
  /// never come closer to an obstacle than it starts (or than the safety clearance); nullopt with
  /// the reason in `report` when there is no such way.
  std::optional<ExecTrajectory> escapeTrajectoryLocked(double t, const EsdfMap& map, std::string* report) const;
  /// From the commanded position at rest, back along the flown path (see Config), or with none, back
  /// to the known anchor when within its zone (*to_anchor true); nullopt with the reason when there
  /// is neither or the fitted manoeuvre fails its check.
  std::optional<ExecTrajectory> backoffTrajectoryLocked(double t, const EsdfMap& map, std::string* report,
                                                        bool* to_anchor = nullptr) const;
  /// A slow rest-to-rest manoeuvre along `walk` (from the commanded position p0, d0 from obstacles),
  /// peaking at speed_mps, checked like an escape; nullopt with the reason when the check fails.
  std::optional<ExecTrajectory> restToRestLocked(const std::vector<Eigen::Vector3d>& walk, double t, const EsdfMap& map,
                                                 double d0, double speed_mps, const char* what, std::string* report) const;
  /// The global route for the goals the next reference will go through, when it is stale (mutex
  /// released during the search); gives the mission up when the route proves a goal unreachable.
  /// *searched_until: the clock (now(), or t) when a search ended; untouched when none ran.
  void routeLocked(double t, const EsdfMap& map, std::unique_lock<std::mutex>* lock, FsmOutput* out,
                   const std::function<double()>& now, double* searched_until);
  /// The route check (Config::route_check_length_m) of a moving vehicle: true when the map shows a
  /// part of the route ahead newly blocked; the re-route is then pending (searched at the next tick).
  bool routeBlockedLocked(double t, const EsdfMap& map, FsmOutput* out);
  /// Samples the new route_ and marks those already blocked on the map it was searched on.
  void markRouteLocked(const EsdfMap& map);
  /// The stall rule (Config::progress_timeout_s), once per tick before the state machine: true when
  /// it acted (re-route, stop, back-off or give-up) and the tick ends there.
  bool handleStallLocked(double t, const EsdfMap& map, FsmOutput* out);
  /// A place stalled at, for every later route search (the oldest dropped beyond kMaxStallZones).
  void addStallZoneLocked(const GlobalRouter::Zone& zone);
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
  void plan(double t, const EsdfMap& map, FsmEvent::Trigger trigger, std::unique_lock<std::mutex>* lock,
            FsmOutput* out, const std::function<double()>& now);

  Config config_;
  std::optional<Config> pending_config_;  // reconfigure(): applied at the next tick
  std::unique_ptr<TopoReplanner> replanner_;  // used by tick() only, outside the lock
  PlanObserver plan_observer_;                // tick() only, outside the lock

  mutable std::mutex mutex_;
  FsmState state_ = FsmState::kInit;
  bool have_odom_ = false;
  double odom_time_s_ = 0.0;
  double odom_arrival_s_ = 0.0;
  bool have_raw_depth_ = false;   // the last stamp passed to setDepthFused, as passed
  double raw_depth_stamp_s_ = 0.0;
  bool have_depth_ = false;
  double depth_stamp_s_ = 0.0;
  double depth_arrival_s_ = 0.0;
  bool have_clock_ = false;
  double last_clock_s_ = 0.0;
  std::optional<GridGeometry> map_geometry_;  // the window of the map last ticked on (setGoals)
  double typical_step_s_ = 0.0;  // running mean of the clock's steps between calls [s]
  int time_jumps_ = 0;
  bool time_jumped_ = false;      // set by observeClockLocked, consumed by tick (replan)
  double time_jump_clock_s_ = 0.0;  // the clock when the last jump was seen
  bool inputs_reported_ = false;  // the stale-input message was given (once per episode)
  size_t next_goal_ = 0;          // goals_[next_goal_..] are not reached yet
  Eigen::Vector3d odom_position_ = Eigen::Vector3d::Zero();
  Eigen::Vector3d odom_velocity_ = Eigen::Vector3d::Zero();
  std::vector<Eigen::Vector3d> pending_goals_;  // set by setGoals, consumed by tick
  bool goals_pending_ = false;
  std::vector<Eigen::Vector3d> goals_;          // the current mission
  GoalStatus last_goal_status_ = GoalStatus::kAccepted;
  PolynomialTrajectory reference_;
  std::optional<ExecTrajectory> current_;
  std::optional<ExecTrajectory> previous_;  // the one current_ replaced: flown until current_ starts
  int64_t next_id_ = 0;
  std::optional<ServerSetpoint> server_;  // the trajectory server's latest setpoint
  bool server_reported_ = false;          // the divergence message was given (once per episode)
  double server_anchor_s_ = -1e300;       // the last re-anchoring on the server's hold [s]
  int server_resyncs_ = 0;
  bool collision_ahead_ = false;  // set by checkSafety, consumed by tick
  int consecutive_failures_ = 0;
  // Global guidance and strategies.
  std::unique_ptr<GlobalRouter> router_;  // used by tick() only, outside the lock
  std::unique_ptr<GlobalRouter> start_router_;  // ... relaxed farther from the start: the proof of unreachability
  Path route_;                            // through route_goals_; empty: straight references
  std::vector<Eigen::Vector3d> route_goals_;
  // The route sampled along its length (route check): the samples, whether each was already within
  // the safety clearance of a known obstacle when the route was searched (never a reason to re-route),
  // and the sample the vehicle was last found nearest to (the check looks on from there).
  std::vector<Eigen::Vector3d> route_samples_;
  std::vector<uint8_t> route_sample_blocked_;
  size_t route_sample_at_ = 0;
  double route_checked_s_ = -INFINITY;
  std::string reroute_reason_;            // why the pending re-route: said in its planning call's event
  bool route_stale_ = true;
  bool rerouting_ = false;                // the pending goals are a re-route of the mission
  bool rerouted_since_success_ = false;   // an immediate re-route was done since the last published plan
  int failures_at_reroute_ = 0;
  std::vector<Eigen::Vector3d> flown_;    // commanded positions 0.25 m apart, newest last (back-offs)
  int backoffs_ = 0;                      // in this mission
  int look_holds_ = 0;                    // plans cut to a hold at look_hold_position_ in a row
  // Where the vehicle hovers without having been flown there by a committed trajectory (a mission's
  // start, a re-anchoring): the known-space commitment counts known_start_radius_m around it as known.
  std::optional<Eigen::Vector3d> known_anchor_;
  // Set by an odometry jump: the stop from the measured position runs on into a map in the new frame
  // (forgotten, or wrong by the jump), so the hover where it ends was not flown to through known
  // space either; the anchor moves there once the vehicle is at rest.
  bool anchor_at_rest_ = false;
  Eigen::Vector3d look_hold_position_ = Eigen::Vector3d::Zero();
  double look_hold_since_s_ = 0.0;        // the first hold at look_hold_position_ [s]
  bool new_mission_ = false;              // set by setGoals: the next started reference begins a mission
  double last_progress_s_ = 0.0;          // the mission's start or its last successful plan (not a hold) [s]
  uint64_t route_epoch_ = 0;              // bumped by setGoals, stops and odometry jumps: a route searched before is stale
  double mission_limit_s_ = INFINITY;
  MissionProgress progress_;              // the distance left along the mission's way
  int stalls_ = 0;                        // stall remedies since the last gain of progress
  bool force_stall_ = false;              // failures at rest asked for the stall remedy now
  int failures_at_stall_ = 0;             // consecutive_failures_ when the failures last forced it
  double rest_retry_after_s_ = -INFINITY; // a failed plan at rest is tried again from then
  double moving_retry_after_s_ = -INFINITY;  // a failed periodic replan of a safe trajectory: from then
  double stall_gain_s_ = 0.0;             // progress_.lastGain() when stalls_ was last reset
  bool backoff_when_stopped_ = false;     // a stall remedy: back off once the stop it began has ended
  double progress_tick_s_ = NAN;          // the last tick that measured progress (or paused it) [s]
  std::vector<GlobalRouter::Zone> stall_zones_;  // where missions stalled: later route searches avoid them
  static constexpr size_t kMaxStallZones = 32;
  double takeover_delay_s_;       // the adaptive takeover delay (tick() only writes it, under the mutex)
};

}  // namespace topo_planner
