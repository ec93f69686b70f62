#include "topo_planner/bspline_opt/path_guided_optimizer.h"

#include <nlopt.hpp>

#include <algorithm>
#include <cassert>
#include <chrono>
#include <cmath>
#include <limits>
#include <random>

#include "topo_planner/bspline_opt/bspline_costs.h"

namespace topo_planner {

// p = (Q0 + 4 Q1 + Q2) / 6, v = (Q2 - Q0) / (2 dt), a = (Q0 - 2 Q1 + Q2) / dt^2.
bool setCubicStart(const Eigen::Vector3d& p, const Eigen::Vector3d& v, const Eigen::Vector3d& a, UniformBspline* s) {
  if (s->degree() != 3 || s->numControlPoints() < 3) return false;
  const double dt = s->knotSpan();
  const Eigen::Vector3d q1 = p - a * dt * dt / 6.0;
  s->controlPoints().row(0) = (q1 - v * dt + a * dt * dt / 2.0).transpose();
  s->controlPoints().row(1) = q1.transpose();
  s->controlPoints().row(2) = (q1 + v * dt + a * dt * dt / 2.0).transpose();
  return true;
}

namespace {

using Clock = std::chrono::steady_clock;

constexpr double kMaxCheckIntervals = 1e7;  // bound of the final check's curve samples
constexpr double kStartSlackM = 0.01;       // a curve leaving the clearance from inside it: sampling slack [m]
double msSince(Clock::time_point t0) { return std::chrono::duration<double, std::milli>(Clock::now() - t0).count(); }

bool finiteNonNegative(double x) { return std::isfinite(x) && x >= 0.0; }

}  // namespace

Eigen::MatrixX3d PathGuidedOptimizer::guideSamples(const Path& path, int m) {
  assert(!path.empty() && m >= 1);
  Eigen::MatrixX3d g(m, 3);
  double total = 0.0;
  for (size_t i = 1; i < path.size(); ++i) total += (path[i] - path[i - 1]).norm();
  if (path.size() == 1 || total <= 0.0) {
    g.rowwise() = path.front().transpose();
    return g;
  }
  size_t seg = 1;
  double seg_start = 0.0, seg_len = (path[1] - path[0]).norm();
  for (int i = 1; i <= m; ++i) {
    const double target = total * i / (m + 1);
    while (seg + 1 < path.size() && seg_start + seg_len < target) {
      seg_start += seg_len;
      ++seg;
      seg_len = (path[seg] - path[seg - 1]).norm();
    }
    const double s = seg_len > 0.0 ? std::clamp((target - seg_start) / seg_len, 0.0, 1.0) : 1.0;
    g.row(i - 1) = (path[seg - 1] + s * (path[seg] - path[seg - 1])).transpose();
  }
  return g;
}

Eigen::MatrixX3d PathGuidedOptimizer::guideSamplesAlong(const Path& guide, const Eigen::MatrixX3d& q, int first,
                                                       int last) {
  assert(!guide.empty() && first >= 1 && last >= first && last + 1 < q.rows());
  const int m = last - first + 1;
  std::vector<double> polygon{0.0};
  for (int i = 1; i < q.rows(); ++i) polygon.push_back(polygon.back() + (q.row(i) - q.row(i - 1)).norm());
  double total = 0.0;
  for (size_t i = 1; i < guide.size(); ++i) total += (guide[i] - guide[i - 1]).norm();
  if (!(polygon.back() > 1e-9) || guide.size() == 1 || !(total > 0.0)) return guideSamples(guide, m);
  Eigen::MatrixX3d g(m, 3);
  size_t seg = 1;
  double seg_start = 0.0, seg_len = (guide[1] - guide[0]).norm();
  for (int j = 0; j < m; ++j) {
    const double target = total * polygon[size_t(first + j)] / polygon.back();  // non-decreasing in j
    while (seg + 1 < guide.size() && seg_start + seg_len < target) {
      seg_start += seg_len;
      ++seg;
      seg_len = (guide[seg] - guide[seg - 1]).norm();
    }
    const double f = seg_len > 0.0 ? std::clamp((target - seg_start) / seg_len, 0.0, 1.0) : 1.0;
    g.row(j) = (guide[seg - 1] + f * (guide[seg] - guide[seg - 1])).transpose();
  }
  return g;
}

namespace {

// The phase-2 problem handed to NLopt: the free control points flattened row by row.
struct RefineProblem {
  const PathGuidedOptimizer::Config* config = nullptr;
  const EsdfMap* map = nullptr;
  Eigen::MatrixX3d q, grad;
  double dt = 0.0;
  int first = 0, last = 0;
  int evaluations = 0, max_evaluations = 0;
  bool non_finite = false, budget_exhausted = false;
  double best_cost = std::numeric_limits<double>::infinity();
  std::vector<double> best_x;

  // The preconditioner (Config::precondition): the lower banded Cholesky factor L of the
  // smoothness Hessian over the free points, L(i, i) = l0(i), L(i, i-1) = l1(i), L(i, i-2) = l2(i).
  // The solver's variables are y = L^T x (x: the free control points, a column per axis).
  bool preconditioned = false;
  Eigen::VectorXd l0, l1, l2;

  // The Hessian of sum ||Q_{i+1} - 2 Q_i + Q_{i-1}||^2 over the free points (with the fixed ends),
  // times 2 l2s, factored in place. False (no preconditioning) when it is not positive definite.
  bool factorSmoothness(int n, double l2s) {
    const int m = last - first + 1;
    if (!(l2s > 0.0) || m < 1) return false;
    l0 = Eigen::VectorXd::Zero(m), l1 = Eigen::VectorXd::Zero(m), l2 = Eigen::VectorXd::Zero(m);
    const double coeff[3] = {1.0, -2.0, 1.0};
    for (int i = std::max(1, first - 1); i <= std::min(n - 2, last + 1); ++i)
      for (int a = 0; a < 3; ++a)
        for (int b = 0; b <= a; ++b) {
          const int ia = i - 1 + a - first, ib = i - 1 + b - first;
          if (ia < 0 || ia >= m || ib < 0 || ib >= m) continue;
          const double h = 2.0 * l2s * coeff[a] * coeff[b];
          (ia == ib ? l0 : ia - ib == 1 ? l1 : l2)(ia) += h;
        }
    for (int i = 0; i < m; ++i) {  // banded Cholesky, in place
      if (i >= 2) l2(i) /= l0(i - 2);
      if (i >= 1) l1(i) = (l1(i) - (i >= 2 ? l2(i) * l1(i - 1) : 0.0)) / l0(i - 1);
      const double d = l0(i) - (i >= 1 ? l1(i) * l1(i) : 0.0) - (i >= 2 ? l2(i) * l2(i) : 0.0);
      if (!(d > 0.0) || !std::isfinite(d)) return false;
      l0(i) = std::sqrt(d);
    }
    return true;
  }
  // x from y: solve L^T x = y (backward).
  void unpack(const double* y) {
    const int m = last - first + 1;
    for (int c = 0; c < 3; ++c)
      for (int i = m - 1; i >= 0; --i) {
        double v = y[3 * i + c];
        if (preconditioned) {
          if (i + 1 < m) v -= l1(i + 1) * q(first + i + 1, c);
          if (i + 2 < m) v -= l2(i + 2) * q(first + i + 2, c);
          v /= l0(i);
        }
        q(first + i, c) = v;
      }
  }
  // y from the current q: y = L^T x.
  void pack(double* y) const {
    const int m = last - first + 1;
    for (int c = 0; c < 3; ++c)
      for (int i = 0; i < m; ++i) {
        double v = q(first + i, c);
        if (preconditioned) {
          v *= l0(i);
          if (i + 1 < m) v += l1(i + 1) * q(first + i + 1, c);
          if (i + 2 < m) v += l2(i + 2) * q(first + i + 2, c);
        }
        y[3 * i + c] = v;
      }
  }
  // The gradient in y from grad (in x): solve L gy = gx (forward).
  void packGradient(double* g) {
    const int m = last - first + 1;
    for (int c = 0; c < 3; ++c)
      for (int i = 0; i < m; ++i) {
        double v = grad(first + i, c);
        if (preconditioned) {
          if (i >= 1) v -= l1(i) * g[3 * (i - 1) + c];
          if (i >= 2) v -= l2(i) * g[3 * (i - 2) + c];
          v /= l0(i);
        }
        g[3 * i + c] = v;
      }
  }
  // f_p2 and its gradient; also the unweighted terms when asked.
  double cost(Eigen::MatrixX3d* g, double* fs = nullptr, double* fc = nullptr, double* fd = nullptr) {
    const PathGuidedOptimizer::Config& c = *config;
    if (g) g->setZero();
    const double s = smoothnessCost(q, first, last, c.l2s, g);
    const double col = collisionCost(q, first, last, *map, c.d0_m, c.l2c, g, c.min_z_m, c.max_z_m, c.face_offset_m);
    const double d = velocityCost(q, dt, c.feasibility_margin * c.max_vel_mps, c.l2d, g) +
                     accelerationCost(q, dt, c.feasibility_margin * c.max_acc_mps2, c.l2d, g);
    if (fs) *fs = s;
    if (fc) *fc = col;
    if (fd) *fd = d;
    return c.l2s * s + c.l2c * col + c.l2d * d;
  }
  double evaluate(unsigned n, const double* x, double* g) {
    // Some algorithms (the Luksan codes behind LD_LBFGS and LD_TNEWTON*) check maxeval only between
    // iterations; stop at the budget exactly so that every algorithm gets the same count.
    if (evaluations >= max_evaluations) {
      budget_exhausted = true;
      throw nlopt::forced_stop();
    }
    ++evaluations;
    unpack(x);
    const double f = cost(g ? &grad : nullptr);
    if (!std::isfinite(f) || (g && !grad.allFinite())) {
      non_finite = true;
      throw nlopt::forced_stop();  // caught by NLopt's C++ wrapper, re-thrown by optimize()
    }
    if (g) packGradient(g);
    if (f < best_cost) {
      best_cost = f;
      best_x.assign(x, x + n);
    }
    return f;
  }
  static double objective(unsigned n, const double* x, double* g, void* data) {
    return static_cast<RefineProblem*>(data)->evaluate(n, x, g);
  }
};

}  // namespace

bool PathGuidedOptimizer::Config::validate(std::string* why) const {
  auto fail = [&](const std::string& reason) {
    if (why) *why = reason;
    return false;
  };
  if (!finiteNonNegative(l1s) || !std::isfinite(l1g) || l1g <= 0.0) return fail("l1s must be >= 0 and l1g > 0");
  if (!finiteNonNegative(l2s) || !finiteNonNegative(l2c) || !finiteNonNegative(l2d))
    return fail("l2s, l2c, l2d must be finite and >= 0");
  if (!std::isfinite(d0_m) || d0_m <= 0.0) return fail("d0_m must be positive");
  if (!std::isfinite(max_vel_mps) || max_vel_mps <= 0.0 || !std::isfinite(max_acc_mps2) || max_acc_mps2 <= 0.0)
    return fail("max_vel_mps and max_acc_mps2 must be positive");
  if (!(feasibility_margin > 0.0 && feasibility_margin <= 1.0)) return fail("feasibility_margin must be in (0, 1]");
  const int algorithm_id = int(nlopt_algorithm_from_string(algorithm.c_str()));
  if (algorithm_id < 0 || algorithm_id >= int(NLOPT_NUM_ALGORITHMS))
    return fail("unknown NLopt algorithm '" + algorithm + "'");
  if (max_iterations < 1) return fail("max_iterations must be >= 1");
  if (vector_storage < 0) return fail("vector_storage must be >= 0");
  if (!finiteNonNegative(max_time_s) || !finiteNonNegative(xtol_rel) || !finiteNonNegative(ftol_rel))
    return fail("max_time_s, xtol_rel, ftol_rel must be finite and >= 0");
  if (!std::isfinite(max_time_ratio) || max_time_ratio < 1.0) return fail("max_time_ratio must be >= 1");
  if (!finiteNonNegative(clearance_m) || !finiteNonNegative(check_step_m))
    return fail("clearance_m and check_step_m must be finite and >= 0");
  if (collision_retries < 0 || !std::isfinite(collision_retry_factor) || collision_retry_factor < 1.0 ||
      !finiteNonNegative(collision_retry_d0_step_m))
    return fail("collision_retries must be >= 0, collision_retry_factor >= 1, collision_retry_d0_step_m >= 0");
  if (!finiteNonNegative(face_offset_m)) return fail("face_offset_m must be finite and >= 0");
  if (!finiteNonNegative(restart_offset_m) || !finiteNonNegative(restart_noise_m))
    return fail("restart_offset_m and restart_noise_m must be finite and >= 0");
  return true;
}

bool PathGuidedOptimizer::validateInput(const UniformBspline& spline, OptimizationResult* result) const {
  std::string why;
  result->spline = spline;
  if (!config_.validate(&why)) {
    result->status = OptimizationStatus::kInvalidInput;
    result->message = "invalid config: " + why;
    return false;
  }
  if (!spline.isValid(&why)) {
    result->status = OptimizationStatus::kInvalidInput;
    result->message = "invalid spline: " + why;
    return false;
  }
  if (spline.numControlPoints() < 2 * spline.degree() + 1) {
    result->status = OptimizationStatus::kInvalidInput;
    result->message = "invalid spline: fewer than 2 * degree + 1 control points (no free control point)";
    return false;
  }
  return true;
}

OptimizationResult PathGuidedOptimizer::guidePhase(const UniformBspline& initial, const Path& guide) const {
  const Clock::time_point t0 = Clock::now();
  OptimizationResult result;
  if (!validateInput(initial, &result)) return result;
  if (guide.empty()) {
    result.status = OptimizationStatus::kInvalidInput;
    result.message = "empty guide path";
    return result;
  }
  for (const Eigen::Vector3d& p : guide)
    if (!p.allFinite()) {
      result.status = OptimizationStatus::kInvalidInput;
      result.message = "guide path not finite";
      return result;
    }

  const int n = initial.numControlPoints(), p = initial.degree();
  const int first = p, last = n - 1 - p, m = last - first + 1;
  const Eigen::MatrixX3d& q0 = initial.controlPoints();
  const Eigen::MatrixX3d g =
      config_.guide_follows_initial ? guideSamplesAlong(guide, q0, first, last) : guideSamples(guide, m);

  // H = l1s D_f^T D_f + l1g I (lower band: diagonal, first and second subdiagonal) and
  // b = l1g G - l1s D_f^T D_c Q_c, from the second differences that touch a free point.
  Eigen::VectorXd diag = Eigen::VectorXd::Constant(m, config_.l1g), sub1 = Eigen::VectorXd::Zero(m),
                  sub2 = Eigen::VectorXd::Zero(m);
  Eigen::MatrixX3d x = config_.l1g * g;  // right-hand side, then the solution
  const double coeff[3] = {1.0, -2.0, 1.0};
  for (int i = std::max(1, first - 1); i <= std::min(n - 2, last + 1); ++i)
    for (int a = 0; a < 3; ++a) {
      const int ia = i - 1 + a;
      if (ia < first || ia > last) continue;
      for (int b = 0; b < 3; ++b) {
        const int ib = i - 1 + b;
        const double h = config_.l1s * coeff[a] * coeff[b];
        if (ib < first || ib > last)
          x.row(ia - first) -= h * q0.row(ib);
        else if (ib == ia)
          diag(ia - first) += h;
        else if (ib == ia - 1)
          sub1(ia - first) += h;
        else if (ib == ia - 2)
          sub2(ia - first) += h;
      }
    }
  // Banded LDL^T: l1(i) = L(i, i-1), l2(i) = L(i, i-2), d(i) = D(i), in place.
  Eigen::VectorXd& d = diag;
  Eigen::VectorXd& l1 = sub1;
  Eigen::VectorXd& l2 = sub2;
  for (int i = 0; i < m; ++i) {
    if (i >= 2) l2(i) /= d(i - 2);
    if (i >= 1) l1(i) = (l1(i) - (i >= 2 ? l2(i) * d(i - 2) * l1(i - 1) : 0.0)) / d(i - 1);
    if (i >= 1) d(i) -= l1(i) * l1(i) * d(i - 1);
    if (i >= 2) d(i) -= l2(i) * l2(i) * d(i - 2);
    if (!(d(i) > 0.0)) {
      result.status = OptimizationStatus::kOptimizationFailed;
      result.message = "guide phase: system not positive definite";
      return result;
    }
  }
  for (int i = 1; i < m; ++i) {
    x.row(i) -= l1(i) * x.row(i - 1);
    if (i >= 2) x.row(i) -= l2(i) * x.row(i - 2);
  }
  for (int i = 0; i < m; ++i) x.row(i) /= d(i);
  for (int i = m - 2; i >= 0; --i) {
    x.row(i) -= l1(i + 1) * x.row(i + 1);
    if (i + 2 < m) x.row(i) -= l2(i + 2) * x.row(i + 2);
  }

  result.spline.controlPoints().middleRows(first, m) = x;
  const Eigen::MatrixX3d& q = result.spline.controlPoints();
  if (!q.allFinite()) {
    result.status = OptimizationStatus::kOptimizationFailed;
    result.message = "guide phase: solution not finite";
    return result;
  }
  result.cost.guide = guideCost(q, g, first, last, 0.0, nullptr);
  result.cost.smoothness = smoothnessCost(q, first, last, 0.0, nullptr);
  result.cost.duration_s = result.spline.duration();
  result.status = OptimizationStatus::kSuccess;
  result.stats.phase1_ms = result.stats.total_ms = msSince(t0);
  return result;
}

OptimizationResult PathGuidedOptimizer::refinePhase(const UniformBspline& spline, const EsdfMap& map) const {
  const Clock::time_point t0 = Clock::now();
  OptimizationResult result;
  if (!validateInput(spline, &result)) return result;

  RefineProblem problem;
  problem.config = &config_;
  problem.map = &map;
  problem.q = spline.controlPoints();
  problem.grad.resize(problem.q.rows(), 3);
  problem.dt = spline.knotSpan();
  problem.max_evaluations = config_.max_iterations;
  problem.first = spline.degree();
  problem.last = spline.numControlPoints() - 1 - spline.degree();
  const int m = problem.last - problem.first + 1;
  problem.preconditioned = config_.precondition && problem.factorSmoothness(int(problem.q.rows()), config_.l2s);
  std::vector<double> x(size_t(3 * m));
  problem.pack(x.data());

  std::string error;
  try {
    nlopt::opt opt(config_.algorithm.c_str(), unsigned(3 * m));
    opt.set_min_objective(&RefineProblem::objective, &problem);
    opt.set_maxeval(config_.max_iterations);
    if (config_.max_time_s > 0.0) opt.set_maxtime(config_.max_time_s);
    opt.set_xtol_rel(config_.xtol_rel);
    opt.set_ftol_rel(config_.ftol_rel);
    opt.set_vector_storage(unsigned(config_.vector_storage));
    double f = 0.0;
    result.stats.nlopt_result = int(opt.optimize(x, f));
  } catch (const nlopt::roundoff_limited&) {
    // The line search cannot make progress at machine precision: a converged run, keep the best point.
    result.stats.nlopt_result = int(nlopt::ROUNDOFF_LIMITED);
  } catch (const nlopt::forced_stop&) {
    result.stats.nlopt_result = int(nlopt::FORCED_STOP);
    error = "NLopt forced stop";
  } catch (const std::exception& e) {
    result.stats.nlopt_result = int(nlopt::FAILURE);
    error = std::string("NLopt: ") + e.what();
  }
  // Our own stops: a non-finite cost is a failure; the evaluation budget is not (some algorithms
  // report the forced stop at the budget as a generic failure).
  if (problem.non_finite) {
    error = "cost or gradient not finite";
  } else if (problem.budget_exhausted) {
    error.clear();
    result.stats.nlopt_result = int(nlopt::MAXEVAL_REACHED);
  }
  result.stats.iterations = problem.evaluations;
  result.stats.runs = 1;
  if (error.empty() && problem.best_x.empty()) error = "NLopt made no evaluation";
  if (!error.empty() && problem.preconditioned && result.stats.nlopt_result == int(nlopt::FAILURE)) {
    // Luksan's generic failure (its line search found no descent, in 1 of 500 bench-opt tasks in
    // the preconditioned coordinates): the run again in the raw ones; both runs' work counts.
    Config raw = config_;
    raw.precondition = false;
    OptimizationResult again = PathGuidedOptimizer(raw).refinePhase(spline, map);
    again.stats.iterations += problem.evaluations;
    again.stats.runs += 1;
    again.stats.phase2_ms = again.stats.total_ms = msSince(t0);
    return again;
  }
  if (!error.empty()) {
    result.status = OptimizationStatus::kOptimizationFailed;
    result.message = error;
    result.stats.phase2_ms = result.stats.total_ms = msSince(t0);
    return result;
  }
  problem.unpack(problem.best_x.data());
  double fs = 0.0, fc = 0.0, fd = 0.0;
  result.cost.phase2 = problem.cost(nullptr, &fs, &fc, &fd);
  result.cost.smoothness = fs;
  result.cost.collision = fc;
  result.cost.feasibility = fd;
  result.cost.duration_s = spline.duration();
  result.spline.controlPoints() = problem.q;
  result.status = OptimizationStatus::kSuccess;
  result.stats.phase2_ms = result.stats.total_ms = msSince(t0);
  return result;
}

void PathGuidedOptimizer::finish(const EsdfMap& map, OptimizationResult* result) const {
  const Clock::time_point t0 = Clock::now();
  UniformBspline& spline = result->spline;
  OptimizationStats& stats = result->stats;
  const int first = spline.degree(), last = spline.numControlPoints() - 1 - spline.degree();
  result->status = OptimizationStatus::kSuccess;
  result->message.clear();

  // Feasibility first (it does not move the path): stretch time when allowed. The derivative control
  // points the start state alone fixes are exempt: that state is the vehicle's already (hard
  // braking, or a velocity point a0 dt / 2 past the limit), no knot span helps it, and stretching
  // would change it. Every other one, up to the end state, is held to the limits.
  const double duration_before = spline.duration();
  if (config_.reallocate_time) spline.reallocateTime(config_.max_vel_mps, config_.max_acc_mps2, true);
  stats.time_ratio = spline.duration() / duration_before;
  stats.max_vel_mps = spline.maxVelocityPastStart();
  stats.max_acc_mps2 = spline.maxAccelerationPastStart();
  const bool feasible = stats.max_vel_mps <= config_.max_vel_mps * (1.0 + 1e-9) &&
                        stats.max_acc_mps2 <= config_.max_acc_mps2 * (1.0 + 1e-9) &&
                        stats.time_ratio <= config_.max_time_ratio;

  // Collision check on the curve: time steps short enough that consecutive samples are at most
  // `step` apart along the curve (speed <= max_vel_mps bound).
  const double step = config_.check_step_m > 0.0 ? config_.check_step_m : 0.5 * map.geometry().resolution();
  const double duration = spline.duration();
  const double vmax = stats.max_vel_mps;
  const double wanted = vmax > 0.0 ? std::ceil(duration * vmax / step) : 1.0;
  if (!(wanted <= kMaxCheckIntervals)) {
    // Longer than 500 km at the default step: not a local trajectory, and not checkable here.
    result->status = OptimizationStatus::kInvalidInput;
    result->message = "curve too long to check";
    stats.check_ms = msSince(t0);
    return;
  }
  const int intervals = std::max(1, int(wanted));
  stats.min_clearance_m = std::numeric_limits<double>::infinity();
  bool out_of_map = false, collision = false, out_of_band = false;
  auto bandExcess = [&](double z) { return heightBandExcess(z, config_.min_z_m, config_.max_z_m); };
  const double band_allowed =
      std::max(bandExcess(spline.evaluate(0.0).z()), bandExcess(spline.evaluate(duration).z())) + 0.05;
  // A curve that starts inside the clearance (the map grew beside the trajectory being flown) may
  // stay inside it only while it moves out: until it first reaches the clearance, no sample closer
  // than the start by more than kStartSlackM.
  const DistanceQuery at_start = map.query(spline.evaluate(0.0));
  bool leaving = at_start.status != QueryStatus::kOutOfMap && at_start.status != QueryStatus::kInvalidInput &&
                 at_start.distance < config_.clearance_m;
  const double leaving_floor = at_start.distance - kStartSlackM;
  for (int k = 0; k <= intervals; ++k) {
    const double t_k = duration * k / intervals;
    const Eigen::Vector3d p = spline.evaluate(t_k);
    if (bandExcess(p.z()) > band_allowed) out_of_band = true;
    const DistanceQuery q = map.query(p);
    if (q.status == QueryStatus::kOutOfMap || q.status == QueryStatus::kInvalidInput) {
      out_of_map = true;
      continue;
    }
    if (q.status == QueryStatus::kUnknown && !config_.unknown_is_free) collision = true;
    if (q.distance < stats.min_clearance_m) {
      stats.min_clearance_m = q.distance;
      stats.min_clearance_t_s = t_k;
    }
    if (leaving && q.distance >= config_.clearance_m) leaving = false;
    if (q.distance < (leaving ? leaving_floor : config_.clearance_m)) collision = true;
  }
  stats.check_samples = intervals + 1;

  if (out_of_map || out_of_band) {
    result->status = OptimizationStatus::kOutOfMap;
    result->message = out_of_map ? "curve leaves the map" : "curve leaves the height band";
  } else if (collision) {
    result->status = OptimizationStatus::kInCollision;
    result->message = "curve closer than the clearance to an obstacle";
  } else if (!feasible) {
    result->status = OptimizationStatus::kInfeasible;
    result->message = config_.reallocate_time ? "time reallocation above max_time_ratio" : "limits exceeded";
  }

  const Eigen::MatrixX3d& q = spline.controlPoints();
  const double dt = spline.knotSpan();
  result->cost.smoothness = smoothnessCost(q, first, last, 0.0, nullptr);
  result->cost.collision =
      collisionCost(q, first, last, map, config_.d0_m, 0.0, nullptr, config_.min_z_m, config_.max_z_m, config_.face_offset_m);
  result->cost.feasibility = velocityCost(q, dt, config_.max_vel_mps, 0.0, nullptr) +
                             accelerationCost(q, dt, config_.max_acc_mps2, 0.0, nullptr);
  result->cost.jerk_integral_m2ps5 = spline.jerkIntegral();
  result->cost.duration_s = duration;
  stats.check_ms = msSince(t0);
}

OptimizationResult PathGuidedOptimizer::check(const UniformBspline& spline, const EsdfMap& map) const {
  const Clock::time_point t0 = Clock::now();
  OptimizationResult result;
  if (!validateInput(spline, &result)) return result;
  finish(map, &result);
  result.stats.total_ms = msSince(t0);
  return result;
}

OptimizationResult PathGuidedOptimizer::optimize(const UniformBspline& initial, const Path& guide,
                                                 const EsdfMap& map) const {
  const Clock::time_point t0 = Clock::now();
  const OptimizationResult warmup = guidePhase(initial, guide);
  if (warmup.status != OptimizationStatus::kSuccess) return warmup;
  OptimizationResult result = refinePhase(warmup.spline, map);
  UniformBspline refined = result.spline;  // before finish() reallocates its time
  if (result.status == OptimizationStatus::kSuccess) finish(map, &result);
  // The stretched retry's timing: the refined curve as fast as the refine's limits allow, never
  // faster than the segment's timing (the guide phase's knot span dt0); the stretch counts in
  // stats.time_ratio. The start state (the initial spline's, at dt0) is kept: a cubic's first
  // control points are set anew for each knot span. Re-timed, the refined curve's start is set
  // anew and the curve checked again; when that fails, it keeps the knot span it was refined at.
  const double margin_vel = config_.feasibility_margin * config_.max_vel_mps,
               margin_acc = config_.feasibility_margin * config_.max_acc_mps2;
  const double dt0 = warmup.spline.knotSpan();
  const UniformBspline initial_vel = initial.derivative();
  const Eigen::Vector3d start_p = initial.evaluate(0.0), start_v = initial_vel.evaluate(0.0),
                        start_a = initial_vel.derivative().evaluate(0.0);
  auto finishStretched = [&](OptimizationResult* r) {
    const OptimizationResult refined_at = *r;  // before the re-timing
    double check_ms = r->stats.check_ms;      // finish() sets its own
    auto finishAt = [&](double stretch) {
      finish(map, r);
      r->stats.time_ratio *= stretch;
      if (r->status == OptimizationStatus::kSuccess && r->stats.time_ratio > config_.max_time_ratio) {
        r->status = OptimizationStatus::kInfeasible;
        r->message = "time reallocation above max_time_ratio";
      }
    };
    UniformBspline& q = r->spline;
    const double need =
        std::max(q.maxVelocityPastStart() / margin_vel, std::sqrt(q.maxAccelerationPastStart() / margin_acc));
    if (std::isfinite(need) && need > 0.0) q.setKnotSpan(std::max(dt0, q.knotSpan() * need));
    const bool retimed = q.knotSpan() != refined_at.spline.knotSpan();
    if (retimed) setCubicStart(start_p, start_v, start_a, &q);
    finishAt(q.knotSpan() / dt0);
    if (retimed && r->status != OptimizationStatus::kSuccess) {  // as refined
      check_ms += r->stats.check_ms;
      *r = refined_at;
      finishAt(r->spline.knotSpan() / dt0);
    }
    r->stats.check_ms += check_ms;
  };
  auto addTimes = [](const OptimizationStats& from, OptimizationStats* to) {
    to->phase2_ms += from.phase2_ms;
    to->check_ms += from.check_ms;
    to->iterations += from.iterations;
    to->runs += from.runs;
  };
  if (result.status == OptimizationStatus::kInCollision && config_.stretched_retry) {
    // The guide phase's spline timed for the refine's limits (see Config::stretched_retry).
    UniformBspline stretched = warmup.spline;
    if (stretched.reallocateTime(margin_vel, margin_acc, true) > 1.0) {
      setCubicStart(start_p, start_v, start_a, &stretched);
      OptimizationResult again = refinePhase(stretched, map);
      addTimes(result.stats, &again.stats);
      if (again.status == OptimizationStatus::kSuccess) finishStretched(&again);
      if (again.status == OptimizationStatus::kSuccess) {
        result = std::move(again);
      } else {  // the collision retries go on from the first refine; the time spent counts
        result.stats.phase2_ms = again.stats.phase2_ms;
        result.stats.check_ms = again.stats.check_ms;
        result.stats.iterations = again.stats.iterations;
        result.stats.runs = again.stats.runs;
      }
    }
  }
  Config stronger = config_;
  for (int retry = 0; retry < config_.collision_retries && result.status == OptimizationStatus::kInCollision; ++retry) {
    stronger.l2c *= config_.collision_retry_factor;
    stronger.d0_m += config_.collision_retry_d0_step_m;
    OptimizationResult again = PathGuidedOptimizer(stronger).refinePhase(refined, map);
    addTimes(result.stats, &again.stats);
    if (again.status != OptimizationStatus::kSuccess) {  // NLopt failed: keep the checked result; its time counts
      result.stats.phase2_ms = again.stats.phase2_ms;
      result.stats.iterations = again.stats.iterations;
      result.stats.runs = again.stats.runs;
      break;
    }
    refined = again.spline;
    const double check_ms = again.stats.check_ms;
    finish(map, &again);  // the check of this optimiser's config (clearance, limits), not the stronger one's
    again.stats.check_ms += check_ms;
    // Costs as this optimiser weighs them, so candidates compare alike.
    result = std::move(again);
  }
  if (result.status == OptimizationStatus::kInCollision && config_.guide_phase_fallback) {
    // The guide phase's spline, timed as the stretched retry times a refined one: it follows the
    // guide, which keeps the search's clearance, and when it passes the check it is a plan.
    OptimizationResult kept = warmup;
    kept.stats.check_ms = 0.0;
    finishStretched(&kept);
    if (kept.status == OptimizationStatus::kSuccess) {
      addTimes(result.stats, &kept.stats);
      kept.stats.guide_phase_kept = true;
      result = std::move(kept);
    } else {
      result.stats.check_ms += kept.stats.check_ms;
    }
  }
  result.cost.guide = warmup.cost.guide;
  result.stats.phase1_ms = warmup.stats.phase1_ms;
  result.stats.total_ms = msSince(t0);
  return result;
}

OptimizationResult PathGuidedOptimizer::gto(const UniformBspline& initial, const EsdfMap& map) const {
  const Clock::time_point t0 = Clock::now();
  OptimizationResult result = refinePhase(initial, map);
  if (result.status == OptimizationStatus::kSuccess) finish(map, &result);
  result.stats.total_ms = msSince(t0);
  return result;
}

OptimizationResult PathGuidedOptimizer::gtoWithRestarts(const UniformBspline& initial, const EsdfMap& map, int runs,
                                                        uint32_t seed) const {
  assert(runs >= 1);
  const Clock::time_point t0 = Clock::now();
  OptimizationResult best = gto(initial, map);
  if (best.status == OptimizationStatus::kInvalidInput) return best;
  double phase2_ms = best.stats.phase2_ms, check_ms = best.stats.check_ms;
  int iterations = best.stats.iterations;

  const int n = initial.numControlPoints(), p = initial.degree();
  const int first = p, last = n - 1 - p;
  const Eigen::Vector3d chord = initial.controlPoints().row(n - 1) - initial.controlPoints().row(0);
  // Two unit vectors perpendicular to the start-goal chord (any pair when start == goal).
  const Eigen::Vector3d axis = chord.norm() > 1e-9 ? Eigen::Vector3d(chord.normalized()) : Eigen::Vector3d::UnitX();
  const Eigen::Vector3d helper = std::abs(axis.z()) < 0.9 ? Eigen::Vector3d::UnitZ() : Eigen::Vector3d::UnitX();
  const Eigen::Vector3d e1 = axis.cross(helper).normalized(), e2 = axis.cross(e1);
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> uniform(0.0, 1.0);
  std::normal_distribution<double> noise(0.0, 1.0);
  // Successes first, then checked failures (collision, out of map, infeasible), then NLopt failures;
  // within a rank the lower phase-2 cost.
  auto rank = [](const OptimizationResult& r) {
    return r.status == OptimizationStatus::kSuccess ? 0 : (r.status == OptimizationStatus::kOptimizationFailed ? 2 : 1);
  };
  auto better = [&](const OptimizationResult& a, const OptimizationResult& b) {
    if (rank(a) != rank(b)) return rank(a) < rank(b);
    return a.cost.phase2 < b.cost.phase2;
  };
  for (int r = 1; r < runs; ++r) {
    const double angle = 2.0 * M_PI * uniform(rng), amplitude = config_.restart_offset_m * uniform(rng);
    const Eigen::Vector3d offset = amplitude * (std::cos(angle) * e1 + std::sin(angle) * e2);
    UniformBspline start = initial;
    for (int i = first; i <= last; ++i) {
      const double bump = std::sin(M_PI * (i - first + 1) / (last - first + 2));
      for (int c = 0; c < 3; ++c)
        start.controlPoints()(i, c) += bump * offset(c) + config_.restart_noise_m * noise(rng);
    }
    OptimizationResult candidate = gto(start, map);
    phase2_ms += candidate.stats.phase2_ms;
    check_ms += candidate.stats.check_ms;
    iterations += candidate.stats.iterations;
    if (better(candidate, best)) {
      best = std::move(candidate);
      best.stats.best_run = r;
    }
  }
  best.stats.runs = runs;
  best.stats.phase2_ms = phase2_ms;
  best.stats.check_ms = check_ms;
  best.stats.iterations = iterations;
  best.stats.total_ms = msSince(t0);
  return best;
}

}  // namespace topo_planner
