// The benchmark tasks file (forest_gen's start_and_end.csv) through readTasksCsv, and the first tasks
// on to what bench_replan does with them before planning: the minimum-snap reference trajectory.
#include <sstream>
#include <string>

#include "../../topo_replan/bench/replan_suite.h"
#include "fuzz_input.h"
#include "topo_planner/topo_replan/polynomial_trajectory.h"

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
    PolynomialTrajectory trajectory;
    if (referenceTrajectory({t.start, t.goal}, FlatState::atRest(t.start), FlatState::atRest(t.goal), reference,
                            &trajectory) == TrajectoryStatus::kSuccess)
      TOPO_PLANNER_FUZZ_CHECK(std::isfinite(trajectory.duration()));
  }
  return 0;
}
