// Wall-clock hang guards of the ROS tests: make test-asan / test-tsan set TOPO_PLANNER_TIME_LIMIT_SCALE
// (the sanitizers slow every process down; the flights themselves run on simulated time).
#pragma once

#include <cstdlib>

namespace topo_planner_test {

inline double wallScale() {
  const char* s = std::getenv("TOPO_PLANNER_TIME_LIMIT_SCALE");
  const double k = s ? std::atof(s) : 1.0;
  return k >= 1.0 ? k : 1.0;
}

}  // namespace topo_planner_test
