#include "path_searching/path_searching.h"
namespace fast_planner {
const char* path_searching_name() { return "fast_planner::path_searching"; }
}
