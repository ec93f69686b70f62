// The benchmark tasks file (forest_gen's start_and_end.csv) through readTasksCsv, and the first tasks
// on to what bench_replan does with them before planning: the minimum-snap reference trajectory.
// The reference is built only for tasks up to kMaxReferenceLengthM long: referenceTrajectory checks
// its limits every 10 ms of flight (up to 1e5 samples per check, a few checks), so a task of 1 km
// costs ~0.1 s under the sanitizers, and the first runs with any length fuzzed at 9 execs/s. That
// cost is linear in the length and bounded, not a bug; forest_gen's tasks are 6 to 10 m in 20 m
// worlds, and longer ones still go through the reader.
#include <sstream>
#include <string>

#include "../../topo_replan/bench/replan_suite.h"
#include "fuzz_input.h"
#include "topo_planner/topo_replan/polynomial_trajectory.h"

namespace {
constexpr double kMaxReferenceLengthM = 100.0;
}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace topo_planner;
  std::istringstream in(std::string(reinterpret_cast<const char*>(data), size));
  std::vector<bench::ReplanTask> tasks;
  const bench::TasksCsvStats stats = bench::readTasksCsv(in, &tasks, 64);
  TOPO_PLANNER_FUZZ_CHECK(tasks.size() <= 64);
  TOPO_PLANNER_FUZZ_CHECK(stats.bad_rows >= 0 && size_t(stats.rows) >= tasks.size());
  const ReferenceConfig reference;
  for (size_t i = 0; i < tasks.size() && i < 4; ++i) {
    const bench::ReplanTask& t = tasks[i];
    TOPO_PLANNER_FUZZ_CHECK(t.start.allFinite() && t.goal.allFinite());
    if (!((t.goal - t.start).norm() <= kMaxReferenceLengthM)) continue;
    PolynomialTrajectory trajectory;
    if (referenceTrajectory({t.start, t.goal}, FlatState::atRest(t.start), FlatState::atRest(t.goal), reference,
                            &trajectory) == TrajectoryStatus::kSuccess) {
      TOPO_PLANNER_FUZZ_CHECK(std::isfinite(trajectory.duration()));
      // It starts and ends where the task does.
      const double tol = 1e-6 * (1.0 + t.start.cwiseAbs().maxCoeff() + t.goal.cwiseAbs().maxCoeff());
      TOPO_PLANNER_FUZZ_CHECK((trajectory.position(0.0) - t.start).cwiseAbs().maxCoeff() <= tol);
      TOPO_PLANNER_FUZZ_CHECK((trajectory.position(trajectory.duration()) - t.goal).cwiseAbs().maxCoeff() <= tol);
    }
  }
  return 0;
}
