#pragma once
// Fast-Planner's module path_searching, as far as the name-clash check needs it.
namespace fast_planner {
const char* path_searching_name();
}
