#pragma once
// Fast-Planner's module bspline_opt, as far as the name-clash check needs it.
namespace fast_planner {
const char* bspline_opt_name();
}
