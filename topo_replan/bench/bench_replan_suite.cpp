// make bench-replan: the paper's Table I, as a gtest executable.
//   bench_replan_suite [--maps N] [--tasks-per-map N] [--style S] [--collision-retries N] [--out DIR]   (default 10 x 50 = 500 tasks per density)
// Prints the Markdown table and a RESULT line; writes DIR/replan_tasks.csv (every task and method)
// and DIR/replan_table1.md. scripts/plot_replan.py turns the CSV into DIR/replan_table1.png.
#include <gtest/gtest.h>

#include <cstdio>
#include <cstring>
#include <fstream>

#include "replan_suite.h"

using namespace topo_planner;

namespace {
bench::SuiteConfig g_config;
std::string g_out = "results";
}  // namespace

TEST(ReplanSuite, TableI) {
  const std::vector<bench::TaskOutcome> outcomes =
      bench::runSuite(g_config, {ObstacleDensity::kLow, ObstacleDensity::kMedium, ObstacleDensity::kHigh});
  ASSERT_FALSE(outcomes.empty()) << "no task ran (unknown --style?)";
  const auto summary = bench::summarize(outcomes);
  const std::string table = bench::markdownTable(summary);
  std::printf("\n%s\n", table.c_str());
  EXPECT_TRUE(bench::writeCsv(outcomes, g_out + "/replan_tasks.csv")) << "cannot write " << g_out;
  std::ofstream(g_out + "/replan_table1.md") << table;
  for (const char* density : {"low", "medium", "high"}) {
    std::vector<bench::TaskOutcome> of;
    for (const bench::TaskOutcome& o : outcomes)
      if (o.density == density && o.method == bench::Method::kProposed) of.push_back(o);
    std::printf("Where the proposed method's time goes, %s density:\n%s\n", density, bench::phaseTable(of).c_str());
  }
  int common_gto = 0;
  const double ratio = bench::jerkRatio(outcomes, bench::Method::kProposed, bench::Method::kGto, &common_gto);
  auto rate = [&](const char* d, bench::Method m) { return summary.at(d).at(m).successRate(); };
  std::printf("jerk integral, proposed / gto on the %d tasks both solved: %.3f\n", common_gto, ratio);
  std::printf("RESULT success_low=%.4f success_medium=%.4f success_high=%.4f total_ms_median_medium=%.3f "
              "total_ms_p95_medium=%.3f jerk_ratio_vs_gto=%.3f gto_success_medium=%.4f gto_restart_success_medium=%.4f "
              "astar_pgo_success_medium=%.4f\n",
              rate("low", bench::Method::kProposed), rate("medium", bench::Method::kProposed),
              rate("high", bench::Method::kProposed), summary.at("medium").at(bench::Method::kProposed).time_median_ms,
              summary.at("medium").at(bench::Method::kProposed).time_p95_ms, ratio, rate("medium", bench::Method::kGto),
              rate("medium", bench::Method::kGtoRestart), rate("medium", bench::Method::kAstarPgo));
}

int main(int argc, char** argv) {
  ::testing::InitGoogleTest(&argc, argv);
  for (int i = 1; i + 1 < argc; i += 2) {
    if (!std::strcmp(argv[i], "--maps")) g_config.maps_per_density = std::max(1, std::atoi(argv[i + 1]));
    if (!std::strcmp(argv[i], "--tasks-per-map")) g_config.tasks_per_map = std::max(1, std::atoi(argv[i + 1]));
    if (!std::strcmp(argv[i], "--out")) g_out = argv[i + 1];
    if (!std::strcmp(argv[i], "--style")) g_config.style = argv[i + 1];
    if (!std::strcmp(argv[i], "--collision-retries")) g_config.collision_retries = std::atoi(argv[i + 1]);
  }
  return RUN_ALL_TESTS();
}
