// make bench-topo: the topological path search on random forests at three densities, against a
// plain PRM with the same sample count followed by pairwise UVD filtering.
//   Maps: 20 x 20 x 3 m at 0.1 m, pillars + floating boxes (plan_env/map_generator.h presets).
//   Tasks: 500 per density (10 maps x 50), start and goal free, 6-10 m apart, straight line blocked.
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstring>
#include <map>
#include <numeric>
#include <random>
#include <string>

#include "topo_planner/plan_env/synthetic_scene.h"
#include "topo_planner/plan_env/timing.h"
#include "topo_planner/path_searching/topo_path_search.h"
#include "topo_planner/plan_env/map_generator.h"

using namespace topo_planner;

namespace {

struct Task {
  Eigen::Vector3d start, goal;
};

// Plain PRM of n samples (radius-connected), depth-first paths, then pairwise UVD filtering.
struct PrmResult {
  int distinct = 0;
  double ms = 0.0;
};
PrmResult plainPrm(const EsdfMap& map, const Task& task, int n, double clearance, uint32_t seed) {
  const double t0 = nowMs();
  const VisibilityChecker checker(map, clearance, true);
  std::mt19937 rng(seed);
  const Eigen::Vector3d lo = task.start.cwiseMin(task.goal) - Eigen::Vector3d(1.0, 3.5, 1.5);
  const Eigen::Vector3d hi = task.start.cwiseMax(task.goal) + Eigen::Vector3d(1.0, 3.5, 1.5);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  std::vector<Eigen::Vector3d> nodes{task.start, task.goal};
  for (int i = 0; i < n; ++i) {
    const Eigen::Vector3d p = lo + (hi - lo).cwiseProduct(Eigen::Vector3d(u(rng), u(rng), u(rng)));
    if (checker.isFree(p)) nodes.push_back(p);
  }
  const double radius = 2.5;
  std::vector<std::vector<int>> adj(nodes.size());
  for (size_t a = 0; a < nodes.size(); ++a)
    for (size_t b = a + 1; b < nodes.size(); ++b)
      if ((nodes[a] - nodes[b]).norm() < radius && checker.lineVisible(nodes[a], nodes[b])) {
        adj[a].push_back(int(b));
        adj[b].push_back(int(a));
      }
  // Depth-first search for up to 300 paths of at most 20 nodes, pruned and budgeted as the
  // roadmap's (hop counts to the goal, 20000 expansions).
  std::vector<int> hops(nodes.size(), -1);
  std::vector<int> queue{1};
  hops[1] = 0;
  for (size_t h = 0; h < queue.size(); ++h)
    for (int nb : adj[size_t(queue[h])])
      if (hops[size_t(nb)] < 0) {
        hops[size_t(nb)] = hops[size_t(queue[h])] + 1;
        queue.push_back(nb);
      }
  std::vector<Path> raw;
  std::vector<int> stack{0};
  std::vector<char> on(nodes.size(), 0);
  on[0] = 1;
  int expansions = 0;
  std::function<void()> dfs = [&] {
    if (raw.size() >= 300 || ++expansions > 20000 || hops[0] < 0) return;
    const int cur = stack.back();
    for (int nb : adj[size_t(cur)])
      if (nb == 1) {
        Path p;
        for (int i : stack) p.push_back(nodes[size_t(i)]);
        p.push_back(nodes[1]);
        raw.push_back(p);
        if (raw.size() >= 300) return;
      }
    if (stack.size() >= 20) return;
    for (int nb : adj[size_t(cur)]) {
      if (nb == 1 || on[size_t(nb)] || hops[size_t(nb)] < 0 || int(stack.size()) + 1 + hops[size_t(nb)] > 20) continue;
      on[size_t(nb)] = 1;
      stack.push_back(nb);
      dfs();
      stack.pop_back();
      on[size_t(nb)] = 0;
      if (raw.size() >= 300) return;
    }
  };
  dfs();
  std::vector<size_t> kept;
  for (size_t i = 0; i < raw.size(); ++i) {
    bool eq = false;
    for (size_t k : kept)
      if ((eq = uniformVisibilityEquivalent(raw[i], raw[k], checker))) break;
    if (!eq) kept.push_back(i);
  }
  PrmResult r;
  r.distinct = int(kept.size());
  r.ms = nowMs() - t0;
  return r;
}

}  // namespace

int main(int argc, char** argv) {
  int maps = 10, tasks_per_map = 50, samples = 160, prm_tasks = 100, unproductive = 0;
  for (int i = 1; i + 1 < argc; i += 2) {
    if (!std::strcmp(argv[i], "--maps")) maps = std::max(1, std::atoi(argv[i + 1]));
    if (!std::strcmp(argv[i], "--tasks-per-map")) tasks_per_map = std::max(1, std::atoi(argv[i + 1]));
    if (!std::strcmp(argv[i], "--samples")) samples = std::max(1, std::atoi(argv[i + 1]));
    if (!std::strcmp(argv[i], "--prm-tasks")) prm_tasks = std::max(0, std::atoi(argv[i + 1]));
    if (!std::strcmp(argv[i], "--unproductive")) unproductive = std::max(0, std::atoi(argv[i + 1]));
  }
  const double clearance = 0.3;
  std::printf("# bench_topo: %d maps x %d tasks per density, 20 x 20 x 3 m at 0.1 m, N_max = %d, clearance %.1f m\n",
              maps, tasks_per_map, samples, clearance);
  std::printf("# densities (pillars + floating boxes per m^2): low %.2f+%.2f, medium %.2f+%.2f, high %.2f+%.2f\n\n",
              ForestConfig::preset(ObstacleDensity::kLow).pillars_per_m2,
              ForestConfig::preset(ObstacleDensity::kLow).floating_per_m2,
              ForestConfig::preset(ObstacleDensity::kMedium).pillars_per_m2,
              ForestConfig::preset(ObstacleDensity::kMedium).floating_per_m2,
              ForestConfig::preset(ObstacleDensity::kHigh).pillars_per_m2,
              ForestConfig::preset(ObstacleDensity::kHigh).floating_per_m2);
  std::printf("| density | method | tasks | found | paths (mean) | total ms median | p95 | roadmap | extract | shorten | prune | distinct paths / ms |\n");
  std::printf("|---|---|---|---|---|---|---|---|---|---|---|---|\n");

  std::map<std::string, double> result;
  for (ObstacleDensity density : {ObstacleDensity::kLow, ObstacleDensity::kMedium, ObstacleDensity::kHigh}) {
    const std::string name = toString(density);
    std::vector<double> total, roadmap, extract, shorten, prune, prm_ms;
    double paths = 0.0, prm_distinct = 0.0, topo_distinct_on_prm_tasks = 0.0, topo_ms_on_prm_tasks = 0.0;
    int found = 0, tasks = 0, prm_done = 0;
    for (int m = 0; m < maps; ++m) {
      SyntheticScene scene({20.0, 20.0, 3.0});
      const uint32_t map_seed = 1000u * uint32_t(density) + uint32_t(m);
      scene.forest(density, map_seed);
      const EsdfMap& map = scene.finish();
      const VisibilityChecker checker(map, clearance, true);
      const VisibilityChecker roomy(map, clearance + 0.2, true);
      std::mt19937 rng(map_seed * 7919u + 13u);
      std::uniform_real_distribution<double> ux(1.5, 18.5), uz(1.0, 2.0);
      int made = 0;
      while (made < tasks_per_map) {
        Task t{{ux(rng), ux(rng), uz(rng)}, {ux(rng), ux(rng), uz(rng)}};
        const double d = (t.goal - t.start).norm();
        if (d < 6.0 || d > 10.0 || !roomy.isFree(t.start) || !roomy.isFree(t.goal) || checker.lineVisible(t.start, t.goal))
          continue;
        ++made;
        ++tasks;
        TopoPathSearch::Config c;
        c.clearance_m = clearance;
        c.roadmap.max_samples = samples;
        c.roadmap.max_unproductive_samples = unproductive;
        c.seed = uint32_t(tasks);
        TopoPathSearch search(c);
        const TopoSearchResult r = search.search(map, t.start, t.goal);
        found += r.status == SearchStatus::kSuccess;
        paths += double(r.paths.size());
        total.push_back(r.stats.total_ms);
        roadmap.push_back(r.stats.roadmap_ms);
        extract.push_back(r.stats.extraction_ms);
        shorten.push_back(r.stats.shortening_ms);
        prune.push_back(r.stats.pruning_ms);
        if (prm_done < prm_tasks * (m + 1) / maps) {
          const PrmResult p = plainPrm(map, t, samples, clearance, uint32_t(tasks));
          prm_ms.push_back(p.ms);
          prm_distinct += p.distinct;
          topo_distinct_on_prm_tasks += r.stats.distinct_paths;
          topo_ms_on_prm_tasks += r.stats.total_ms;
          ++prm_done;
        }
      }
      std::fprintf(stderr, "\r%-6s map %2d/%d", name.c_str(), m + 1, maps);
    }
    std::fprintf(stderr, "\n");
    const double topo_rate = topo_distinct_on_prm_tasks / std::max(1e-9, topo_ms_on_prm_tasks);
    const double prm_sum_ms = std::accumulate(prm_ms.begin(), prm_ms.end(), 0.0);
    const double prm_rate = prm_distinct / std::max(1e-9, prm_sum_ms);
    std::printf("| %s | topological (ours) | %d | %.1f%% | %.2f | %.3f | %.3f | %.3f | %.3f | %.3f | %.3f | %.2f |\n",
                name.c_str(), tasks, 100.0 * found / tasks, paths / tasks, percentile(total, 0.5),
                percentile(total, 0.95), percentile(roadmap, 0.5), percentile(extract, 0.5), percentile(shorten, 0.5),
                percentile(prune, 0.5), topo_rate);
    std::printf("| %s | plain PRM + UVD filter | %d | - | %.2f (distinct) | %.3f | %.3f | - | - | - | - | %.2f |\n",
                name.c_str(), prm_done, prm_done ? prm_distinct / prm_done : 0.0, percentile(prm_ms, 0.5),
                percentile(prm_ms, 0.95), prm_rate);
    result["search_ms_median_" + name] = percentile(total, 0.5);
    result["search_ms_p95_" + name] = percentile(total, 0.95);
    result["paths_mean_" + name] = paths / tasks;
    result["found_rate_" + name] = double(found) / tasks;
    result["prm_ms_median_" + name] = percentile(prm_ms, 0.5);
    result["distinct_per_ms_ratio_" + name] = prm_rate > 0 ? topo_rate / prm_rate : 0.0;
  }
  std::printf("\nRESULT");
  for (const char* k : {"search_ms_median_low", "search_ms_median_medium", "search_ms_median_high", "search_ms_p95_medium",
                        "paths_mean_medium", "found_rate_low", "found_rate_medium", "found_rate_high",
                        "prm_ms_median_medium", "distinct_per_ms_ratio_medium"})
    std::printf(" %s=%.4g", k, result[k]);
  std::printf("\n");
  return 0;
}
