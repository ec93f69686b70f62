#include "topo_planner/path_searching/search_status.h"

namespace topo_planner {

const char* toString(SearchStatus status) {
  switch (status) {
    case SearchStatus::kSuccess: return "success";
    case SearchStatus::kNoPath: return "no path";
    case SearchStatus::kStartInObstacle: return "start in obstacle";
    case SearchStatus::kGoalInObstacle: return "goal in obstacle";
    case SearchStatus::kOutOfMap: return "start or goal out of the map";
    case SearchStatus::kInvalidInput: return "invalid input";
    case SearchStatus::kBudgetExhausted: return "budget exhausted without a path";
  }
  return "unknown status";
}

}  // namespace topo_planner
