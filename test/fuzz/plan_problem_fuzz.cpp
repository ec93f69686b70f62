// Saved replanning problems (topo_replan/plan_problem_io.h; what replay_plan reads, and what a user
// may send with a bug report): the bytes as <base>.problem beside a fixed small OctoMap <base>.bt
// (the OctoMap reader has its own harness), through loadPlanProblem, then, when it loads, the local
// problem of the replanner on it (the reference checked along the horizon, the local goal, the
// initial spline). The window is bounded by kMaxMemoryMb (loadPlanProblem's max_memory_mb, kept
// below the fuzzer's RSS limit). Properties: a loaded problem's request points to its own reference
// and has a finite start; a failed load says why.
#include <unistd.h>

#include <cstdio>
#include <fstream>
#include <memory>
#include <string>

#include "fuzz_input.h"
#include "topo_planner/plan_env/map_io.h"
#include "topo_planner/topo_replan/plan_problem_io.h"
#include "topo_planner/topo_replan/topo_replanner.h"

namespace {

constexpr double kMaxMemoryMb = 8.0;

// Per process (libFuzzer's -jobs run several): the base path, its .bt written once.
const std::string& base() {
  static const std::string path = [] {
    const std::string b = "/tmp/topo_planner_fuzz_plan_problem_" + std::to_string(::getpid());
    std::string why;
    topo_planner::OccupancyMap::Config c;
    c.resolution_m = 0.1;
    c.size_m = Eigen::Vector3d(4.0, 4.0, 2.0);
    c.origin_m = Eigen::Vector3d(-2.0, -2.0, 0.0);
    const auto map = topo_planner::OccupancyMap::create(c, &why);
    TOPO_PLANNER_FUZZ_CHECK(map != nullptr);
    for (int i = -10; i < 10; ++i) map->setState(Eigen::Vector3i(5, i, 8), topo_planner::VoxelState::kOccupied);
    map->setState(Eigen::Vector3i(0, 0, 8), topo_planner::VoxelState::kFree);
    TOPO_PLANNER_FUZZ_CHECK(topo_planner::saveOctomapFile(*map, b + ".bt", &why) == topo_planner::MapStatus::kSuccess);
    return b;
  }();
  return path;
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace topo_planner;
  {
    std::ofstream out(base() + ".problem", std::ios::binary | std::ios::trunc);
    out.write(reinterpret_cast<const char*>(data), std::streamsize(size));
  }
  PlanProblem problem;
  std::string why;
  if (!loadPlanProblem(base(), &problem, &why, kMaxMemoryMb)) {
    TOPO_PLANNER_FUZZ_CHECK(!why.empty());
    return 0;
  }
  TOPO_PLANNER_FUZZ_CHECK(problem.request.reference == &problem.reference);
  TOPO_PLANNER_FUZZ_CHECK(problem.request.start.allFinite());
  TOPO_PLANNER_FUZZ_CHECK(problem.esdf != nullptr && problem.occupancy != nullptr);
  // The local problem walks the reference in 10 ms steps (a reference standing still: all of it),
  // each step a walk over its segments: linear in both and bounded by the loader
  // (kMaxPlanProblemDurationS, kMaxPlanProblemSegments), but a long one takes seconds under the
  // sanitizers; the local problem is built for references up to a mission's two minutes.
  if (!(problem.reference.duration() <= 120.0 && problem.reference.segments().size() <= 200)) return 0;
  static const std::unique_ptr<TopoReplanner> replanner = [] {
    TopoReplanner::Config c;
    c.num_threads = 1;
    std::string error;
    return TopoReplanner::create(c, &error);
  }();
  TOPO_PLANNER_FUZZ_CHECK(replanner != nullptr);
  const LocalProblem lp = replanner->localProblem(*problem.esdf, problem.request);
  if (lp.status == ReplanStatus::kSuccess) {
    TOPO_PLANNER_FUZZ_CHECK(lp.goal.allFinite() && lp.initial.isValid(nullptr));
  } else {
    TOPO_PLANNER_FUZZ_CHECK(!lp.message.empty());
  }
  return 0;
}
