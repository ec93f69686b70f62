// One closed-loop flight without ROS (plan_manage/sim_flight.h), in simulated time: the world from a
// map file or the map generator, the planner configured from config/*.yaml as the planner node is.
// Prints the flight's figures and, with --json, writes them for scripts/bench_speed.py.
//
//   sim_flight (--map FILE.bt | --forest STYLE DENSITY SEED) --start X Y Z --goals "X Y Z ..."
//              [--config DIR] [--max-vel V] [--max-acc A] [--sensing ideal|realistic]
//              [--window OX OY OZ SX SY SZ] [--goal-timeout S] [--json FILE] [--trace FILE.csv] [--quiet]
//              [--param name=value ...] (config/planner.yaml overrides) [--dump-plans DIR FROM TO]
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include "topo_planner/plan_env/map_generator.h"
#include "topo_planner/plan_env/map_io.h"
#include "topo_planner/plan_manage/planner_params.h"
#include "topo_planner/plan_manage/sim_flight.h"
#include "topo_planner/plan_manage/yaml_params.h"
#include "topo_planner/topo_replan/plan_problem_io.h"

using namespace topo_planner;

namespace {

int usage(const std::string& why) {
  std::fprintf(stderr,
               "sim_flight: %s\nusage: sim_flight (--map FILE.bt | --forest STYLE DENSITY SEED) --start X Y Z --goals \"X Y Z ...\"\n"
               "                  [--config DIR] [--max-vel V] [--max-acc A] [--sensing ideal|realistic]\n"
               "                  [--window OX OY OZ SX SY SZ] [--goal-timeout S] [--json FILE] [--trace FILE.csv] [--quiet]\n",
               why.c_str());
  return 2;
}

std::vector<double> numbers(const std::string& text) {
  std::istringstream in(text);
  std::vector<double> v;
  for (double x; in >> x;) v.push_back(x);
  return v;
}

// The occupied voxel centres of a map file, or of the map generator's world (as map_generator_node).
bool worldPoints(const std::string& map_file, const std::vector<std::string>& forest, const Eigen::Vector3d& start,
                 const std::vector<Eigen::Vector3d>& goals, std::vector<Eigen::Vector3d>* points, std::string* why) {
  std::unique_ptr<OccupancyMap> map;
  if (!map_file.empty()) {
    MapFile file;
    if (readMapFile(map_file, &file, why) != MapStatus::kSuccess) return false;
    OccupancyMap::Config base;
    base.max_memory_mb = 2048.0;
    map = OccupancyMap::create(configFittingMapFile(file, base, base.resolution_m), why);
    if (!map) return false;
    insertMapFile(file, map.get());
  } else {
    ObstacleDensity d = ObstacleDensity::kMedium;
    if (forest[1] == "low") d = ObstacleDensity::kLow;
    else if (forest[1] == "high") d = ObstacleDensity::kHigh;
    else if (forest[1] != "medium") return *why = "density must be low, medium or high", false;
    ForestConfig f = ForestConfig::preset(d);
    if (!f.applyStyle(forest[0])) return *why = "unknown style " + forest[0], false;
    const Eigen::Vector3d lo(-12.0, -10.0, 0.0), hi(12.0, 10.0, 3.0);  // config/map_generator.yaml
    f.keep_free = goals;
    f.keep_free.push_back(start);
    f.keep_free_radius_m = 1.5;
    f.ground_z_m = lo.z();
    f.pillar_height_m = hi.z() - lo.z();
    OccupancyMap::Config mc;
    mc.origin_m = lo;
    mc.size_m = hi - lo;
    map = OccupancyMap::create(mc, why);
    if (!map) return false;
    generateForest(f, uint32_t(std::strtoul(forest[2].c_str(), nullptr, 10)), map.get());
  }
  const GridGeometry& g = map->geometry();
  map->forEachOccupied([&](const Eigen::Vector3i& i) { points->push_back(g.centerOf(i)); });
  return true;
}

}  // namespace

// Times as a JSON list, 3 decimals.
std::string msList(const std::vector<double>& ms) {
  std::ostringstream o;
  o << "[";
  char buf[32];
  for (size_t i = 0; i < ms.size(); ++i) {
    std::snprintf(buf, sizeof(buf), "%.3f", ms[i]);
    o << (i ? ", " : "") << buf;
  }
  o << "]";
  return o.str();
}

// The tail's planning calls: tick ms, published, searched, A*, raw refine, guides, search / optimise ms.
std::string slowCalls(const std::vector<FsmEvent>& events) {
  std::ostringstream o;
  o << "[";
  char buf[256];
  for (size_t i = 0; i < events.size(); ++i) {
    const ReplanStats& s = events[i].stats;
    std::snprintf(buf, sizeof(buf), "%s{\"tick_ms\": %.2f, \"published\": %d, \"searched\": %d, \"astar\": %d, "
                  "\"raw\": %d, \"paths\": %d, \"search_ms\": %.2f, \"topo_ms\": %.2f, \"samples\": %d, \"optimize_ms\": %.2f}",
                  i ? ", " : "", s.total_ms, int(events[i].published), int(s.searched), int(s.used_astar),
                  int(s.used_raw_refine), s.paths, s.search_ms, s.search.total_ms, s.search.roadmap.samples, s.optimize_ms);
    o << buf;
  }
  o << "]";
  return o.str();
}

int main(int argc, char** argv) {
  std::string map_file, config_dir = TOPO_PLANNER_CONFIG_DIR, sensing = "ideal", json, trace;
  std::vector<std::string> forest;
  Eigen::Vector3d start(-15.0, 0.0, 1.0);
  std::vector<Eigen::Vector3d> goals;
  double max_vel = 3.0, max_acc = 2.5, goal_timeout = 90.0;
  std::vector<double> window{-20.0, -10.0, 0.3, 40.0, 20.0, 3.4};
  bool quiet = false;
  std::vector<std::pair<std::string, std::string>> overrides;  // --param fsm/x=1 (config/planner.yaml)
  std::string dump_dir;  // --dump-plans DIR FROM TO: every planning problem in [FROM, TO] s (replay_plan)
  double dump_from = 0.0, dump_to = -1.0;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    auto need = [&](int n) { return i + n < argc; };
    if (a == "--map" && need(1)) map_file = argv[++i];
    else if (a == "--forest" && need(3)) forest = {argv[i + 1], argv[i + 2], argv[i + 3]}, i += 3;
    else if (a == "--start" && need(3)) {
      for (int k = 0; k < 3; ++k) start[k] = std::atof(argv[++i]);
    } else if (a == "--goals" && need(1)) {
      const std::vector<double> v = numbers(argv[++i]);
      if (v.empty() || v.size() % 3) return usage("--goals needs x y z triples");
      for (size_t k = 0; k < v.size(); k += 3) goals.emplace_back(v[k], v[k + 1], v[k + 2]);
    } else if (a == "--config" && need(1)) config_dir = argv[++i];
    else if (a == "--max-vel" && need(1)) max_vel = std::atof(argv[++i]);
    else if (a == "--max-acc" && need(1)) max_acc = std::atof(argv[++i]);
    else if (a == "--sensing" && need(1)) sensing = argv[++i];
    else if (a == "--goal-timeout" && need(1)) goal_timeout = std::atof(argv[++i]);
    else if (a == "--json" && need(1)) json = argv[++i];
    else if (a == "--trace" && need(1)) trace = argv[++i];
    else if (a == "--quiet") quiet = true;
    else if (a == "--param" && need(1)) {
      const std::string kv = argv[++i];
      const size_t eq = kv.find('=');
      if (eq == std::string::npos) return usage("--param needs name=value");
      overrides.emplace_back(kv.substr(0, eq), kv.substr(eq + 1));
    }
    else if (a == "--dump-plans" && need(3)) {
      dump_dir = argv[++i];
      dump_from = std::atof(argv[++i]);
      dump_to = std::atof(argv[++i]);
    }
    else if (a == "--window" && need(6)) {
      for (int k = 0; k < 6; ++k) window[size_t(k)] = std::atof(argv[++i]);
    } else {
      return usage("bad argument " + a);
    }
  }
  if ((map_file.empty() == forest.empty()) || goals.empty()) return usage("give --map or --forest, and --goals");
  if (sensing != "ideal" && sensing != "realistic") return usage("--sensing is ideal or realistic");

  // The planner, mapping, camera and trajectory server as configured in config/*.yaml.
  std::string why;
  SimFlight::Config c;
  if (!loadSimFlightConfig(config_dir, max_vel, max_acc, sensing == "realistic", &c, &why, overrides)) return usage(why);
  c.goal_timeout_s = goal_timeout;
  c.map.origin_m = Eigen::Vector3d(window[0], window[1], window[2]);
  c.map.size_m = Eigen::Vector3d(window[3], window[4], window[5]);

  std::vector<Eigen::Vector3d> points;
  if (!worldPoints(map_file, forest, start, goals, &points, &why)) return usage(why);
  TruthMap::Config tc;
  tc.include_points = goals;
  tc.include_points.push_back(start);
  std::shared_ptr<const TruthMap> truth = TruthMap::build(points, tc, &why);
  if (!truth) return usage("true map: " + why);

  double sim_now = 0.0;
  int dumped = 0;
  if (!dump_dir.empty())
    c.plan_observer = [&](const EsdfMap& map, const ReplanRequest& request, const ReplanResult& result) {
      if (sim_now < dump_from || sim_now > dump_to) return;
      char base[512];
      std::snprintf(base, sizeof(base), "%s/plan_%03d_t%.2f", dump_dir.c_str(), dumped++, sim_now);
      std::string error;
      if (!savePlanProblem(base, map, request, result.message, &error)) std::fprintf(stderr, "sim_flight: %s\n", error.c_str());
    };
  std::ofstream trace_out;
  if (!trace.empty()) {
    trace_out.open(trace);
    trace_out << "t,x,y,z,vx,vy,vz,speed,yaw,mode,trajectory_id,clearance_m,event\n";
  }
  const SimFlight::Result r = SimFlight::fly(*truth, start, goals, c, [&](const SimFlight::Step& s) {
    sim_now = s.t_s + c.server_period_s;
    if (!trace_out.is_open()) return;
    const Setpoint& sp = s.setpoint;
    std::string event;
    if (s.output && s.output->event) {
      const FsmEvent& e = *s.output->event;
      event = std::string(toString(e.trigger)) + " " + toString(e.status) + " " + e.fallback;
    }
    if (s.output && !s.output->message.empty()) event += (event.empty() ? "" : " | ") + s.output->message;
    if (s.published) {
      const ExecTrajectory& p = *s.published;
      char text[256];
      std::snprintf(text, sizeof(text), " | published %ld: %.2f s, brake at +%.2f s%s, max %.2f m/s, reference %.2f-%.2f s%s%s",
                    long(p.id), p.spline.duration(), p.brake_start_s - p.start_time_s,
                    p.stops_before_unknown ? " (cut before unknown space)" : "", p.spline.maxVelocity(), p.reference_start_s,
                    p.reference_end_s, p.braking ? " BRAKING" : "", p.escape ? " MANOEUVRE" : "");
      event += text;
      event += " | speeds";
      const UniformBspline vel = p.spline.derivative();
      for (double tau = 0.0; tau <= p.spline.duration() + 1e-9; tau += 0.2) {
        std::snprintf(text, sizeof(text), " %.2f", vel.evaluate(tau).norm());
        event += text;
      }
      if (s.output && s.output->plan) {
        const ReplanResult& plan = *s.output->plan;
        std::snprintf(text, sizeof(text), " | searched %d, %zu candidates, chosen %d, local goal %.2f-%.2f s",
                      int(plan.stats.searched), plan.candidates.size(), plan.chosen, plan.local_start_time_s,
                      plan.local_goal_time_s);
        event += text;
        for (size_t i = 0; i < plan.candidates.size(); ++i) {
          const ReplanCandidate& k = plan.candidates[i];
          double guide = 0.0;
          for (size_t j = 1; j < k.guide.size(); ++j) guide += (k.guide[j] - k.guide[j - 1]).norm();
          std::snprintf(text, sizeof(text), " [%zu: %s ratio %.2f guide %.1f m cost %.1f%s]", i, toString(k.result.status),
                        k.result.stats.time_ratio, guide, k.selection_cost, k.retried_along ? " along" : "");
          event += text;
        }
      }
    }
    for (char& ch : event)
      if (ch == ',' || ch == '\n') ch = ';';
    char line[512];
    std::snprintf(line, sizeof(line), "%.3f,%.3f,%.3f,%.3f,%.3f,%.3f,%.3f,%.3f,%.3f,%d,%ld,%.3f,", s.t_s,
                  sp.state.position.x(), sp.state.position.y(), sp.state.position.z(), sp.state.velocity.x(),
                  sp.state.velocity.y(), sp.state.velocity.z(), sp.state.velocity.norm(), sp.yaw, int(sp.mode),
                  long(sp.trajectory_id), s.clearance_m);
    trace_out << line << event << "\n";
  });
  if (!quiet) {
    std::printf("sim_flight: %s\n  %s\n  speed account: %.0f%% fast; slow:", r.message.c_str(), formatSimFlight(r).c_str(),
                100.0 * r.fast_share);
    for (int k = 0; k < kNumSlowCauses; ++k)
      if (r.speed.share(SlowCause(k)) >= 0.005) std::printf(" %s %.0f%%", toString(SlowCause(k)), 100.0 * r.speed.share(SlowCause(k)));
    std::printf("\n");
  }
  if (!json.empty()) {
    std::ofstream out(json);
    out << "{\"ok\": " << (r.ok ? "true" : "false") << ", \"goals_total\": " << r.goals.size()
        << ", \"goals_reached\": " << r.goals_reached << ", \"collisions\": " << r.collisions
        << ", \"min_clearance_m\": " << r.min_clearance_m << ", \"mean_speed_mps\": " << r.mean_speed_mps
        << ", \"max_speed_mps\": " << r.max_speed_mps << ", \"fast_share\": " << r.fast_share
        << ", \"oracle_time_s\": " << (std::isfinite(r.oracle_time_s) ? std::to_string(r.oracle_time_s) : "null")
        << ", \"reached_time_s\": " << (std::isfinite(r.reached_time_s) ? std::to_string(r.reached_time_s) : "null")
        << ", \"time_ratio\": " << (std::isfinite(r.time_ratio) ? std::to_string(r.time_ratio) : "null")
        << ", \"replans\": " << r.replans << ", \"replan_failures\": " << r.replan_failures
        << ", \"replan_ms\": " << msList(r.replan_ms) << ", \"planner_ms\": " << msList(r.planner_ms)
        << ", \"slow_calls\": " << slowCalls(r.slow_calls)
        << ", \"emergency_stops\": " << r.emergency_stops << ", \"speed_account_s\": {\"total\": " << r.speed.total_s
        << ", \"fast\": " << r.speed.fast_s;
    for (int k = 0; k < kNumSlowCauses; ++k) out << ", \"" << toString(SlowCause(k)) << "\": " << r.speed.slow_s[size_t(k)];
    out << "}, \"message\": \"" << r.message << "\"}\n";
  }
  return r.ok ? 0 : 1;
}
