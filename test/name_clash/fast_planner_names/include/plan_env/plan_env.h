#pragma once
// Fast-Planner's module plan_env, as far as the name-clash check needs it.
namespace fast_planner {
const char* plan_env_name();
}
