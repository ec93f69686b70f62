#pragma once

namespace topo_planner {

/// Outcome of a trajectory optimisation (PathGuidedOptimizer).
enum class OptimizationStatus {
  kSuccess,             ///< collision-free with the clearance along the curve, and feasible
  kInCollision,         ///< some curve sample is closer than the clearance to an obstacle
  kOutOfMap,            ///< some curve sample leaves the map window (cannot be verified)
  kInfeasible,          ///< velocity/acceleration above the limits and time reallocation not allowed or too long
  kOptimizationFailed,  ///< NLopt reported an error, or a cost was not finite
  kInvalidInput,        ///< invalid spline (NaN, knot span <= 0, too few control points), empty guide, bad
                        ///< config, or a curve too long for the final check (> 1e7 samples)
};

const char* toString(OptimizationStatus status);

}  // namespace topo_planner
