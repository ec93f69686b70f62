#include "topo_planner/plan_manage/planner_settings.h"

#include <cmath>
#include <sstream>

namespace topo_planner {

bool PlannerSettings::validate(std::string* why) const {
  std::ostringstream e;
  const auto period = [&](const char* name, double v) {
    if (!(v >= kMinPeriodS && v <= kMaxPeriodS)) e << name << " must be in [" << kMinPeriodS << ", " << kMaxPeriodS << "] s; ";
  };
  period("plan_period_s", plan_period_s);
  period("safety_period_s", safety_period_s);
  if (!(std::isfinite(vis_sample_s) && vis_sample_s >= kMinVisSampleS))
    e << "vis_sample_s must be finite and at least " << kMinVisSampleS << " s; ";
  if (!std::isfinite(goal_height_m)) e << "goal_height_m must be finite; ";
  if (!(reference_speed_ratio > 0.0 && reference_speed_ratio <= 1.0)) e << "reference/speed_ratio must be in (0, 1]; ";
  if (!(max_failed_plan_dumps >= 0 && max_failed_plan_dumps <= kMaxFailedPlanDumps))
    e << "debug/max_failed_plan_dumps must be in [0, " << kMaxFailedPlanDumps << "]; ";
  for (const Eigen::Vector3d& g : goals)
    if (!g.allFinite()) {
      e << "goals_m must be finite; ";
      break;
    }
  std::string reasons = e.str();
  if (reasons.empty()) return true;
  reasons.resize(reasons.size() - 2);  // the last "; "
  if (why) *why = reasons;
  return false;
}

}  // namespace topo_planner
