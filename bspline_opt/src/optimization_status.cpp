#include "topo_planner/bspline_opt/optimization_status.h"

namespace topo_planner {

const char* toString(OptimizationStatus status) {
  switch (status) {
    case OptimizationStatus::kSuccess: return "success";
    case OptimizationStatus::kInCollision: return "in collision";
    case OptimizationStatus::kOutOfMap: return "out of map";
    case OptimizationStatus::kInfeasible: return "infeasible";
    case OptimizationStatus::kOptimizationFailed: return "optimization failed";
    case OptimizationStatus::kInvalidInput: return "invalid input";
  }
  return "unknown status";
}

}  // namespace topo_planner
