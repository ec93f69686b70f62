// A small run of the Table I suite in CI: 20 tasks per density (2 maps x 10), every method, with the
// success checks of the paper's claims: the proposed method solves every task, at least as often as
// each baseline, and more smoothly than GTO where both succeed.
#include <gtest/gtest.h>

#include "replan_suite.h"

namespace topo_planner {
namespace {

TEST(ReplanSuite, SmallRunPassesItsSuccessChecks) {
  bench::SuiteConfig c;
  c.maps_per_density = 2;
  c.tasks_per_map = 10;
  const auto outcomes = bench::runSuite(c, {ObstacleDensity::kLow, ObstacleDensity::kMedium, ObstacleDensity::kHigh});
  const auto summary = bench::summarize(outcomes);
  std::printf("%s\n", bench::markdownTable(summary).c_str());
  for (const char* density : {"low", "medium", "high"}) {
    const auto& s = summary.at(density);
    EXPECT_EQ(s.at(bench::Method::kProposed).tasks, 20) << density;
    EXPECT_EQ(s.at(bench::Method::kProposed).solved, 20) << density;
    for (bench::Method m : bench::allMethods())
      EXPECT_GE(s.at(bench::Method::kProposed).solved, s.at(m).solved) << density << " " << bench::toString(m);
  }
  int common = 0;
  const double ratio = bench::jerkRatio(outcomes, bench::Method::kProposed, bench::Method::kGto, &common);
  EXPECT_GT(common, 10);
  EXPECT_LT(ratio, 1.0);
}

}  // namespace
}  // namespace topo_planner
