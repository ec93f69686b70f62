#include "bspline_opt/bspline_opt.h"
namespace fast_planner {
const char* bspline_opt_name() { return "fast_planner::bspline_opt"; }
}
