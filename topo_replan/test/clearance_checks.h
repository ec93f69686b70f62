#pragma once
// Checks shared by the replanner's tests on a trajectory planned from a start inside the
// optimiser's clearance (TopoReplanner::Config::min_start_clearance_m).

#include <gtest/gtest.h>

#include "topo_planner/bspline_opt/uniform_bspline.h"
#include "topo_planner/plan_env/esdf_map.h"

namespace topo_planner {

/// Sampled every step_s: until the trajectory first reaches clearance_m, no sample is more than
/// 11 mm closer to an obstacle than its start (the optimiser's 1 cm slack and a millimetre of
/// sampling); from then on none is inside clearance_m - tolerance_m; and it does reach clearance_m.
inline ::testing::AssertionResult movesOutOfTheClearance(const UniformBspline& trajectory, const EsdfMap& map,
                                                         double clearance_m, double step_s, double tolerance_m) {
  const double d0 = map.query(trajectory.evaluate(0.0)).distance;
  bool out = false;
  for (double t = 0.0; t <= trajectory.duration(); t += step_s) {
    const double d = map.query(trajectory.evaluate(t)).distance;
    const double floor = out ? clearance_m - tolerance_m : d0 - 0.011;
    if (d < floor)
      return ::testing::AssertionFailure() << "at t = " << t << " s the distance is " << d << " m, below " << floor
                                           << " m (" << (out ? "after" : "before") << " reaching the clearance; "
                                           << "the start's is " << d0 << " m)";
    out = out || d >= clearance_m;
  }
  if (!out) return ::testing::AssertionFailure() << "never reaches the clearance of " << clearance_m << " m";
  return ::testing::AssertionSuccess();
}

}  // namespace topo_planner
