#include "plan_env/plan_env.h"
namespace fast_planner {
const char* plan_env_name() { return "fast_planner::plan_env"; }
}
