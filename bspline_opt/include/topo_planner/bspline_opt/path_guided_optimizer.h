#pragma once
// Path-guided trajectory optimisation, PGO (paper, Sect. III-B), and the plain gradient-based
// trajectory optimisation (GTO) baseline it is compared with.
//
//  * GuidePhase (phase 1), Eq. 1-3: f_p1 = l1s f_s + l1g f_g over the free control points
//    Q_p..Q_{N-p} (the first and last p are fixed by the boundary states). f_s is the elastic band
//    of Eq. 2, f_g the squared distance of Q_i to G_i, the guide path sampled uniformly by arc length
//    (G_p..G_{N-p} at arc length (i - p + 1) / (N - 2p + 2), the ends excluded; with
//    guide_follows_initial, at the fractions of the guide's length that the initial's control
//    points lie at along its control polygon, keeping the initial's timing). It is an
//    unconstrained QP with a pentadiagonal SPD Hessian l1s D^T D + l1g I: one banded LDL^T
//    factorisation and one solve for the three coordinates, no iteration.
//  * RefinePhase (phase 2), Eq. 4: f_p2 = l2s f_s + l2c f_c + l2d (f_v + f_a) with the terms of
//    bspline_costs.h, minimised with NLopt (LD_LBFGS by default) under an evaluation budget.
//  * Then feasibility is enforced, not only weighted: when the derivative control points exceed the
//    limits the knot span is lengthened (UniformBspline::reallocateTime, the path is unchanged).
//  * Final check: the curve is sampled at most a check step apart in arc length (half a voxel by
//    default; the time step is the step over the speed bound) on the true ESDF (trilinear
//    EsdfMap::query) against clearance_m (a curve that starts inside it must move out: until it
//    first reaches it, no sample more than 1 cm closer than the start), and the limits are checked
//    on the derivative control
//    points (convex hull bound, so they hold along the whole curve), all but those the start state
//    alone fixes (UniformBspline::maxAccelerationPastStart): a curve planned from hard braking keeps
//    that state at its start, and is held to the limits from there on.
//
// GTO is phase 2 alone from the initial spline, then the same reallocation and check; the restart
// variant runs it from the initial spline and from n - 1 perturbed copies (seeded), keeping the best.
//
// Threads: every method is const and keeps no state between calls (each run owns its NLopt object,
// and the map is only read), so one optimizer, or one per worker, can run in parallel threads on
// the same const EsdfMap while no thread writes the map.

#include <Eigen/Core>
#include <cstdint>
#include <string>
#include <vector>

#include "topo_planner/bspline_opt/optimization_status.h"
#include "topo_planner/bspline_opt/uniform_bspline.h"
#include "topo_planner/plan_env/esdf_map.h"

namespace topo_planner {

/// A guide path: waypoints in the world frame (the same type as path_searching's Path).
using Path = std::vector<Eigen::Vector3d>;

/// Cost breakdown of a result (unweighted terms, as in bspline_costs.h).
struct OptimizationCosts {
  double smoothness = 0.0;   ///< f_s of the result [m^2]
  double guide = 0.0;        ///< f_g at the end of phase 1 [m^2]; 0 when there was no phase 1
  double collision = 0.0;    ///< f_c of the result, d0 = Config::d0_m [m^2]
  double feasibility = 0.0;  ///< f_v + f_a of the result, after time reallocation
  double phase2 = 0.0;       ///< weighted f_p2 at the end of phase 2 (before reallocation)
  double jerk_integral_m2ps5 = 0.0;  ///< integral of ||jerk||^2 over the result [m^2/s^5]
  double duration_s = 0.0;   ///< duration of the result [s]
};

struct OptimizationStats {
  double phase1_ms = 0.0;  ///< guide phase (closed form)
  double phase2_ms = 0.0;  ///< refine phase (NLopt), summed over restarts
  double check_ms = 0.0;   ///< reallocation and final check
  double total_ms = 0.0;
  int iterations = 0;      ///< phase-2 objective evaluations (NLopt's budget unit), summed over restarts
  int nlopt_result = 0;    ///< NLopt's result code of the (chosen) run; see nlopt.h
  int runs = 0;            ///< phase-2 runs (1, n for gtoWithRestarts, more after collision retries)
  int best_run = 0;        ///< the run the result comes from (0 = unperturbed)
  double time_ratio = 1.0;     ///< duration after / before time reallocation
  double min_clearance_m = 0.0;  ///< smallest ESDF distance over the curve samples [m]
  double min_clearance_t_s = 0.0;  ///< curve time of that sample [s]
  int check_samples = 0;        ///< curve samples of the final check
  double max_vel_mps = 0.0;     ///< bound from the velocity control points of the result past its start
  double max_acc_mps2 = 0.0;    ///< ... and from its acceleration control points (maxAccelerationPastStart)
  bool guide_phase_kept = false;  ///< the result is the guide phase's spline (Config::guide_phase_fallback)
};

/// A cubic's first three control points set for the start state (p, v, a) at its knot span (after
/// a re-timing, which scales the start's derivatives). False (unchanged) for other degrees.
bool setCubicStart(const Eigen::Vector3d& p, const Eigen::Vector3d& v, const Eigen::Vector3d& a, UniformBspline* s);

struct OptimizationResult {
  OptimizationStatus status = OptimizationStatus::kInvalidInput;
  std::string message;   ///< why, for the failures (empty on success)
  UniformBspline spline;  ///< the optimised spline (the input when the input was invalid)
  OptimizationCosts cost;
  OptimizationStats stats;
};

class PathGuidedOptimizer {
 public:
  struct Config {
    // Phase 1, Eq. 1: f_p1 = l1s f_s + l1g f_g.
    double l1s = 1.0;  ///< lambda_1s: smoothness weight of the guide phase
    double l1g = 1.0;  ///< lambda_1g: guide weight (> 0, makes the QP strictly convex)
    /// The guide points spaced as the initial spline's control points are along its polygon (its
    /// timing) instead of uniformly (a constant pace). An initial that accelerates from a slow start
    /// (TopoReplanner's profile_timing) pulled to a constant pace had control-point accelerations
    /// of 24 m/s^2 in its guide phase, and the stretched retry stretched the plan 2.5x for them.
    bool guide_follows_initial = false;
    // Phase 2, Eq. 4: f_p2 = l2s f_s + l2c f_c + l2d (f_v + f_a).
    double l2s = 1.0;   ///< lambda_2s: smoothness weight of the refine phase
    double l2c = 10.0;  ///< lambda_2c: collision weight
    double l2d = 1.0;   ///< lambda_2d: velocity and acceleration feasibility weight
    double d0_m = 0.5;  ///< the collision cost is zero at ESDF distances beyond this [m]
    double max_vel_mps = 3.0;   ///< velocity limit (feasibility cost, reallocation, check) [m/s]
    double max_acc_mps2 = 2.5;  ///< acceleration limit [m/s^2]
    /// The refine phase's feasibility cost starts at this fraction of max_vel_mps and max_acc_mps2,
    /// in (0, 1]; the reallocation and the check keep the full limits. Below 1 the refined curves
    /// keep headroom: a replan that starts from their state (accelerating near the limit) can still
    /// turn or slow down without a stretch that steps its start velocity. 1: the paper's cost.
    double feasibility_margin = 1.0;
    std::string algorithm = "LD_LBFGS";  ///< NLopt algorithm name, e.g. LD_LBFGS, LD_MMA, LD_TNEWTON_PRECOND_RESTART
    int max_iterations = 200;  ///< NLopt objective evaluations per phase-2 run (maxeval)
    double max_time_s = 0.0;   ///< NLopt time limit per phase-2 run [s]; 0 = none (tests use counts only)
    double xtol_rel = 1e-5;    ///< NLopt stop: relative change of the control points
    double ftol_rel = 1e-6;    ///< NLopt stop: relative change of f_p2
    /// Past steps kept by the quasi-Newton algorithms (LBFGS, TNEWTON, VAR). 0 lets NLopt choose,
    /// which is "10 MiB worth of vectors": thousands here, and most of the run time goes to them.
    int vector_storage = 10;
    /// Refine in preconditioned coordinates y = L^T x, where L L^T is the Hessian of the smoothness
    /// term over the free control points (a banded Cholesky factor, computed once per run). The
    /// second differences make that Hessian ill-conditioned (its condition number grows as the
    /// fourth power of the number of points), and L-BFGS on the raw control points used every
    /// evaluation of its budget; in y the smoothness term is the identity's and the collision and
    /// feasibility terms are what is left to learn. Same minimum, fewer evaluations to reach it.
    bool precondition = true;
    // Feasibility and final check.
    bool reallocate_time = true;  ///< lengthen the knot span when the limits are exceeded (else kInfeasible)
    double max_time_ratio = 3.0;  ///< a longer stretch is kInfeasible (the stretched spline is returned)
    double clearance_m = 0.25;    ///< every curve sample keeps at least this ESDF distance [m] (see the check)
    /// Height band (a geofence): a curve sample farther out of it than the curve's start or end
    /// (by more than 0.05 m) fails the check as leaving the map [m].
    double min_z_m = -1e9;
    double max_z_m = 1e9;
    /// The collision cost counts the map window's and the band's faces as obstacles this much
    /// farther than they are (bspline_costs.h): they need no clearance, and at 0 a face within d0_m
    /// pushes a curve that keeps to a narrow way beside it (a window at the map's edge, a gap above
    /// the floor) into the obstacles across the way [m]. 0: faces count at their distance.
    double face_offset_m = 0.0;
    double check_step_m = 0.0;    ///< arc-length step of the collision check [m]; 0 = half a voxel
    bool unknown_is_free = true;  ///< unknown voxels pass the check (replanning in a partial map)
    // PGO's second chance: a refined curve that fails the check in collision (the cost, on control
    // points, is met while the curve between them cuts a corner, or smoothness and feasibility
    // outweighed it in a narrow opening) is refined again from where it ended, each time with the
    // collision weight times collision_retry_factor and d0 raised by collision_retry_d0_step_m.
    int collision_retries = 2;             ///< extra refine runs at most (0 = the paper's single run)
    double collision_retry_factor = 4.0;   ///< l2c multiplier per extra run (>= 1)
    double collision_retry_d0_step_m = 0.1;  ///< d0_m increase per extra run [m]
    /// Before those: when the refined curve collides and the guide phase's spline breaks the
    /// refine's limits (a detour, or a sharp turn into an opening, flown in the reference segment's
    /// time), refine again from that spline with its time stretched to the limits, then time the
    /// result as tightly as the limits allow (never faster than the segment). Refined in the
    /// segment's time, the feasibility cost outweighs the collision cost of a thin wall, whose two
    /// sides the control points straddle, and pulls the curve through it (a wall beside the window
    /// the guide goes through). The stretch is part of stats.time_ratio. false: the paper's PGO.
    bool stretched_retry = true;
    /// Last: when every refined curve collides, the guide phase's spline, timed like the stretched
    /// retry's result, is the result if it passes the check. The refine trades clearance for
    /// smoothness and feasibility, and in a tight window (its bottom near the band's floor) it
    /// can push a curve that was clear out of clearance. false: the paper's PGO.
    bool guide_phase_fallback = true;
    // GTO with random restarts: restart r > 0 starts from the initial spline plus a smooth lateral
    // bump (zero at the fixed ends) and per-point noise.
    double restart_offset_m = 1.5;  ///< largest bump, uniform in [0, this], perpendicular to start-goal [m]
    double restart_noise_m = 0.1;   ///< standard deviation of the per-point noise [m]

    /// True when every field is in range (weights finite and >= 0, l1g > 0, positive limits,
    /// known algorithm, ...); otherwise says why.
    bool validate(std::string* why) const;
  };

  explicit PathGuidedOptimizer(const Config& config) : config_(config) {}
  const Config& config() const { return config_; }

  /// The guide points G_p..G_{N-p} of the free control points: `count` points at arc lengths
  /// i / (count + 1), i = 1..count, of the guide (its ends excluded), one per row. Precondition:
  /// non-empty guide, count >= 1.
  static Eigen::MatrixX3d guideSamples(const Path& guide, int count);
  /// The guide points of the free control points first..last of `q` (a spline's control points)
  /// at the fractions of the guide's length that they lie at along q's control polygon (see
  /// guide_follows_initial). Uniform (guideSamples) when the polygon has no length.
  static Eigen::MatrixX3d guideSamplesAlong(const Path& guide, const Eigen::MatrixX3d& q, int first, int last);

  /// Phase 1 only: the warm-up spline (kSuccess) with cost.guide and cost.smoothness; no check.
  OptimizationResult guidePhase(const UniformBspline& initial, const Path& guide) const;
  /// Phase 2 only: the refined spline (kSuccess when NLopt ran without error); no reallocation, no check.
  OptimizationResult refinePhase(const UniformBspline& spline, const EsdfMap& map) const;
  /// Time reallocation and final check of a spline (status, costs and stats filled).
  OptimizationResult check(const UniformBspline& spline, const EsdfMap& map) const;

  /// PGO: phase 1, phase 2, time reallocation, final check (phase 2 again while the check finds a
  /// collision: from the stretched guide-phase spline (stretched_retry), then up to
  /// collision_retries times from where it ended; then the guide phase's spline itself,
  /// guide_phase_fallback).
  OptimizationResult optimize(const UniformBspline& initial, const Path& guide, const EsdfMap& map) const;
  /// Baseline GTO: phase 2 from the initial spline, time reallocation, final check.
  OptimizationResult gto(const UniformBspline& initial, const EsdfMap& map) const;
  /// GTO from the initial spline and runs - 1 perturbed copies (generator seeded with seed); the
  /// best result: successes first, then the lowest phase-2 cost. runs >= 1.
  OptimizationResult gtoWithRestarts(const UniformBspline& initial, const EsdfMap& map, int runs, uint32_t seed) const;

 private:
  // Checks the config and the spline (one free control point at least); fills the result on failure.
  bool validateInput(const UniformBspline& spline, OptimizationResult* result) const;
  // Reallocation, final check and cost breakdown of result->spline.
  void finish(const EsdfMap& map, OptimizationResult* result) const;

  Config config_;
};

}  // namespace topo_planner
