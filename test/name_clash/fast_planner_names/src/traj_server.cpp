// Prints the modules it linked: the libraries named plan_env, bspline_opt and path_searching are
// this package's, not topo_planner's.
#include <cstdio>

#include "bspline_opt/bspline_opt.h"
#include "path_searching/path_searching.h"
#include "plan_env/plan_env.h"

int main() {
  std::printf("%s %s %s\n", fast_planner::plan_env_name(), fast_planner::bspline_opt_name(),
              fast_planner::path_searching_name());
  return 0;
}
