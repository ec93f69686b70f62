// The planner node's own range checks (PlannerSettings::validate, readPlannerParams refuses to start
// on them): the defaults pass, each out-of-range field is refused and named.
#include <gtest/gtest.h>

#include <cmath>
#include <functional>
#include <limits>
#include <string>

#include "topo_planner/plan_manage/planner_settings.h"

namespace topo_planner {
namespace {

constexpr double kInf = std::numeric_limits<double>::infinity();
constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

TEST(PlannerSettings, DefaultsAreValid) {
  std::string why = "unchanged";
  EXPECT_TRUE(PlannerSettings().validate(&why));
  EXPECT_EQ(why, "unchanged");
}

struct Case {
  const char* field;  // named in the reason
  std::function<void(PlannerSettings*)> set;
};

TEST(PlannerSettings, OutOfRangeFieldsAreRefusedByName) {
  const Case cases[] = {
      {"plan_period_s", [](PlannerSettings* s) { s->plan_period_s = kInf; }},
      {"plan_period_s", [](PlannerSettings* s) { s->plan_period_s = 0.0; }},
      {"plan_period_s", [](PlannerSettings* s) { s->plan_period_s = kNaN; }},
      {"plan_period_s", [](PlannerSettings* s) { s->plan_period_s = 1e10; }},  // beyond ros::Duration
      {"plan_period_s", [](PlannerSettings* s) { s->plan_period_s = 1e-300; }},  // ros::Duration of 0
      {"safety_period_s", [](PlannerSettings* s) { s->safety_period_s = kInf; }},
      {"safety_period_s", [](PlannerSettings* s) { s->safety_period_s = -0.05; }},
      {"vis_sample_s", [](PlannerSettings* s) { s->vis_sample_s = 1e-300; }},  // T / dt overflowed int
      {"vis_sample_s", [](PlannerSettings* s) { s->vis_sample_s = 0.0; }},
      {"vis_sample_s", [](PlannerSettings* s) { s->vis_sample_s = kInf; }},
      {"goal_height_m", [](PlannerSettings* s) { s->goal_height_m = kNaN; }},
      {"reference/speed_ratio", [](PlannerSettings* s) { s->reference_speed_ratio = 1.5; }},
      {"reference/speed_ratio", [](PlannerSettings* s) { s->reference_speed_ratio = 0.0; }},
      {"goals_m", [](PlannerSettings* s) { s->goals = {Eigen::Vector3d(1, 2, 1), Eigen::Vector3d(kNaN, 0, 1)}; }},
  };
  for (const Case& c : cases) {
    PlannerSettings s;
    c.set(&s);
    std::string why;
    EXPECT_FALSE(s.validate(&why)) << c.field;
    EXPECT_NE(why.find(c.field), std::string::npos) << c.field << ": " << why;
  }
}

TEST(PlannerSettings, BoundsThemselvesAreAccepted) {
  PlannerSettings s;
  s.vis_sample_s = PlannerSettings::kMinVisSampleS;
  s.plan_period_s = PlannerSettings::kMaxPeriodS;
  s.safety_period_s = PlannerSettings::kMinPeriodS;
  s.reference_speed_ratio = 1.0;
  std::string why;
  EXPECT_TRUE(s.validate(&why)) << why;
  s.vis_sample_s = 0.999 * PlannerSettings::kMinVisSampleS;
  EXPECT_FALSE(s.validate(&why));
}

TEST(PlannerSettings, EveryReasonIsGiven) {
  PlannerSettings s;
  s.plan_period_s = kInf;
  s.vis_sample_s = 0.0;
  std::string why;
  ASSERT_FALSE(s.validate(&why));
  EXPECT_NE(why.find("plan_period_s"), std::string::npos) << why;
  EXPECT_NE(why.find("vis_sample_s"), std::string::npos) << why;
  EXPECT_NE(why.substr(why.size() - 2), "; ") << why;
}

}  // namespace
}  // namespace topo_planner
