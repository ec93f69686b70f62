// replay_plan: plans again the failed replanning problems the planner node saved
// (debug/dump_failed_plans_dir, topo_replan/plan_problem_io.h), with the planner's parameters, and
// prints the local problem and every candidate's outcome: what a failure in flight was made of, and
// whether a change fixes it, without flying again.
//   roslaunch topo_planner replay_plan.launch problems:="/tmp/plans/plan_00012 /tmp/plans/plan_00013"
// The parameters are read like the planner node's (config/planner.yaml in ~); the result depends on
// the planning's wall-clock budgets (search/max_time_s, optimizer/max_time_s) as in flight.
#include <ros/ros.h>

#include <cstdio>
#include <string>
#include <vector>

#include "topo_planner/path_searching/grid_astar.h"
#include "topo_planner/path_searching/visibility.h"
#include "topo_planner/plan_manage/planner_server.h"
#include "topo_planner/topo_replan/plan_problem_io.h"
#include "topo_planner/topo_replan/replan_fsm.h"
#include "topo_planner/topo_replan/topo_replanner.h"

namespace {

using namespace topo_planner;

// The least ESDF distance along a polyline, sampled every 5 cm, and where.
double pathClearance(const EsdfMap& map, const Path& path, Eigen::Vector3d* where) {
  double best = INFINITY;
  for (size_t i = 1; i < path.size(); ++i) {
    const double length = (path[i] - path[i - 1]).norm();
    const int steps = std::max(1, int(std::ceil(length / 0.05)));
    for (int k = 0; k <= steps; ++k) {
      const Eigen::Vector3d p = path[i - 1] + (path[i] - path[i - 1]) * (double(k) / steps);
      const DistanceQuery q = map.query(p);
      if (q.status == QueryStatus::kOutOfMap || q.status == QueryStatus::kInvalidInput) continue;
      if (q.distance < best) {
        best = q.distance;
        *where = p;
      }
    }
  }
  return best;
}

double pathLength(const Path& path) {
  double length = 0.0;
  for (size_t i = 1; i < path.size(); ++i) length += (path[i] - path[i - 1]).norm();
  return length;
}

void printVector(const char* name, const Eigen::Vector3d& v) { std::printf("%s (%.2f, %.2f, %.2f)", name, v.x(), v.y(), v.z()); }

// Each phase of the optimisation of one candidate, checked on its own: where the curve is lost.
void printPhases(const TopoReplanner& replanner, const LocalProblem& lp, const Path& guide, const EsdfMap& map) {
  const PathGuidedOptimizer optimizer(replanner.config().optimizer);
  PathGuidedOptimizer::Config fixed_time = replanner.config().optimizer;
  fixed_time.reallocate_time = false;
  const PathGuidedOptimizer checker(fixed_time);
  auto show = [&](const char* what, const OptimizationResult& r) {
    if (r.status != OptimizationStatus::kSuccess) {
      std::printf("       %s: %s %s\n", what, toString(r.status), r.message.c_str());
      return;
    }
    const OptimizationResult c = checker.check(r.spline, map);
    std::printf("       %s: check %s, clearance %.2f", what, toString(c.status), c.stats.min_clearance_m);
    printVector(" at", r.spline.evaluate(c.stats.min_clearance_t_s));
    std::printf(", %d control points, f_s %.2f f_c %.3f f_d %.3f f_g %.2f\n", r.spline.numControlPoints(),
                r.cost.smoothness, r.cost.collision, r.cost.feasibility, r.cost.guide);
  };
  show("initial", checker.check(lp.initial, map));
  const OptimizationResult warm = optimizer.guidePhase(lp.initial, guide);
  show("guide phase", warm);
  if (warm.status != OptimizationStatus::kSuccess) return;
  show("refine", optimizer.refinePhase(warm.spline, map));
  // The stretched retry's start: the guide phase's spline timed for the refine's limits, keeping
  // the start state as optimize() does.
  const PathGuidedOptimizer::Config& oc = replanner.config().optimizer;
  OptimizationResult stretched = warm;
  const double ratio = stretched.spline.reallocateTime(oc.feasibility_margin * oc.max_vel_mps,
                                                       oc.feasibility_margin * oc.max_acc_mps2, true);
  const UniformBspline vel = lp.initial.derivative();
  if (ratio > 1.0)
    setCubicStart(lp.initial.evaluate(0.0), vel.evaluate(0.0), vel.derivative().evaluate(0.0), &stretched.spline);
  std::printf("       guide phase stretched x%.2f to the refine's limits:\n", ratio);
  show("  stretched", stretched);
  show("  refine", optimizer.refinePhase(stretched.spline, map));
}

int replay(TopoReplanner& replanner, const std::string& path, bool phases) {
  PlanProblem problem;
  std::string why;
  if (!loadPlanProblem(path, &problem, &why)) {
    std::printf("%s: cannot load: %s\n", path.c_str(), why.c_str());
    return 1;
  }
  const EsdfMap& map = *problem.esdf;
  const ReplanRequest& request = problem.request;
  std::printf("== %s\n   in flight: %s\n", path.c_str(), problem.note.c_str());
  printVector("   start", request.start.position);
  printVector(" v", request.start.velocity);
  printVector(" a", request.start.acceleration);
  std::printf(" |v| %.2f; reference t %.2f of %.2f s, attempt %u\n", request.start.velocity.norm(),
              request.reference_time_s, problem.reference.duration(), request.attempt);
  const LocalProblem lp = replanner.localProblem(map, request);
  std::printf("   local problem: %s", toString(lp.status));
  if (lp.status == ReplanStatus::kSuccess) {
    printVector(", goal", lp.goal);
    std::printf(" %.2f m away, segment %.2f m in %.2f s, reference collides at t %.2f\n", (lp.goal - lp.start).norm(),
                lp.initial_length_m, lp.initial.duration(), lp.collision_time_s);
  } else {
    std::printf(": %s\n", lp.message.c_str());
  }
  if (phases && lp.status == ReplanStatus::kSuccess) {
    // The A* fallback's view: is there a way at all, at which clearance and in which box.
    for (const double margin : {3.0, 6.0, 12.0})
      for (const double clearance : {replanner.config().astar.clearance_m, 0.2}) {
        GridAStar::Config ac = replanner.config().astar;
        ac.search_margin_m = margin;
        ac.margin_doublings = 0;
        ac.clearance_m = clearance;
        ac.max_expansions = 4000000;
        GridAStar astar(ac);
        const GridAStar::Result r = astar.search(map, lp.search_start, lp.goal);
        std::printf("   A* margin %.0f m clearance %.2f m: %s, %zu points, %d expansions\n", margin, clearance,
                    toString(r.status), r.path.size(), r.expansions);
      }
    const VisibilityChecker free_at(map, replanner.config().astar.clearance_m, replanner.config().astar.unknown_is_free);
    std::printf("   search start free %d, goal free %d (ESDF %.2f m at the goal)\n", int(free_at.isFree(lp.search_start)),
                int(free_at.isFree(lp.goal)), map.query(lp.goal).distance);
  }
  const ReplanResult result = replanner.replan(map, request);
  std::printf("   replayed: %s%s%s (%.1f ms: search %.1f, optimise %.1f)\n", toString(result.status),
              result.message.empty() ? "" : ": ", result.message.c_str(), result.stats.total_ms, result.stats.search_ms,
              result.stats.optimize_ms);
  for (size_t i = 0; i < result.candidates.size(); ++i) {
    const ReplanCandidate& c = result.candidates[i];
    Eigen::Vector3d guide_at = Eigen::Vector3d::Zero();
    const double guide_clearance = pathClearance(map, c.guide, &guide_at);
    const OptimizationStats& st = c.result.stats;
    std::printf("   %s%zu: guide %zu points %.2f m (x%.2f the segment), clearance %.2f", int(i) == result.chosen ? "*" : " ",
                i, c.guide.size(), pathLength(c.guide), pathLength(c.guide) / std::max(1e-9, lp.initial_length_m),
                guide_clearance);
    printVector(" at", guide_at);
    std::printf("\n       -> %s, clearance %.2f", toString(c.result.status), st.min_clearance_m);
    if (c.result.spline.numControlPoints() > 0 && std::isfinite(st.min_clearance_m))
      printVector(" at", c.result.spline.evaluate(st.min_clearance_t_s));
    std::printf(" (t %.2f of %.2f s), time ratio %.2f, v %.2f, a %.2f, %d evaluations", st.min_clearance_t_s,
                c.result.spline.duration(), st.time_ratio, st.max_vel_mps, st.max_acc_mps2, st.iterations);
    if (c.retried_along)
      std::printf("; first try %s, clearance %.2f", toString(c.first_status), c.first_min_clearance_m);
    if (c.start_velocity_step_mps > 0.0) std::printf("; start velocity step %.2f m/s", c.start_velocity_step_mps);
    std::printf("\n");
    if (phases && !c.guide.empty()) printPhases(replanner, lp, c.guide, map);
  }
  return result.status == ReplanStatus::kSuccess ? 0 : 2;
}

}  // namespace

int main(int argc, char** argv) {
  ros::init(argc, argv, "replay_plan", ros::init_options::AnonymousName);
  std::vector<std::string> args;
  ros::removeROSArgs(argc, argv, args);
  ros::NodeHandle nh("~");
  // Arguments: problem bases, and --phases=true|false (each optimisation phase of every candidate
  // checked on its own).
  bool phases = false;
  std::vector<std::string> paths;
  for (size_t i = 1; i < args.size(); ++i) {
    if (args[i].rfind("--phases=", 0) == 0) phases = args[i] == "--phases=true" || args[i] == "--phases=1";
    else if (!args[i].empty()) paths.push_back(args[i]);
  }
  if (paths.empty()) {
    std::fprintf(stderr, "usage: replay_plan [--phases=true] <base>... (files saved by the planner's debug/dump_failed_plans_dir)\n");
    return 1;
  }
  PlannerServer::Config config;
  if (!readPlannerParams(nh, &config)) return 1;
  std::string why;
  const std::unique_ptr<TopoReplanner> replanner = TopoReplanner::create(ReplanFsm::replannerConfig(config.fsm), &why);
  if (!replanner) {
    std::fprintf(stderr, "replay_plan: %s\n", why.c_str());
    return 1;
  }
  int failed = 0, unloadable = 0;
  for (const std::string& path : paths) {
    const int r = replay(*replanner, path, phases);
    failed += r == 2;
    unloadable += r == 1;
  }
  std::printf("replay_plan: %zu problem(s): %zu planned, %d failed again, %d not loaded\n", paths.size(),
              paths.size() - size_t(failed + unloadable), failed, unloadable);
  return unloadable > 0 ? 1 : 0;
}
