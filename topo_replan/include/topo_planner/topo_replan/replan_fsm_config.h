#pragma once
// The replanning FSM's settings (ReplanFsm::Config) and their validation: every field with its
// default, unit and why. The FSM hands each of its units the part it needs (the functions at the
// end, defined in replan_fsm_config.cpp with the validation).

#include <string>

#include "topo_planner/path_searching/global_router.h"
#include "topo_planner/topo_replan/input_monitor.h"
#include "topo_planner/topo_replan/known_space_commitment.h"
#include "topo_planner/topo_replan/manoeuvres.h"
#include "topo_planner/topo_replan/mission_remedies.h"
#include "topo_planner/topo_replan/plan_commit.h"
#include "topo_planner/topo_replan/polynomial_trajectory.h"
#include "topo_planner/topo_replan/route_watch.h"
#include "topo_planner/topo_replan/safety_check.h"
#include "topo_planner/topo_replan/server_link.h"
#include "topo_planner/topo_replan/topo_replanner.h"

namespace topo_planner {

struct ReplanFsmConfig {
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

  // The settings of each unit.
  KnownSpaceCommitment::Config commitment() const;  ///< its clearance, margin, back-up deceleration, band
  MissionRemedies::Config remedies() const;
  RouteWatch::Config routeWatch() const;
  ServerLink::Config serverLink() const;
  InputMonitor::Config inputMonitor() const;
  ManoeuvreConfig manoeuvres() const;  ///< braking, escape, back-off
  SafetyCheck::Config safetyCheck() const;
  PlanCommitConfig planCommit() const;
};

}  // namespace topo_planner
