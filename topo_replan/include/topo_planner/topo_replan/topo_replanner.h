#pragma once
// The replanner of the paper (Sect. V, Fig. 5): given the map, the current state and the global
// reference trajectory, it checks the reference within the replanning horizon; if it collides, it
// searches topologically distinct guide paths between the current position and the first safe
// reference point at or past the horizon (path_searching), optimises one trajectory per path with
// the two-phase path-guided optimisation (bspline_opt) in parallel on a pool of workers it owns, and
// returns the best verified one. When the search finds no path, or no candidate passes the final
// check, one more candidate guided by a grid A* path is tried as a last resort.
//
// Start state: the optimiser keeps the start control points, but its time reallocation (stretching
// the knot span to meet the limits) scales the start velocity and acceleration too. The chosen
// trajectory is then first eased into the stretch (UniformBspline::easeIntoStretch: the same path,
// the pace from before the stretch at the start, the stretched pace after 1 s, else 0.5 s or 2 s)
// and checked again (without reallocation); failing that, refitted through its own knot positions
// with the exact start derivatives and checked; when that refit fails the check it is refined once more
// (start and end states fixed) and checked; when that fails too the stretched trajectory is kept
// and the velocity step is reported (stats.start_velocity_jump_mps).
//
// Selection: among the candidates that passed the optimiser's final check (collision-free along the
// curve at its clearance, velocity and acceleration within limits) and reach the local goal within
// max_selection_delay_ratio of the fastest of them, the one with the least
//   cost = jerk integral [m^2/s^5] + duration_weight * duration [s]
// (duration_weight = 0 by default: the paper's smoothness criterion). The paper's candidates share
// one time allocation; after time reallocation they do not, and jerk falls with the fifth power of
// a stretch: by jerk alone a candidate slowed 2.5x for its detour won over one as smooth in shape
// at the reference's pace, and in a dense forest every plan crept. Ties go to the shorter guide.
//
// Determinism: with the search's max_time_s and the optimiser's max_time_s at 0, every budget is a
// count and the result does not depend on the number of workers or on timing (tested).
//
// Threads: replan() is not reentrant (one caller at a time); inside, each worker uses its own
// optimiser and writes only its own candidate; the map is only read.

#include <cmath>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "topo_planner/bspline_opt/path_guided_optimizer.h"
#include "topo_planner/path_searching/grid_astar.h"
#include "topo_planner/path_searching/topo_path_search.h"
#include "topo_planner/plan_env/thread_pool.h"
#include "topo_planner/topo_replan/polynomial_trajectory.h"

namespace topo_planner {

enum class ReplanStatus {
  kSuccess,
  kStartInCollision,    ///< the current position is closer than the optimiser's clearance (interpolated)
                        ///< to an obstacle, or inside the search's clearance (voxel centre) with no way
                        ///< out of it within max_search_start_offset_m
  kGoalInCollision,     ///< no safe reference point at or past the horizon
  kGoalOutOfMap,        ///< the local goal lies outside the map
  kInvalidInput,        ///< NaN/inf state, empty reference, invalid config
  kNoPath,              ///< neither the topological search nor A* found a guide path
  kOptimizationFailed,  ///< no candidate passed the final check
};
const char* toString(ReplanStatus status);

/// What the caller can fall back on when the status is not kSuccess.
enum class ReplanFallback {
  kNone,           ///< a verified trajectory is returned
  kKeepReference,  ///< the reference is free for safe_prefix_s more seconds: keep flying it and retry
  kStop,           ///< nothing safe ahead: brake now
};
const char* toString(ReplanFallback fallback);

struct ReplanRequest {
  FlatState start;                                ///< current state (its position, velocity, acceleration)
  const PolynomialTrajectory* reference = nullptr;  ///< the global reference
  double reference_time_s = 0.0;                  ///< time on the reference where the local segment begins
  /// The local goal no later on the reference than this: an intermediate goal not reached yet, so
  /// that the plans pass through it instead of cutting its corner [s].
  double max_local_goal_time_s = INFINITY;
  /// Failed attempts at this problem so far: the search is seeded with its seed + attempt, so a
  /// retry from the same state draws another roadmap (the result is still a function of the input).
  uint32_t attempt = 0;
};

/// The local replanning problem every method starts from (the replanner and the baselines alike):
/// the reference checked within the horizon, the local goal, and the colliding reference segment
/// fitted as the initial B-spline from the start state to the local goal.
struct LocalProblem {
  ReplanStatus status = ReplanStatus::kInvalidInput;  ///< kSuccess when the problem is well posed
  std::string message;
  Eigen::Vector3d start = Eigen::Vector3d::Zero();
  /// Where the guide search starts: the start, or, when the start keeps the optimiser's clearance
  /// but not the search's, the first point up the distance field that keeps the search's (the guide
  /// paths then begin with the start itself).
  Eigen::Vector3d search_start = Eigen::Vector3d::Zero();
  Eigen::Vector3d goal = Eigen::Vector3d::Zero();
  /// Where the guide search ends: the goal, or, when the goal is the final one and keeps the
  /// optimiser's clearance but not the search's (a goal beside an obstacle that the map now shows a
  /// little closer than when it was accepted), the first point up the distance field that keeps the
  /// search's (the guide paths then end with the goal itself).
  Eigen::Vector3d search_goal = Eigen::Vector3d::Zero();
  double start_time_s = 0.0;           ///< reference time of the local start
  double goal_time_s = 0.0;            ///< reference time of the local goal
  double collision_time_s = -1.0;      ///< first colliding reference time in the horizon; -1 if none
  double horizon_end_time_s = 0.0;
  UniformBspline initial;              ///< the reference segment as a cubic B-spline
  double initial_length_m = 0.0;       ///< its arc length [m]
  Eigen::Vector3d goal_velocity = Eigen::Vector3d::Zero();      ///< the reference's state at the local goal
  Eigen::Vector3d goal_acceleration = Eigen::Vector3d::Zero();
};

struct ReplanCandidate {
  Path guide;
  OptimizationResult result;
  double selection_cost = INFINITY;  ///< see the class comment; +inf when it failed
  bool start_repaired = false;          ///< its start velocity was restored after time reallocation
  double start_velocity_step_mps = 0.0; ///< what remains of the start velocity's change [m/s]
  std::string repair_note;              ///< why the start could not be restored (for the logs)
  /// The guide was long enough for a second try from a spline along it (initialAlong) after the
  /// first failed; `result` is then the better of the two (passed, else the larger clearance), and
  /// these say how the first, from the reference segment's timing, ended.
  bool retried_along = false;
  OptimizationStatus first_status = OptimizationStatus::kSuccess;
  double first_min_clearance_m = 0.0;
};

struct ReplanStats {
  bool searched = false;         ///< false when the reference was free within the horizon
  bool used_astar = false;       ///< an A* guide was tried (the search found nothing or no candidate passed)
  bool used_raw_refine = false;  ///< the guides were optimised again without preconditioning (raw_refine_fallback)
  double check_ms = 0.0;         ///< reference check and local problem
  double search_ms = 0.0;        ///< topological search (+ A* fallback)
  double optimize_ms = 0.0;      ///< the parallel optimisation, wall time
  double total_ms = 0.0;
  bool start_repaired = false;   ///< time reallocation changed the start derivatives and a refit restored them
  double start_velocity_jump_mps = 0.0;  ///< |v(0) - start velocity| of the returned trajectory
  int paths = 0;                 ///< guide paths optimised
  int feasible_candidates = 0;   ///< candidates that passed the final check
  TopoSearchStats search;
};

struct ReplanResult {
  ReplanStatus status = ReplanStatus::kInvalidInput;
  std::string message;
  UniformBspline trajectory;          ///< valid when status == kSuccess; starts at request.start
  double local_start_time_s = 0.0;    ///< reference time of the local start
  double local_goal_time_s = 0.0;     ///< reference time the trajectory rejoins the reference at
  double reference_collision_time_s = -1.0;  ///< first colliding reference time in the horizon; -1 if none
  std::vector<ReplanCandidate> candidates;   ///< one per guide path (for visualisation)
  RoadmapGraph roadmap;               ///< the search's roadmap, with search.keep_raw_paths (for visualisation)
  int chosen = -1;                    ///< index into candidates; -1 when the reference itself was kept
  ReplanFallback fallback = ReplanFallback::kNone;
  double safe_prefix_s = 0.0;         ///< with kKeepReference: collision-free reference time left
  ReplanStats stats;
};

class TopoReplanner {
 public:
  /// Most control point spacings of a local segment (the initial spline's fit is dense in them):
  /// 1000 x 0.35 m is 50 times the horizon; a longer one is a reference moving absurdly fast
  /// (kInvalidInput).
  static constexpr int kMaxInitialSegments = 1000;

  struct Config {
    TopoPathSearch::Config search;        ///< guide paths (Sect. IV)
    PathGuidedOptimizer::Config optimizer;  ///< PGO (Sect. III); its clearance_m is the final check's
    GridAStar::Config astar;              ///< last-resort guide (no topological path, or none passed)
    double horizon_m = 7.0;               ///< length of reference checked and replanned [m] ...
    /// ... or, when longer, this long of flight at the start's speed [s]; 0: horizon_m alone.
    double horizon_time_s = 0.0;
    double reference_clearance_m = 0.3;   ///< the reference collides where the ESDF is below this [m]
    /// When the reference collides at the horizon, the local goal is the first reference point past
    /// it that is followed by this much collision-free reference (not just the first free point:
    /// a goal right behind an obstacle forces a hairpin around it) [m]. 0 in the benchmarks.
    double local_goal_margin_m = 0.0;
    /// How far past the first free point beyond the horizon such a goal is looked for (past further
    /// collisions of the reference); beyond it, the goal is the end of the free stretch that follows
    /// that point, up to local_goal_margin_m long [m].
    double max_local_goal_extension_m = 5.0;
    double reference_sample_s = 0.01;     ///< time step of the reference check, at least 1e-4 [s]
    double control_point_spacing_m = 0.35;  ///< initial spline: about one control point per this [m]
    /// The initial spline's timing. false: the reference's own (the paper's: the local segment is the
    /// reference between the two times). true: along the same path, the fastest speed within the
    /// reference's own speed at each point where the reference keeps or loses speed (a corner, the
    /// goal), and within what its curvature allows where it gains speed (its own start from rest: a
    /// faster vehicle is not held to that ramp), from the start's speed at the optimiser's acceleration
    /// (feasibility_margin of it): a vehicle slower than the reference's timing (it started late, it
    /// slowed for an obstacle) is not asked to catch up with it, which asked for 22-220 m/s^2 at the
    /// start and stretched every candidate (time ratios of 1.3-1.6 at 5 m/s in the open).
    bool profile_timing = false;
    /// The local segment's timing aims at no more than this speed (the FSM's
    /// cruiseSpeed: what the camera's depth allows); 0: the optimiser's max_vel [m/s].
    double cruise_speed_mps = 0.0;
    /// A guide path longer than this times the reference segment whose candidate failed from the
    /// segment's timing is optimised again from an initial spline along the guide, timed for its
    /// length (initialAlong).
    double guide_timing_ratio = 1.15;
    /// Candidates whose start velocity differs from the start state's by more than this (time
    /// reallocation scaled it and the refit that restores it failed its check) are chosen only when
    /// no other candidate passed [m/s].
    double max_start_velocity_step_mps = 0.1;
    /// A start that keeps the optimiser's clearance but not the search's (a trajectory may pass an
    /// obstacle closer than the search's clearance, and replanning starts on it) is moved up the
    /// distance field at most this far for the search [m]. 0: such a start is kStartInCollision.
    /// The same holds for the final goal (the reference's end): within this distance of it, the
    /// reference is held to the optimiser's clearance rather than reference_clearance_m and the
    /// search's, and the search ends up the distance field from it.
    double max_search_start_offset_m = 0.3;
    /// A start closer to an obstacle than the smaller of this and the optimiser's clearance is
    /// kStartInCollision (by default the optimiser's clearance). A start between the two (the map
    /// grew beside the trajectory being flown) is planned from, and the plan must move out of the
    /// clearance (PathGuidedOptimizer's check) [m].
    double min_start_clearance_m = 1e9;
    /// When no candidate passed (the A* guide's included) and the optimiser refines in preconditioned
    /// coordinates (PathGuidedOptimizer::Config::precondition), every guide is optimised once more
    /// in the control points' own coordinates. The two descents can end in different local minima
    /// beside a narrow opening; this keeps every plan the raw refine found (a window in a corner at
    /// the band's floor, test_plan_problem) at no cost to the calls that pass.
    bool raw_refine_fallback = true;
    int num_threads = 2;                  ///< optimisation workers, the caller included
    double duration_weight = 0.0;         ///< selection cost weight of the duration [m^2/s^6]
    /// Only candidates that reach the local goal within this factor of the fastest one's time are
    /// chosen from (the least cost among them; see the class comment); >= 1, infinity: cost alone.
    double max_selection_delay_ratio = 1.25;

    bool validate(std::string* why) const;
  };

  /// nullptr with a reason for an invalid config.
  static std::unique_ptr<TopoReplanner> create(const Config& config, std::string* error);
  const Config& config() const { return config_; }

  ReplanResult replan(const EsdfMap& map, const ReplanRequest& request);

  /// The candidate the selection rule (class comment) chooses among those that passed (a finite
  /// selection_cost); -1 if none.
  static int selectCandidate(const std::vector<ReplanCandidate>& candidates, double max_start_velocity_step_mps,
                             double max_selection_delay_ratio);

  /// The local problem of a request (what replan() starts from), for baselines and diagnostics.
  LocalProblem localProblem(const EsdfMap& map, const ReplanRequest& request) const;

 private:
  explicit TopoReplanner(const Config& config);

  Config config_;
  ThreadPool pool_;
  /// The refit described in the class comment; false (trajectory unchanged) when not needed or not safe.
  /// `time_ratio`: the stretch of the reallocation (1: none).
  bool repairStart(const FlatState& start, const EsdfMap& map, double time_ratio, UniformBspline* trajectory,
                   std::string* why) const;
  /// The initial spline of profile_timing: the reference's path from the start to its time t_g,
  /// timed from the start's speed (see Config::profile_timing), fitted with
  /// `segments` knot intervals; the goal's velocity and acceleration (the reference's, scaled down
  /// when the profile arrives slower) are returned too. False when it cannot be timed or fitted.
  bool profileTimedSegment(const PolynomialTrajectory& ref, const FlatState& start, double t0, double t_g, int segments,
                           Eigen::Vector3d* goal_velocity, Eigen::Vector3d* goal_acceleration,
                           UniformBspline* out) const;
  /// The speed the timing aims at: cruise_speed_mps when set, the optimiser's max_vel otherwise.
  double cruiseSpeed() const {
    return config_.cruise_speed_mps > 0.0 ? std::min(config_.cruise_speed_mps, config_.optimizer.max_vel_mps)
                                          : config_.optimizer.max_vel_mps;
  }
  /// An initial spline along `guide`, timed for its length, when the guide is longer than
  /// guide_timing_ratio times the reference segment (a candidate that failed from the segment's
  /// timing is optimised again from it); nullopt otherwise.
  std::optional<UniformBspline> initialAlong(const LocalProblem& lp, const Path& guide) const;

  std::vector<PathGuidedOptimizer> optimizers_;  // one per worker
  std::vector<PathGuidedOptimizer> raw_optimizers_;  // the same without preconditioning (raw_refine_fallback)
  PathGuidedOptimizer checker_;                  // final check without time reallocation
  TopoPathSearch search_;
  GridAStar astar_;
};

}  // namespace topo_planner
