#pragma once

namespace topo_planner {

/// Outcome of a path search.
enum class SearchStatus {
  kSuccess,
  kNoPath,           ///< the search space was exhausted without reaching the goal
  kStartInObstacle,  ///< the start is closer than the clearance to an obstacle
  kGoalInObstacle,   ///< the goal is closer than the clearance to an obstacle
  kOutOfMap,         ///< start or goal outside the map window
  kInvalidInput,     ///< NaN/inf, start equal to goal, or an invalid config
  kBudgetExhausted,  ///< sample, expansion or time budget used up without a path
};

const char* toString(SearchStatus status);

}  // namespace topo_planner
