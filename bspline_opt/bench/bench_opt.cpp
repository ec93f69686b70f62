// make bench-opt: path-guided optimisation (PGO, paper Sect. III) against plain gradient-based
// optimisation (GTO) and GTO with random restarts, and three NLopt algorithms, on the same tasks.
//   Maps: 20 x 20 x 3 m at 0.1 m, medium density forests (plan_env/map_generator.h preset).
//   Tasks: start and goal 0.6 m from obstacles, 5-9 m apart; the reference segment is a straight
//   rest-to-rest cubic B-spline (control points ~0.3 m apart, 20-40 of them) timed to the limits,
//   and it is in collision: it enters an obstacle (ESDF distance < 0 somewhere). Guide path: grid A* with 0.4 m
//   clearance, then PathShortener (Alg. 2); tasks without one are counted and skipped.
//   Success: the final check passes (clearance along the whole curve, limits on the derivative
//   control points). Limits 3 m/s, 2.5 m/s^2, clearance 0.25 m. Budgets by evaluation count.
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <map>
#include <random>
#include <string>

#include "topo_planner/plan_env/synthetic_scene.h"
#include "topo_planner/plan_env/timing.h"
#include "topo_planner/bspline_opt/path_guided_optimizer.h"
#include "topo_planner/path_searching/grid_astar.h"
#include "topo_planner/path_searching/path_shortener.h"
#include "topo_planner/plan_env/map_generator.h"

using namespace topo_planner;

namespace {

constexpr double kMaxVel = 3.0, kMaxAcc = 2.5, kClearance = 0.25, kGuideClearance = 0.4;

UniformBspline reference(const Eigen::Vector3d& start, const Eigen::Vector3d& goal) {
  const int n = std::clamp(int(std::lround((goal - start).norm() / 0.3)) + 5, 20, 40);
  UniformBspline s = UniformBspline::straightLine(start, goal, n, 3, 0.01);
  s.reallocateTime(kMaxVel, kMaxAcc);
  return s;
}

// True when the curve enters an obstacle (ESDF distance below zero at some sample 1 cm apart or less).
bool crossesObstacle(const UniformBspline& s, const EsdfMap& map) {
  const int samples = std::max(2, int(std::ceil(s.arcLength() / 0.01)));
  for (int k = 0; k <= samples; ++k) {
    const DistanceQuery q = map.query(s.evaluate(s.duration() * k / samples));
    if (q.status == QueryStatus::kOk && q.distance < 0.0) return true;
  }
  return false;
}

struct Method {
  enum Kind { kPgo, kGto, kGtoRestarts };
  Method(std::string n, Kind k, std::string a) : name(std::move(n)), kind(k), algorithm(std::move(a)) {}
  std::string name;
  Kind kind;
  std::string algorithm;
  // Per task.
  std::vector<double> total_ms, phase1_ms, phase2_ms, evaluations, jerk, duration, ratio;
  std::map<OptimizationStatus, int> statuses;
  int tasks = 0;
  double successRate() const {
    const auto it = statuses.find(OptimizationStatus::kSuccess);
    return tasks ? double(it == statuses.end() ? 0 : it->second) / tasks : 0.0;
  }
  double rate(OptimizationStatus s) const {
    const auto it = statuses.find(s);
    return tasks ? double(it == statuses.end() ? 0 : it->second) / tasks : 0.0;
  }
};

}  // namespace

int main(int argc, char** argv) {
  int maps = 10, tasks_per_map = 50, restarts = 8;
  PathGuidedOptimizer::Config base;
  base.max_vel_mps = kMaxVel;
  base.max_acc_mps2 = kMaxAcc;
  base.clearance_m = kClearance;
  // --set name=value overrides a numeric Config field, for tuning runs.
  std::map<std::string, double*> fields = {
      {"l1s", &base.l1s},           {"l1g", &base.l1g},           {"l2s", &base.l2s},
      {"l2c", &base.l2c},           {"l2d", &base.l2d},           {"d0_m", &base.d0_m},
      {"xtol_rel", &base.xtol_rel}, {"ftol_rel", &base.ftol_rel}, {"max_time_s", &base.max_time_s}};
  for (int i = 1; i + 1 < argc; i += 2) {
    if (!std::strcmp(argv[i], "--maps")) maps = std::max(1, std::atoi(argv[i + 1]));
    if (!std::strcmp(argv[i], "--tasks-per-map")) tasks_per_map = std::max(1, std::atoi(argv[i + 1]));
    if (!std::strcmp(argv[i], "--restarts")) restarts = std::max(1, std::atoi(argv[i + 1]));
    if (!std::strcmp(argv[i], "--max-iterations")) base.max_iterations = std::max(1, std::atoi(argv[i + 1]));
    if (!std::strcmp(argv[i], "--vector-storage")) base.vector_storage = std::max(0, std::atoi(argv[i + 1]));
    if (!std::strcmp(argv[i], "--set")) {
      const std::string kv = argv[i + 1];
      const size_t eq = kv.find('=');
      const auto it = fields.find(kv.substr(0, eq));
      if (eq == std::string::npos || it == fields.end()) {
        std::fprintf(stderr, "unknown --set %s\n", kv.c_str());
        return 1;
      }
      *it->second = std::atof(kv.c_str() + eq + 1);
    }
  }
  std::string why;
  if (!base.validate(&why)) {
    std::fprintf(stderr, "invalid config: %s\n", why.c_str());
    return 1;
  }

  std::vector<Method> methods = {
      {"PGO (ours)", Method::kPgo, "LD_LBFGS"},
      {"PGO (ours)", Method::kPgo, "LD_MMA"},
      {"PGO (ours)", Method::kPgo, "LD_TNEWTON_PRECOND_RESTART"},
      {"GTO", Method::kGto, "LD_LBFGS"},
      {"GTO", Method::kGto, "LD_MMA"},
      {"GTO", Method::kGto, "LD_TNEWTON_PRECOND_RESTART"},
      {"GTO + " + std::to_string(restarts) + " restarts", Method::kGtoRestarts, "LD_LBFGS"},
  };

  std::printf("# bench_opt: %d maps x %d tasks, 20 x 20 x 3 m at 0.1 m, medium density (%.2f pillars + %.2f boxes per m^2)\n",
              maps, tasks_per_map, ForestConfig::preset(ObstacleDensity::kMedium).pillars_per_m2,
              ForestConfig::preset(ObstacleDensity::kMedium).floating_per_m2);
  std::printf("# limits %.1f m/s, %.1f m/s^2; success = clearance %.2f m along the curve (checked every %.2f m) and "
              "within limits; d0 %.2f m; budget %d evaluations per phase-2 run, no time limit\n",
              kMaxVel, kMaxAcc, kClearance, 0.05, base.d0_m, base.max_iterations);
  std::printf("# weights l1s %.3g l1g %.3g l2s %.3g l2c %.3g l2d %.3g; xtol_rel %.3g ftol_rel %.3g vector storage %d; "
              "guide: grid A* (clearance %.1f m) + PathShortener; reference enters an obstacle\n",
              base.l1s, base.l1g, base.l2s, base.l2c, base.l2d, base.xtol_rel, base.ftol_rel, base.vector_storage,
              kGuideClearance);

  int tasks = 0, no_guide = 0, control_points_min = 1000, control_points_max = 0;
  for (int m = 0; m < maps; ++m) {
    SyntheticScene scene({20.0, 20.0, 3.0});
    const uint32_t map_seed = 4000u + uint32_t(m);
    scene.forest(ObstacleDensity::kMedium, map_seed);
    const EsdfMap& map = scene.finish();
    const VisibilityChecker roomy(map, 0.6, true), guide_checker(map, kGuideClearance, true);
    const PathShortener shortener(guide_checker);
    GridAStar::Config ac;
    ac.clearance_m = kGuideClearance;
    GridAStar astar(ac);
    std::mt19937 rng(map_seed * 7919u + 13u);
    std::uniform_real_distribution<double> uxy(1.5, 18.5), uz(1.0, 2.0);
    int made = 0;
    while (made < tasks_per_map) {
      const Eigen::Vector3d start(uxy(rng), uxy(rng), uz(rng)), goal(uxy(rng), uxy(rng), uz(rng));
      const double d = (goal - start).norm();
      if (d < 5.0 || d > 9.0 || !roomy.isFree(start) || !roomy.isFree(goal)) continue;
      const UniformBspline initial = reference(start, goal);
      if (!crossesObstacle(initial, map)) continue;
      const GridAStar::Result a = astar.search(map, start, goal);
      ++made;
      if (a.status != SearchStatus::kSuccess) {
        ++no_guide;
        continue;
      }
      ++tasks;
      control_points_min = std::min(control_points_min, initial.numControlPoints());
      control_points_max = std::max(control_points_max, initial.numControlPoints());
      const Path guide = shortener.shorten(a.path);
      for (Method& method : methods) {
        PathGuidedOptimizer::Config c = base;
        c.algorithm = method.algorithm;
        const PathGuidedOptimizer optimizer(c);
        OptimizationResult r;
        switch (method.kind) {
          case Method::kPgo: r = optimizer.optimize(initial, guide, map); break;
          case Method::kGto: r = optimizer.gto(initial, map); break;
          case Method::kGtoRestarts: r = optimizer.gtoWithRestarts(initial, map, restarts, uint32_t(tasks)); break;
        }
        ++method.tasks;
        ++method.statuses[r.status];
        method.total_ms.push_back(r.stats.total_ms);
        method.phase1_ms.push_back(r.stats.phase1_ms);
        method.phase2_ms.push_back(r.stats.phase2_ms);
        method.evaluations.push_back(r.stats.iterations);
        if (r.status == OptimizationStatus::kSuccess) {
          method.jerk.push_back(r.cost.jerk_integral_m2ps5);
          method.duration.push_back(r.cost.duration_s);
          method.ratio.push_back(r.stats.time_ratio);
        }
      }
    }
    std::fprintf(stderr, "\rmap %2d/%d", m + 1, maps);
  }
  std::fprintf(stderr, "\n");
  std::printf("# %d tasks with a guide path (%d more without one, skipped); %d-%d control points\n\n", tasks, no_guide,
              control_points_min, control_points_max);

  std::printf("| method | NLopt | tasks | success | in collision | infeasible | failed | total ms median | p95 | "
              "phase 1 ms median | p95 | phase 2 ms median | p95 | evaluations median | jerk integral median "
              "[m^2/s^5] | duration median [s] | time ratio median |\n");
  std::printf("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|\n");
  for (const Method& m : methods) {
    const double failed = m.rate(OptimizationStatus::kOptimizationFailed) + m.rate(OptimizationStatus::kInvalidInput);
    const double collision = m.rate(OptimizationStatus::kInCollision) + m.rate(OptimizationStatus::kOutOfMap);
    std::printf("| %s | %s | %d | %.1f%% | %.1f%% | %.1f%% | %.1f%% | %.3f | %.3f | ", m.name.c_str(),
                m.algorithm.c_str(), m.tasks, 100.0 * m.successRate(), 100.0 * collision,
                100.0 * m.rate(OptimizationStatus::kInfeasible), 100.0 * failed, percentile(m.total_ms, 0.5),
                percentile(m.total_ms, 0.95));
    if (m.kind == Method::kPgo)
      std::printf("%.4f | %.4f | ", percentile(m.phase1_ms, 0.5), percentile(m.phase1_ms, 0.95));
    else
      std::printf("- | - | ");
    std::printf("%.3f | %.3f | %.0f | %.2f | %.2f | %.3f |\n", percentile(m.phase2_ms, 0.5),
                percentile(m.phase2_ms, 0.95), percentile(m.evaluations, 0.5), percentile(m.jerk, 0.5),
                percentile(m.duration, 0.5), percentile(m.ratio, 0.5));
  }
  const Method& pgo = methods[0];
  const Method& gto = methods[3];
  const Method& gto_restarts = methods[6];
  std::printf("\nRESULT pgo_ms_median=%.4g pgo_ms_p95=%.4g phase1_ms_median=%.4g phase1_ms_p95=%.4g "
              "phase2_ms_median=%.4g pgo_success=%.4g gto_success=%.4g gto_restart_success=%.4g "
              "pgo_mma_success=%.4g pgo_tnewton_success=%.4g gto_ms_median=%.4g gto_restart_ms_median=%.4g "
              "pgo_jerk_median=%.4g gto_jerk_median=%.4g tasks=%d no_guide=%d\n",
              percentile(pgo.total_ms, 0.5), percentile(pgo.total_ms, 0.95), percentile(pgo.phase1_ms, 0.5),
              percentile(pgo.phase1_ms, 0.95), percentile(pgo.phase2_ms, 0.5), pgo.successRate(), gto.successRate(),
              gto_restarts.successRate(), methods[1].successRate(), methods[2].successRate(),
              percentile(gto.total_ms, 0.5), percentile(gto_restarts.total_ms, 0.5), percentile(pgo.jerk, 0.5),
              percentile(gto.jerk, 0.5), tasks, no_guide);
  return 0;
}
