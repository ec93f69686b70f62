#pragma once
// The replanning benchmark of the paper's Table I, shared by the benchmark executables and the CI
// test: seeded random forests at three densities (plan_env/map_generator.h), random replanning
// tasks whose straight reference is blocked, and four methods started from the same reference
// trajectory (a rest-to-rest minimum-snap line) and the same local problem:
//   proposed    topological guide paths + parallel PGO (TopoReplanner)
//   gto         the refine phase alone from the reference segment (like the paper's TRR baseline)
//   gto_restart GTO with random restarts, best of N (like Ewok's restarts)
//   astar_pgo   PGO guided by a single A* path (what the topological paths add)
// Success: the optimiser's final check (collision-free along the curve at its clearance, velocity
// and acceleration within the limits).

#include <cstdint>
#include <istream>
#include <map>
#include <memory>
#include <string>
#include <vector>

#include "topo_planner/plan_env/map_generator.h"
#include "topo_planner/topo_replan/topo_replanner.h"

namespace topo_planner {
namespace bench {

enum class Method { kProposed, kGto, kGtoRestart, kAstarPgo };
const char* toString(Method m);
bool parseMethod(const std::string& s, Method* m);
const std::vector<Method>& allMethods();

struct SuiteConfig {
  std::string style = "forest";  ///< map style (ForestConfig::applyStyle): forest, walls, rings, windows, boxes, mixed
  int maps_per_density = 10;
  int tasks_per_map = 50;
  Eigen::Vector3d map_size_m{20.0, 20.0, 3.0};
  double min_task_length_m = 6.0, max_task_length_m = 10.0;
  double task_clearance_m = 0.5;  ///< start and goal at least this far from obstacles [m]
  int gto_restarts = 5;
  double max_vel_mps = 3.0, max_acc_mps2 = 2.5;
  bool deterministic = true;      ///< counts only (no time limits)
  int collision_retries = -1;     ///< PGO's collision retries; -1: the optimiser's default
};

/// Where a proposed replan's time went, per call (the profile of the issue on sub-millisecond
/// replanning). The optimisation's phases are summed over its candidates (CPU time on the pool's
/// workers); optimize_wall_ms is the parallel section's wall time, thread hand-off included.
struct PhaseTimes {
  double local_problem_ms = 0.0;  ///< reference check, local problem, initial spline
  double roadmap_ms = 0.0;        ///< Alg. 1: sampling, visibility, UVD
  double extraction_ms = 0.0, shortening_ms = 0.0, pruning_ms = 0.0;
  double astar_ms = 0.0;          ///< the A* last resort, when it ran
  double guide_ms = 0.0;          ///< PGO phase 1 (closed form)
  double refine_ms = 0.0;         ///< PGO phase 2 (NLopt), every run
  double final_check_ms = 0.0;    ///< reallocation and the curve check
  double optimize_wall_ms = 0.0;
  double evaluations = 0.0;       ///< phase-2 objective evaluations, every candidate and run
  double refine_runs = 0.0;

  /// Names and pointers of the fields, in print order.
  static const std::vector<std::pair<const char*, double PhaseTimes::*>>& fields();
};

struct TaskOutcome {
  std::string density;
  int trial = 0;
  Method method = Method::kProposed;
  bool ok = false;
  std::string status;
  double search_ms = 0.0, opt_ms = 0.0, total_ms = 0.0;
  int paths = 0;
  PhaseTimes phases;  ///< the proposed method's only
  double jerk_integral = 0.0, duration_s = 0.0, min_clearance_m = 0.0;
  UniformBspline trajectory;
};

/// A Markdown table of the phases' medians and p95s over `outcomes` (the proposed method's).
std::string phaseTable(const std::vector<TaskOutcome>& outcomes);

/// The replanner configuration used by every method (optimiser, search, A*).
TopoReplanner::Config benchmarkReplannerConfig(const SuiteConfig& suite);

/// Runs one method on one task. `replanner` provides the shared local problem and the proposed
/// method; the baselines use optimizer and astar.
TaskOutcome runMethod(Method method, TopoReplanner& replanner, const PathGuidedOptimizer& optimizer, GridAStar& astar,
                      const EsdfMap& map, const PolynomialTrajectory& reference, int restarts, uint32_t seed);

/// The replanner, optimiser, A* and reference limits shared by every method of a run.
struct MethodRunner {
  explicit MethodRunner(const SuiteConfig& suite);
  TaskOutcome run(Method method, const EsdfMap& map, const PolynomialTrajectory& reference, uint32_t seed);

  TopoReplanner::Config config;
  std::unique_ptr<TopoReplanner> replanner;
  PathGuidedOptimizer optimizer;
  GridAStar astar;
  ReferenceConfig reference;
  int restarts;
};

/// Runs the suite: every method on every task of every density. Progress on stderr.
std::vector<TaskOutcome> runSuite(const SuiteConfig& config, const std::vector<ObstacleDensity>& densities);

struct MethodSummary {
  int tasks = 0, solved = 0;
  double time_median_ms = 0.0, time_p95_ms = 0.0, search_median_ms = 0.0, opt_median_ms = 0.0;
  double jerk_common_mean = 0.0;  ///< over the tasks every method solved
  double jerk_all_mean = 0.0;     ///< over the tasks this method solved
  int common = 0;
  double successRate() const { return tasks ? double(solved) / tasks : 0.0; }
};
/// summary[density][method]
std::map<std::string, std::map<Method, MethodSummary>> summarize(const std::vector<TaskOutcome>& outcomes);

/// The paper's Table I layout, as Markdown.
std::string markdownTable(const std::map<std::string, std::map<Method, MethodSummary>>& summary);
bool writeCsv(const std::vector<TaskOutcome>& outcomes, const std::string& path);
/// One row of a forest_gen tasks file: `#trial,map_id,start_x,start_y,start_z,end_x,end_y,end_z`.
struct ReplanTask {
  int trial = 0;
  int map_id = 0;
  Eigen::Vector3d start = Eigen::Vector3d::Zero();  ///< [m]
  Eigen::Vector3d goal = Eigen::Vector3d::Zero();   ///< [m]
};
/// What readTasksCsv skipped.
struct TasksCsvStats {
  int rows = 0;      ///< data rows read (comment and empty lines excluded)
  int bad_rows = 0;  ///< rows without 8 numbers, with non-finite coordinates, or too long
  bool too_many = false;  ///< more than max_tasks good rows: the rest was not read
};
/// Reads a tasks file (forest_gen's CSV; '#' starts a comment line). A row that does not parse is
/// counted in bad_rows and skipped; lines longer than 4096 bytes are bad rows. At most `max_tasks`
/// tasks are kept.
TasksCsvStats readTasksCsv(std::istream& in, std::vector<ReplanTask>* tasks, size_t max_tasks = 1000000);

/// Mean jerk integral of method a over that of method b, on the tasks both solved (all densities).
double jerkRatio(const std::vector<TaskOutcome>& outcomes, Method a, Method b, int* common = nullptr);

}  // namespace bench
}  // namespace topo_planner
