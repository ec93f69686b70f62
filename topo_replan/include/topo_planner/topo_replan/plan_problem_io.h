#pragma once
// A replanning problem saved to files and loaded back: the map the planner saw (known voxels as an
// OctoMap .bt, with its window and ESDF settings) and the request (start state, global reference,
// reference time, attempt). The planner node writes one per failed plan when asked
// (debug/dump_failed_plans_dir); replay_plan loads it and plans again with every candidate's
// outcome printed, so that a failure seen in flight can be studied and a fix tested offline.
//
// <base>.problem is text, one `key values...` line each; <base>.bt beside it. Loading checks every
// number (finite, in range, counts bounded) and gives a status with a reason; it never throws.

#include <memory>
#include <string>

#include "topo_planner/plan_env/esdf_map.h"
#include "topo_planner/plan_env/occupancy_map.h"
#include "topo_planner/topo_replan/polynomial_trajectory.h"
#include "topo_planner/topo_replan/topo_replanner.h"

namespace topo_planner {

struct PlanProblem {
  std::shared_ptr<OccupancyMap> occupancy;
  std::unique_ptr<EsdfMap> esdf;
  PolynomialTrajectory reference;
  ReplanRequest request;  ///< its reference points to `reference`
  std::string note;       ///< what the planner said of it (the failure message)
};

/// Most reference segments a problem file may hold (a mission's reference has one per 3 m at most:
/// reference/max_segment_length_m), and its longest duration: the replanner walks the reference in
/// 10 ms steps, and its position costs a walk over the segments.
constexpr int kMaxPlanProblemSegments = 2000;
constexpr double kMaxPlanProblemDurationS = 3600.0;

/// Writes <base>.problem and <base>.bt. False with a reason when a file cannot be written.
bool savePlanProblem(const std::string& base, const EsdfMap& map, const ReplanRequest& request,
                     const std::string& note, std::string* error);

/// Reads <base>.problem and <base>.bt (base may also name the .problem file): the map rebuilt in
/// the saved window, its ESDF computed. False with a reason on any malformed or missing input, or a
/// window whose layers would need more than max_memory_mb (OccupancyMap::Config::max_memory_mb).
bool loadPlanProblem(const std::string& base, PlanProblem* out, std::string* error, double max_memory_mb = 4096.0);

}  // namespace topo_planner
