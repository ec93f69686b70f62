#include "replan_suite.h"

#include <algorithm>
#include <cmath>
#include <chrono>
#include <cstdio>
#include <fstream>
#include <iomanip>
#include <random>
#include <set>
#include <sstream>

#include "topo_planner/path_searching/path_shortener.h"
#include "topo_planner/plan_env/map_generator.h"
#include "topo_planner/plan_env/synthetic_scene.h"
#include "topo_planner/plan_env/timing.h"

namespace topo_planner {
namespace bench {

namespace {

double msSince(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
}

}  // namespace

const char* toString(Method m) {
  switch (m) {
    case Method::kProposed: return "proposed";
    case Method::kGto: return "gto";
    case Method::kGtoRestart: return "gto_restart";
    case Method::kAstarPgo: return "astar_pgo";
  }
  return "?";
}

bool parseMethod(const std::string& s, Method* m) {
  for (Method x : allMethods())
    if (s == toString(x)) {
      *m = x;
      return true;
    }
  return false;
}

const std::vector<Method>& allMethods() {
  static const std::vector<Method> all{Method::kProposed, Method::kGto, Method::kGtoRestart, Method::kAstarPgo};
  return all;
}

TopoReplanner::Config benchmarkReplannerConfig(const SuiteConfig& suite) {
  TopoReplanner::Config c;
  c.horizon_m = 1e3;  // the whole task is one local problem
  c.optimizer.max_vel_mps = suite.max_vel_mps;
  c.optimizer.max_acc_mps2 = suite.max_acc_mps2;
  c.num_threads = 2;
  if (suite.collision_retries >= 0) c.optimizer.collision_retries = suite.collision_retries;
  if (suite.deterministic) {
    c.search.roadmap.max_time_s = 0.0;
    c.optimizer.max_time_s = 0.0;
  }
  return c;
}

TaskOutcome runMethod(Method method, TopoReplanner& replanner, const PathGuidedOptimizer& optimizer, GridAStar& astar,
                      const EsdfMap& map, const PolynomialTrajectory& reference, int restarts, uint32_t seed) {
  TaskOutcome out;
  out.method = method;
  ReplanRequest req;
  req.start = reference.state(0.0);
  req.reference = &reference;
  if (method == Method::kProposed) {
    const ReplanResult r = replanner.replan(map, req);
    out.ok = r.status == ReplanStatus::kSuccess;
    out.status = r.message.empty() ? toString(r.status) : r.message;
    out.search_ms = r.stats.search_ms;
    out.opt_ms = r.stats.optimize_ms;
    out.total_ms = r.stats.total_ms;
    out.paths = r.stats.paths;
    PhaseTimes& ph = out.phases;
    ph.local_problem_ms = r.stats.check_ms;
    ph.roadmap_ms = r.stats.search.roadmap_ms;
    ph.extraction_ms = r.stats.search.extraction_ms;
    ph.shortening_ms = r.stats.search.shortening_ms;
    ph.pruning_ms = r.stats.search.pruning_ms;
    if (r.stats.used_astar) ph.astar_ms = std::max(0.0, r.stats.search_ms - r.stats.search.total_ms);
    ph.optimize_wall_ms = r.stats.optimize_ms;
    for (const ReplanCandidate& c : r.candidates) {
      ph.guide_ms += c.result.stats.phase1_ms;
      ph.refine_ms += c.result.stats.phase2_ms;
      ph.final_check_ms += c.result.stats.check_ms;
      ph.evaluations += c.result.stats.iterations;
      ph.refine_runs += c.result.stats.runs;
    }
    if (out.ok) {
      out.trajectory = r.trajectory;
      out.min_clearance_m = r.chosen >= 0 ? r.candidates[size_t(r.chosen)].result.stats.min_clearance_m
                                          : optimizer.check(r.trajectory, map).stats.min_clearance_m;
    }
  } else {
    const LocalProblem lp = replanner.localProblem(map, req);
    if (lp.status != ReplanStatus::kSuccess) {
      out.status = lp.message;
    } else {
      OptimizationResult o;
      if (method == Method::kGto) {
        o = optimizer.gto(lp.initial, map);
      } else if (method == Method::kGtoRestart) {
        o = optimizer.gtoWithRestarts(lp.initial, map, restarts, seed);
      } else {
        const auto t0 = std::chrono::steady_clock::now();
        const GridAStar::Result a = astar.search(map, lp.search_start, lp.goal);
        Path guide;
        if (a.status == SearchStatus::kSuccess) {
          const VisibilityChecker checker(map, replanner.config().astar.clearance_m, true);
          guide = PathShortener(checker).shorten(a.path);
          if (lp.search_start != lp.start) guide.insert(guide.begin(), lp.start);  // as the replanner does
        }
        out.search_ms = msSince(t0);
        out.paths = guide.empty() ? 0 : 1;
        if (guide.empty()) {
          out.status = toString(a.status);
          out.total_ms = out.search_ms;
          return out;
        }
        o = optimizer.optimize(lp.initial, guide, map);
      }
      out.ok = o.status == OptimizationStatus::kSuccess;
      out.status = toString(o.status);
      out.opt_ms = o.stats.total_ms;
      out.min_clearance_m = o.stats.min_clearance_m;
      if (out.ok) out.trajectory = o.spline;
    }
  }
  // The proposed method's time is its whole replan() call (reference check and local problem
  // included); the baselines' is their search and optimisation.
  out.total_ms = method == Method::kProposed ? out.total_ms : out.search_ms + out.opt_ms;
  if (out.ok) {
    out.jerk_integral = out.trajectory.jerkIntegral();
    out.duration_s = out.trajectory.duration();
  }
  return out;
}

const std::vector<std::pair<const char*, double PhaseTimes::*>>& PhaseTimes::fields() {
  static const std::vector<std::pair<const char*, double PhaseTimes::*>> f{
      {"local problem ms", &PhaseTimes::local_problem_ms},
      {"roadmap ms (sampling + visibility + UVD)", &PhaseTimes::roadmap_ms},
      {"path extraction ms", &PhaseTimes::extraction_ms},
      {"shortening ms", &PhaseTimes::shortening_ms},
      {"pruning ms", &PhaseTimes::pruning_ms},
      {"A* last resort ms", &PhaseTimes::astar_ms},
      {"guide phase ms (sum over candidates)", &PhaseTimes::guide_ms},
      {"refine phase ms (sum)", &PhaseTimes::refine_ms},
      {"final check ms (sum)", &PhaseTimes::final_check_ms},
      {"optimisation wall ms", &PhaseTimes::optimize_wall_ms},
      {"refine evaluations (sum)", &PhaseTimes::evaluations},
      {"refine runs (sum)", &PhaseTimes::refine_runs},
  };
  return f;
}

std::string phaseTable(const std::vector<TaskOutcome>& outcomes) {
  std::ostringstream t;
  t << "| phase (per call) | median | p95 | mean |\n|---|---|---|---|\n" << std::fixed << std::setprecision(3);
  for (const auto& [name, field] : PhaseTimes::fields()) {
    std::vector<double> v;
    for (const TaskOutcome& o : outcomes)
      if (o.method == Method::kProposed) v.push_back(o.phases.*field);
    double sum = 0.0;
    for (double x : v) sum += x;
    t << "| " << name << " | " << percentile(v, 0.5) << " | " << percentile(v, 0.95) << " | "
      << (v.empty() ? 0.0 : sum / double(v.size())) << " |\n";
  }
  return t.str();
}

MethodRunner::MethodRunner(const SuiteConfig& suite)
    : config(benchmarkReplannerConfig(suite)),
      replanner(TopoReplanner::create(config, nullptr)),
      optimizer(config.optimizer),
      astar(config.astar),
      restarts(suite.gto_restarts) {
  reference.max_vel_mps = suite.max_vel_mps;
  reference.max_acc_mps2 = suite.max_acc_mps2;
}

TaskOutcome MethodRunner::run(Method method, const EsdfMap& map, const PolynomialTrajectory& ref, uint32_t seed) {
  return runMethod(method, *replanner, optimizer, astar, map, ref, restarts, seed);
}

std::vector<TaskOutcome> runSuite(const SuiteConfig& config, const std::vector<ObstacleDensity>& densities) {
  std::vector<TaskOutcome> outcomes;
  MethodRunner runner(config);
  const int total = int(densities.size()) * config.maps_per_density * config.tasks_per_map;
  int done = 0;
  for (ObstacleDensity density : densities) {
    int trial = 0;
    for (int m = 0; m < config.maps_per_density; ++m) {
      SyntheticScene scene(config.map_size_m);
      const uint32_t map_seed = 1000u * uint32_t(density) + uint32_t(m);
      ForestConfig forest = ForestConfig::preset(density);
      if (!forest.applyStyle(config.style)) {
        std::fprintf(stderr, "replan suite: unknown map style '%s'\n", config.style.c_str());
        return {};
      }
      generateForest(forest, map_seed, scene.occupancy.get());
      const EsdfMap& map = scene.finish();
      const VisibilityChecker line(map, runner.config.search.clearance_m, true);
      std::mt19937 rng(map_seed * 7919u + 13u);
      std::uniform_real_distribution<double> ux(1.5, config.map_size_m.x() - 1.5), uy(1.5, config.map_size_m.y() - 1.5),
          uz(1.0, std::min(2.0, config.map_size_m.z() - 1.0));
      auto roomy = [&](const Eigen::Vector3d& p) {
        const DistanceQuery q = map.query(p);
        return q.status == QueryStatus::kOk && q.distance >= config.task_clearance_m;
      };
      for (int k = 0; k < config.tasks_per_map;) {
        const Eigen::Vector3d s(ux(rng), uy(rng), uz(rng)), g(ux(rng), uy(rng), uz(rng));
        const double d = (g - s).norm();
        if (d < config.min_task_length_m || d > config.max_task_length_m || !roomy(s) || !roomy(g) || line.lineVisible(s, g))
          continue;
        PolynomialTrajectory reference;
        if (referenceTrajectory({s, g}, FlatState::atRest(s), FlatState::atRest(g), runner.reference, &reference) != TrajectoryStatus::kSuccess) continue;
        ++k;
        for (Method method : allMethods()) {
          TaskOutcome o = runner.run(method, map, reference, uint32_t(trial) * 31u + 7u);
          o.density = toString(density);
          o.trial = trial;
          o.trajectory = UniformBspline();  // not kept: the suite only reports
          outcomes.push_back(std::move(o));
        }
        ++trial;
        ++done;
        const int width = 40, filled = width * done / std::max(1, total);
        std::fprintf(stderr, "\r[%s%s] %d/%d tasks (%s)   ", std::string(size_t(filled), '#').c_str(),
                     std::string(size_t(width - filled), '.').c_str(), done, total, toString(density));
      }
    }
  }
  std::fprintf(stderr, "\n");
  return outcomes;
}

std::map<std::string, std::map<Method, MethodSummary>> summarize(const std::vector<TaskOutcome>& outcomes) {
  std::map<std::string, std::map<Method, MethodSummary>> out;
  // Tasks every method solved, per density.
  std::map<std::string, std::map<int, int>> solved_by;
  for (const TaskOutcome& o : outcomes)
    if (o.ok) ++solved_by[o.density][o.trial];
  const int methods = int(allMethods().size());
  std::map<std::string, std::map<Method, std::vector<double>>> times, search, opt, jerk_all, jerk_common;
  for (const TaskOutcome& o : outcomes) {
    MethodSummary& s = out[o.density][o.method];
    ++s.tasks;
    s.solved += o.ok;
    times[o.density][o.method].push_back(o.total_ms);
    search[o.density][o.method].push_back(o.search_ms);
    opt[o.density][o.method].push_back(o.opt_ms);
    if (o.ok) jerk_all[o.density][o.method].push_back(o.jerk_integral);
    if (o.ok && solved_by[o.density][o.trial] == methods) jerk_common[o.density][o.method].push_back(o.jerk_integral);
  }
  auto mean = [](const std::vector<double>& v) {
    double s = 0.0;
    for (double x : v) s += x;
    return v.empty() ? 0.0 : s / double(v.size());
  };
  for (auto& [density, per_method] : out)
    for (auto& [method, s] : per_method) {
      s.time_median_ms = percentile(times[density][method], 0.5);
      s.time_p95_ms = percentile(times[density][method], 0.95);
      s.search_median_ms = percentile(search[density][method], 0.5);
      s.opt_median_ms = percentile(opt[density][method], 0.5);
      s.jerk_all_mean = mean(jerk_all[density][method]);
      s.jerk_common_mean = mean(jerk_common[density][method]);
      s.common = int(jerk_common[density][method].size());
    }
  return out;
}

std::string markdownTable(const std::map<std::string, std::map<Method, MethodSummary>>& summary) {
  std::ostringstream t;
  t << "| Density | Method | Comp. time median (ms) [median search / median opt] | Comp. time p95 (ms) | Success rate (%) | "
       "Smoothness, tasks all solved (m^2/s^5) | Smoothness, own solved (m^2/s^5) |\n";
  t << "|---|---|---|---|---|---|---|\n";
  t << std::fixed;
  for (const char* density : {"low", "medium", "high"}) {
    auto it = summary.find(density);
    if (it == summary.end()) continue;
    for (Method m : allMethods()) {
      auto jt = it->second.find(m);
      if (jt == it->second.end()) continue;
      const MethodSummary& s = jt->second;
      t << "| " << density << " | " << toString(m) << " | " << std::setprecision(2) << s.time_median_ms << " ["
        << s.search_median_ms << " / " << s.opt_median_ms << "] | " << s.time_p95_ms << " | " << std::setprecision(1)
        << 100.0 * s.successRate() << " (" << s.solved << "/" << s.tasks << ") | " << std::setprecision(3)
        << s.jerk_common_mean << " (n=" << s.common << ") | " << s.jerk_all_mean << " |\n";
    }
  }
  return t.str();
}

bool writeCsv(const std::vector<TaskOutcome>& outcomes, const std::string& path) {
  std::ofstream f(path);
  if (!f) return false;
  f << "density,trial,method,ok,status,search_ms,opt_ms,total_ms,paths,jerk_integral,duration_s,min_clearance_m\n";
  f << std::setprecision(9);
  for (const TaskOutcome& o : outcomes)
    f << o.density << "," << o.trial << "," << toString(o.method) << "," << int(o.ok) << ",\"" << o.status << "\","
      << o.search_ms << "," << o.opt_ms << "," << o.total_ms << "," << o.paths << "," << o.jerk_integral << ","
      << o.duration_s << "," << o.min_clearance_m << "\n";
  return bool(f);
}

TasksCsvStats readTasksCsv(std::istream& in, std::vector<ReplanTask>* tasks, size_t max_tasks) {
  TasksCsvStats stats;
  std::string line;
  while (std::getline(in, line)) {
    if (line.empty() || line[0] == '#' || line == "\r") continue;
    ++stats.rows;
    if (tasks->size() >= max_tasks) {
      stats.too_many = true;
      break;
    }
    if (line.size() > 4096) {
      ++stats.bad_rows;
      continue;
    }
    std::replace(line.begin(), line.end(), ',', ' ');
    std::istringstream row(line);
    ReplanTask t;
    if (!(row >> t.trial >> t.map_id >> t.start.x() >> t.start.y() >> t.start.z() >> t.goal.x() >> t.goal.y() >>
          t.goal.z()) ||
        !t.start.allFinite() || !t.goal.allFinite()) {
      ++stats.bad_rows;
      continue;
    }
    tasks->push_back(t);
  }
  return stats;
}

double jerkRatio(const std::vector<TaskOutcome>& outcomes, Method a, Method b, int* common) {
  std::map<std::pair<std::string, int>, std::pair<double, double>> pairs;  // (ja, jb); NaN when unsolved
  for (const TaskOutcome& o : outcomes) {
    if (o.method != a && o.method != b) continue;
    auto& p = pairs.try_emplace({o.density, o.trial}, NAN, NAN).first->second;
    (o.method == a ? p.first : p.second) = o.ok ? o.jerk_integral : NAN;
  }
  double sa = 0.0, sb = 0.0;
  int n = 0;
  for (const auto& [key, p] : pairs)
    if (std::isfinite(p.first) && std::isfinite(p.second)) {
      sa += p.first;
      sb += p.second;
      ++n;
    }
  if (common) *common = n;
  return sb > 0.0 ? sa / sb : NAN;
}

}  // namespace bench
}  // namespace topo_planner
