// Any map, any task list:
//   bench_replan --map FILE.bt|FILE.pcd --tasks TASKS.csv --out DIR [--method proposed|gto|gto_restart|astar_pgo]
//                [--map-id N] [--max-vel 3] [--max-acc 2.5]
// TASKS.csv has the forest_gen header `#trial,map_id,start_x,start_y,start_z,end_x,end_y,end_z`; rows
// whose map_id differs from --map-id are skipped when it is given. Every task is planned rest to rest
// from start to end as one local problem, from a straight minimum-snap reference. Writes
// DIR/summary.csv (trial,map_id,ok,topo_ms,opt_ms,total_ms,num_paths) and, per solved task,
// DIR/traj_<trial>.csv (t,x,y,z every 0.001 s, 9 decimals). Prints a summary and a RESULT line.
#include <algorithm>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <iomanip>
#include <sstream>

#include "topo_planner/plan_env/timing.h"
#include "topo_planner/plan_env/map_io.h"
#include "replan_suite.h"

using namespace topo_planner;

namespace {
int usage() {
  std::fprintf(stderr,
               "usage: bench_replan --map FILE.bt|FILE.pcd --tasks TASKS.csv --out DIR [--method "
               "proposed|gto|gto_restart|astar_pgo] [--map-id N] [--max-vel 3] [--max-acc 2.5]\n");
  return 2;
}
}  // namespace

int main(int argc, char** argv) {
  std::string map_path, tasks_path, out_dir;
  bench::Method method = bench::Method::kProposed;
  int map_id = -1;
  bench::SuiteConfig suite;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    if (i + 1 >= argc) return usage();
    const std::string v = argv[++i];
    if (a == "--map") map_path = v;
    else if (a == "--tasks") tasks_path = v;
    else if (a == "--out") out_dir = v;
    else if (a == "--method") {
      if (!bench::parseMethod(v, &method)) return usage();
    } else if (a == "--map-id") map_id = std::atoi(v.c_str());
    else if (a == "--max-vel") suite.max_vel_mps = std::atof(v.c_str());
    else if (a == "--max-acc") suite.max_acc_mps2 = std::atof(v.c_str());
    else return usage();
  }
  if (map_path.empty() || tasks_path.empty() || out_dir.empty() || !(suite.max_vel_mps > 0) || !(suite.max_acc_mps2 > 0))
    return usage();

  MapFile file;
  std::string err;
  if (readMapFile(map_path, &file, &err) != MapStatus::kSuccess) {
    std::fprintf(stderr, "bench_replan: %s\n", err.c_str());
    return 1;
  }
  auto occ = std::shared_ptr<OccupancyMap>(OccupancyMap::create(configFittingMapFile(file, OccupancyMap::Config(), 0.0), &err));
  if (!occ) {
    std::fprintf(stderr, "bench_replan: %s\n", err.c_str());
    return 1;
  }
  insertMapFile(file, occ.get());
  auto esdf = EsdfMap::create(EsdfMap::Config(), occ, &err);
  esdf->updateAll();

  std::ifstream tasks(tasks_path);
  if (!tasks) {
    std::fprintf(stderr, "bench_replan: cannot open %s\n", tasks_path.c_str());
    return 1;
  }
  std::ofstream summary(out_dir + "/summary.csv");
  if (!summary) {
    std::fprintf(stderr, "bench_replan: cannot write to %s (does the directory exist?)\n", out_dir.c_str());
    return 1;
  }
  summary << "trial,map_id,ok,topo_ms,opt_ms,total_ms,num_paths";
  for (const auto& field : bench::PhaseTimes::fields()) summary << ",\"" << field.first << "\"";
  summary << "\n" << std::fixed << std::setprecision(4);

  std::vector<bench::ReplanTask> task_list;
  const bench::TasksCsvStats csv = bench::readTasksCsv(tasks, &task_list);
  if (csv.too_many) std::fprintf(stderr, "bench_replan: %s: only the first %zu tasks are run\n", tasks_path.c_str(), task_list.size());

  bench::MethodRunner runner(suite);

  std::vector<double> total_ms, jerk;
  std::vector<bench::TaskOutcome> outcomes;  // for the phase table (trajectories dropped)
  int tasks_run = 0, solved = 0;
  const int bad_rows = csv.bad_rows;
  for (const bench::ReplanTask& task : task_list) {
    const int trial = task.trial, id = task.map_id;
    const Eigen::Vector3d s = task.start, g = task.goal;
    if (map_id >= 0 && id != map_id) continue;
    PolynomialTrajectory reference;
    bench::TaskOutcome o;
    if (referenceTrajectory({s, g}, FlatState::atRest(s), FlatState::atRest(g), runner.reference, &reference) == TrajectoryStatus::kSuccess)
      o = runner.run(method, *esdf, reference, uint32_t(trial));
    ++tasks_run;
    summary << trial << "," << id << "," << int(o.ok) << "," << o.search_ms << "," << o.opt_ms << "," << o.total_ms << ","
            << o.paths;
    for (const auto& field : bench::PhaseTimes::fields()) summary << "," << o.phases.*(field.second);
    summary << "\n";
    outcomes.push_back(o);
    outcomes.back().trajectory = UniformBspline();
    total_ms.push_back(o.total_ms);
    if (o.ok) {
      ++solved;
      jerk.push_back(o.jerk_integral);
      std::ofstream traj(out_dir + "/traj_" + std::to_string(trial) + ".csv");
      traj << "t,x,y,z\n" << std::fixed << std::setprecision(9);
      const double T = o.trajectory.duration();
      const long n = long(std::floor(T / 0.001 + 1e-9));
      for (long k = 0; k <= n; ++k) {
        const double t = std::min(T, k * 0.001);
        const Eigen::Vector3d p = o.trajectory.evaluate(t);
        traj << t << "," << p.x() << "," << p.y() << "," << p.z() << "\n";
      }
    }
    std::fprintf(stderr, "\rtask %d: %d/%d solved", trial, solved, tasks_run);
  }
  std::fprintf(stderr, "\n");
  double jerk_mean = 0.0;
  for (double j : jerk) jerk_mean += j / double(std::max<size_t>(1, jerk.size()));
  std::printf("bench_replan: %s, method %s, %d tasks (%d unreadable rows skipped)\n", map_path.c_str(),
              bench::toString(method), tasks_run, bad_rows);
  std::printf("| method | tasks | success | total ms median | p95 | jerk integral mean (solved) |\n|---|---|---|---|---|---|\n");
  std::printf("| %s | %d | %.2f%% | %.3f | %.3f | %.3f |\n", bench::toString(method), tasks_run,
              tasks_run ? 100.0 * solved / tasks_run : 0.0, percentile(total_ms, 0.5), percentile(total_ms, 0.95), jerk_mean);
  if (method == bench::Method::kProposed) std::printf("\n%s\n", bench::phaseTable(outcomes).c_str());
  std::printf("RESULT method=%s tasks=%d success=%.4f total_ms_median=%.3f total_ms_p95=%.3f jerk_mean=%.3f\n",
              bench::toString(method), tasks_run, tasks_run ? double(solved) / tasks_run : 0.0, percentile(total_ms, 0.5),
              percentile(total_ms, 0.95), jerk_mean);
  return 0;
}
