// The topological search on synthetic scenes: the paper's claims as checkable facts.
#include <gtest/gtest.h>
#include <malloc.h>

#include <atomic>
#include <random>
#include <new>

#include "topo_planner/path_searching/grid_astar.h"
#include "topo_planner/plan_env/raycast.h"
#include "topo_planner/path_searching/topo_path_search.h"
#include "topo_planner/plan_env/synthetic_scene.h"

// Live heap bytes of this test binary, for the memory test: every replaceable form of global new
// and delete goes through these two (under AddressSanitizer too).
static std::atomic<long long> g_live_bytes{0};
static void* countedAlloc(size_t n) noexcept {
  void* p = std::malloc(n ? n : 1);
  if (p) g_live_bytes += (long long)malloc_usable_size(p);
  return p;
}
static void countedFree(void* p) noexcept {
  if (!p) return;
  g_live_bytes -= (long long)malloc_usable_size(p);
  std::free(p);
}
void* operator new(size_t n) {
  if (void* p = countedAlloc(n)) return p;
  throw std::bad_alloc();
}
void* operator new[](size_t n) {
  if (void* p = countedAlloc(n)) return p;
  throw std::bad_alloc();
}
void* operator new(size_t n, const std::nothrow_t&) noexcept { return countedAlloc(n); }
void* operator new[](size_t n, const std::nothrow_t&) noexcept { return countedAlloc(n); }
void operator delete(void* p) noexcept { countedFree(p); }
void operator delete[](void* p) noexcept { countedFree(p); }
void operator delete(void* p, size_t) noexcept { countedFree(p); }
void operator delete[](void* p, size_t) noexcept { countedFree(p); }
void operator delete(void* p, const std::nothrow_t&) noexcept { countedFree(p); }
void operator delete[](void* p, const std::nothrow_t&) noexcept { countedFree(p); }

namespace topo_planner {
namespace {

TopoPathSearch::Config searchConfig(int samples = 400) {
  TopoPathSearch::Config c;
  c.clearance_m = 0.3;
  c.roadmap.max_samples = samples;
  c.seed = 7;
  return c;
}

// True when every voxel every segment passes through keeps the clearance: an oracle independent of
// the sphere tracing in VisibilityChecker (a plain DDA reading every voxel).
bool collisionFree(const Path& p, const EsdfMap& map, double clearance) {
  const VisibilityChecker checker(map, clearance, true);
  for (size_t i = 1; i < p.size(); ++i) {
    const bool clear = traverseVoxels(p[i - 1], p[i], map.geometry().resolution(),
                                      [&](const Eigen::Vector3i& v) { return checker.isFreeVoxel(v); });
    if (!clear) return false;
  }
  return true;
}

TEST(Visibility, SphereTracingAgreesWithAPlainDda) {
  SyntheticScene scene({10.0, 8.0, 3.0});
  scene.pillar(5.0, 4.0, 0.5);
  scene.pillar(3.0, 2.5, 0.4);
  scene.box({6.5, 5.0, 0.5}, {7.5, 6.0, 1.5});
  const EsdfMap& map = scene.finish();
  const VisibilityChecker checker(map, 0.3, true);
  std::mt19937 rng(17);
  std::uniform_real_distribution<double> ux(0.3, 9.7), uy(0.3, 7.7), uz(0.3, 2.7);
  int blocked = 0;
  for (int k = 0; k < 3000; ++k) {
    const Eigen::Vector3d a(ux(rng), uy(rng), uz(rng)), b(ux(rng), uy(rng), uz(rng));
    const bool dda = collisionFree({a, b}, map, 0.3);
    ASSERT_EQ(checker.lineVisible(a, b), dda) << a.transpose() << " -> " << b.transpose();
    blocked += !dda;
  }
  EXPECT_GT(blocked, 300);  // both outcomes well represented
  EXPECT_LT(blocked, 2700);
}

// Lateral (y) offset of the path where it crosses x = x0.
double yAtX(const Path& p, double x0) {
  for (size_t i = 1; i < p.size(); ++i)
    if ((p[i - 1].x() - x0) * (p[i].x() - x0) <= 0.0 && p[i].x() != p[i - 1].x())
      return p[i - 1].y() + (p[i].y() - p[i - 1].y()) * (x0 - p[i - 1].x()) / (p[i].x() - p[i - 1].x());
  return NAN;
}
Eigen::Vector3d pointAtX(const Path& p, double x0) {
  for (size_t i = 1; i < p.size(); ++i)
    if ((p[i - 1].x() - x0) * (p[i].x() - x0) <= 0.0 && p[i].x() != p[i - 1].x())
      return p[i - 1] + (p[i] - p[i - 1]) * ((x0 - p[i - 1].x()) / (p[i].x() - p[i - 1].x()));
  return Eigen::Vector3d::Constant(NAN);
}

void expectPairwiseDistinct(const std::vector<Path>& paths, const EsdfMap& map, double clearance) {
  const VisibilityChecker checker(map, clearance, true);
  for (size_t a = 0; a < paths.size(); ++a)
    for (size_t b = a + 1; b < paths.size(); ++b)
      EXPECT_FALSE(uniformVisibilityEquivalent(paths[a], paths[b], checker)) << a << " vs " << b;
}

TEST(TopoSearch, FreeStraightLineGivesTheSegment) {
  SyntheticScene scene({10.0, 8.0, 3.0});
  const EsdfMap& map = scene.finish();
  TopoPathSearch search(searchConfig());
  const Eigen::Vector3d s(1, 4, 1.5), g(9, 4, 1.5);
  const TopoSearchResult r = search.search(map, s, g);
  ASSERT_EQ(r.status, SearchStatus::kSuccess);
  ASSERT_EQ(r.paths.size(), 1u);
  ASSERT_EQ(r.paths[0].size(), 2u);
  EXPECT_TRUE(r.paths[0][0].isApprox(s));
  EXPECT_TRUE(r.paths[0][1].isApprox(g));
}

TEST(TopoSearch, OnePillarGivesLeftAndRight) {
  SyntheticScene scene({10.0, 8.0, 3.0});
  scene.pillar(5.0, 4.0, 0.5);
  const EsdfMap& map = scene.finish();
  TopoPathSearch search(searchConfig());
  const TopoSearchResult r = search.search(map, {1, 4, 1.5}, {9, 4, 1.5});
  ASSERT_EQ(r.status, SearchStatus::kSuccess) << toString(r.status);
  ASSERT_EQ(r.paths.size(), 2u);
  const double y0 = yAtX(r.paths[0], 5.0), y1 = yAtX(r.paths[1], 5.0);
  // One passes on each side, clear of the pillar: radius 0.5 + clearance 0.3, less one voxel
  // (clearance is measured between voxel centres).
  EXPECT_LT(std::min(y0, y1), 4.0 - 0.7);
  EXPECT_GT(std::max(y0, y1), 4.0 + 0.7);
  for (const Path& p : r.paths) EXPECT_TRUE(collisionFree(p, map, 0.3));
  expectPairwiseDistinct(r.paths, map, 0.3);
  EXPECT_GT(r.stats.roadmap.guards, 2);
  EXPECT_GE(r.stats.raw_paths, 2);
  // Shortened paths hug the pillar: not much longer than the straight line.
  for (const Path& p : r.paths) EXPECT_LT(pathLength(p), 8.0 * 1.12);
}

TEST(TopoSearch, WallWithTwoWindowsGivesOnePathThroughEach) {
  SyntheticScene scene({10.0, 8.0, 4.0});
  // Wall x in [4.85, 5.15] across the whole map, with two 1.2 m windows centred at y = 2 and 6, z = 2.
  scene.fill([](const Eigen::Vector3d& p) {
    if (p.x() < 4.85 || p.x() > 5.15) return false;
    const bool in_window = std::abs(p.z() - 2.0) < 0.6 && (std::abs(p.y() - 2.0) < 0.6 || std::abs(p.y() - 6.0) < 0.6);
    return !in_window;
  });
  const EsdfMap& map = scene.finish();
  TopoPathSearch search(searchConfig(600));
  const TopoSearchResult r = search.search(map, {2, 4, 2}, {8, 4, 2});
  ASSERT_EQ(r.status, SearchStatus::kSuccess) << toString(r.status);
  ASSERT_EQ(r.paths.size(), 2u);
  // Each passes the wall inside one of the openings (|y - centre| < 0.6, |z - 2| < 0.6).
  std::vector<Eigen::Vector3d> at_wall{pointAtX(r.paths[0], 5.0), pointAtX(r.paths[1], 5.0)};
  std::sort(at_wall.begin(), at_wall.end(), [](const auto& a, const auto& b) { return a.y() < b.y(); });
  EXPECT_LT(std::abs(at_wall[0].y() - 2.0), 0.6);
  EXPECT_LT(std::abs(at_wall[1].y() - 6.0), 0.6);
  for (const auto& p : at_wall) EXPECT_LT(std::abs(p.z() - 2.0), 0.6);
  for (const Path& p : r.paths) EXPECT_TRUE(collisionFree(p, map, 0.3));
}

TEST(TopoSearch, FloatingBoxOverUnderLeftRight) {
  SyntheticScene scene({10.0, 8.0, 4.0});
  scene.box({4.2, 3.2, 1.4}, {5.8, 4.8, 2.6});
  const EsdfMap& map = scene.finish();
  TopoPathSearch::Config c = searchConfig(800);
  c.roadmap.sample_inflation_m = {1.0, 2.5, 1.8};
  TopoPathSearch search(c);
  const TopoSearchResult r = search.search(map, {1.5, 4, 2}, {8.5, 4, 2});
  ASSERT_EQ(r.status, SearchStatus::kSuccess) << toString(r.status);
  bool over = false, under = false, left = false, right = false;
  for (const Path& p : r.paths) {
    const Eigen::Vector3d q = pointAtX(p, 5.0);
    over |= q.z() > 2.6;
    under |= q.z() < 1.4;
    left |= q.y() > 4.8;
    right |= q.y() < 3.2;
    EXPECT_TRUE(collisionFree(p, map, 0.3));
  }
  EXPECT_TRUE(over && under && left && right) << over << under << left << right << " of " << r.paths.size();
  expectPairwiseDistinct(r.paths, map, 0.3);
}

// The height band: with its top below the box, no guide path goes over it.
TEST(TopoSearch, TheHeightBandKeepsSamplesInside) {
  SyntheticScene scene({10.0, 8.0, 4.0});
  scene.box({4.2, 3.2, 1.4}, {5.8, 4.8, 2.6});
  const EsdfMap& map = scene.finish();
  TopoPathSearch::Config c = searchConfig(800);
  c.roadmap.sample_inflation_m = {1.0, 2.5, 1.8};
  c.roadmap.max_z_m = 2.6;
  TopoPathSearch search(c);
  const TopoSearchResult r = search.search(map, {1.5, 4, 2}, {8.5, 4, 2});
  ASSERT_EQ(r.status, SearchStatus::kSuccess) << toString(r.status);
  for (const Path& p : r.paths)
    for (const Eigen::Vector3d& q : p) EXPECT_LE(q.z(), 2.6) << q.transpose();
}

TEST(TopoSearch, VerticalStartToGoalDirectionWorks) {
  SyntheticScene scene({6.0, 6.0, 6.0});
  scene.box({2.0, 2.0, 2.8}, {4.0, 4.0, 3.2});  // a slab between start and goal
  const EsdfMap& map = scene.finish();
  TopoPathSearch::Config c = searchConfig(600);
  c.roadmap.sample_inflation_m = {0.5, 2.0, 2.0};
  TopoPathSearch search(c);
  const TopoSearchResult r = search.search(map, {3, 3, 1}, {3, 3, 5});
  ASSERT_EQ(r.status, SearchStatus::kSuccess) << toString(r.status);
  EXPECT_GE(r.paths.size(), 2u);
  for (const Path& p : r.paths) EXPECT_TRUE(collisionFree(p, map, 0.3));
}

TEST(TopoSearch, ShorteningIsSafeNotLongerAndEquivalent) {
  SyntheticScene scene({10.0, 8.0, 3.0});
  scene.pillar(5.0, 4.0, 0.5);
  scene.pillar(3.0, 2.5, 0.4);
  scene.pillar(7.0, 5.8, 0.4);
  const EsdfMap& map = scene.finish();
  TopoPathSearch::Config c = searchConfig(600);
  c.keep_raw_paths = true;
  TopoPathSearch search(c);
  const TopoSearchResult r = search.search(map, {1, 4, 1.5}, {9, 4, 1.5});
  ASSERT_EQ(r.status, SearchStatus::kSuccess);
  ASSERT_GE(r.raw_paths.size(), 3u);
  const VisibilityChecker checker(map, 0.3, true);
  const PathShortener shortener(checker);
  int shortened = 0;
  for (const Path& raw : r.raw_paths) {
    ASSERT_TRUE(collisionFree(raw, map, 0.3));
    bool fell_back = false;
    const Path s = shortener.shorten(raw, &fell_back);
    EXPECT_TRUE(collisionFree(s, map, 0.3));
    EXPECT_LE(pathLength(s), pathLength(raw) + 1e-9);
    EXPECT_TRUE(uniformVisibilityEquivalent(s, raw, checker));
    EXPECT_TRUE(s.front().isApprox(raw.front()) && s.back().isApprox(raw.back()));
    shortened += !fell_back && pathLength(s) < pathLength(raw) - 1e-6;
  }
  EXPECT_GT(shortened, int(r.raw_paths.size()) / 2);  // it really shortens
  // A deliberate detour is shortened towards the pillar but stays on its side.
  const Path detour{{1, 4, 1.5}, {2, 7.5, 1.5}, {8, 7.5, 1.5}, {9, 4, 1.5}};
  const Path s = shortener.shorten(detour);
  EXPECT_LT(pathLength(s), pathLength(detour) - 1.0);
  EXPECT_GT(yAtX(s, 5.0), 4.0);
}

TEST(TopoSearch, BadInputsGetTheirStatus) {
  SyntheticScene scene({10.0, 8.0, 3.0});
  scene.pillar(5.0, 4.0, 0.5);
  const EsdfMap& map = scene.finish();
  TopoPathSearch search(searchConfig());
  EXPECT_EQ(search.search(map, {5, 4, 1.5}, {9, 4, 1.5}).status, SearchStatus::kStartInObstacle);
  EXPECT_EQ(search.search(map, {1, 4, 1.5}, {5.2, 4, 1.5}).status, SearchStatus::kGoalInObstacle);
  EXPECT_EQ(search.search(map, {1, 4, 1.5}, {19, 4, 1.5}).status, SearchStatus::kOutOfMap);
  EXPECT_EQ(search.search(map, {-1, 4, 1.5}, {9, 4, 1.5}).status, SearchStatus::kOutOfMap);
  EXPECT_EQ(search.search(map, {NAN, 4, 1.5}, {9, 4, 1.5}).status, SearchStatus::kInvalidInput);
  EXPECT_EQ(search.search(map, {1, 4, INFINITY}, {9, 4, 1.5}).status, SearchStatus::kInvalidInput);
  EXPECT_EQ(search.search(map, {1, 4, 1.5}, {1, 4, 1.5}).status, SearchStatus::kInvalidInput);
  TopoPathSearch::Config bad = searchConfig();
  bad.max_paths = 0;
  EXPECT_EQ(TopoPathSearch(bad).search(map, {1, 4, 1.5}, {9, 4, 1.5}).status, SearchStatus::kInvalidInput);
  // One sample, no extra budget, cannot connect around the pillar; with the extra budget it does.
  TopoPathSearch::Config one = searchConfig(1);
  one.roadmap.max_extra_samples = 0;
  EXPECT_EQ(TopoPathSearch(one).search(map, {1, 4, 1.5}, {9, 4, 1.5}).status, SearchStatus::kBudgetExhausted);
  one.roadmap.max_extra_samples = 600;
  EXPECT_EQ(TopoPathSearch(one).search(map, {1, 4, 1.5}, {9, 4, 1.5}).status, SearchStatus::kSuccess);
}

TEST(TopoSearch, SameSeedSameResult) {
  SyntheticScene scene({10.0, 8.0, 3.0});
  scene.pillar(5.0, 4.0, 0.5);
  scene.pillar(3.0, 2.5, 0.4);
  const EsdfMap& map = scene.finish();
  TopoPathSearch a(searchConfig()), b(searchConfig());
  const TopoSearchResult ra = a.search(map, {1, 4, 1.5}, {9, 4, 1.5});
  const TopoSearchResult rb1 = b.search(map, {1, 4, 1.5}, {9, 4, 1.5});
  const TopoSearchResult rb2 = b.search(map, {1, 4, 1.5}, {9, 4, 1.5});
  ASSERT_EQ(ra.paths.size(), rb1.paths.size());
  for (size_t i = 0; i < ra.paths.size(); ++i) {
    EXPECT_EQ(ra.paths[i], rb1.paths[i]);
    EXPECT_EQ(rb1.paths[i], rb2.paths[i]);
  }
  TopoPathSearch::Config other = searchConfig();
  other.seed = 8;
  const TopoSearchResult rc = TopoPathSearch(other).search(map, {1, 4, 1.5}, {9, 4, 1.5});
  EXPECT_EQ(rc.status, SearchStatus::kSuccess);  // another seed samples differently but still succeeds
  EXPECT_GE(rc.paths.size(), 2u);
}

TEST(TopoSearch, MemoryDoesNotGrowOver10000Calls) {
  SyntheticScene scene({6.0, 4.0, 2.0});
  scene.pillar(3.0, 2.0, 0.4);
  const EsdfMap& map = scene.finish();
  TopoPathSearch::Config c = searchConfig(60);
  c.roadmap.sample_inflation_m = {0.5, 1.5, 0.5};
  TopoPathSearch search(c);
  search.search(map, {0.8, 2, 1}, {5.2, 2, 1});  // the first call sizes the reusable buffers
  const long long before = g_live_bytes.load();
  int found = 0;
  for (int i = 0; i < 10000; ++i) found += search.search(map, {0.8, 2, 1}, {5.2, 2, 1}).status == SearchStatus::kSuccess;
  EXPECT_EQ(g_live_bytes.load(), before);
  EXPECT_EQ(found, 10000);
}

TEST(GridAStar, FindsACollisionFreeNearShortestPath) {
  SyntheticScene scene({10.0, 8.0, 3.0});
  scene.pillar(5.0, 4.0, 0.5);
  const EsdfMap& map = scene.finish();
  GridAStar::Config c;
  c.clearance_m = 0.3;
  GridAStar astar(c);
  const GridAStar::Result r = astar.search(map, {1, 4, 1.5}, {9, 4, 1.5});
  ASSERT_EQ(r.status, SearchStatus::kSuccess);
  const VisibilityChecker checker(map, 0.3, true);
  for (const auto& p : r.path) EXPECT_TRUE(checker.isFree(p));
  EXPECT_LT(pathLength(r.path), 8.0 * 1.25);
  EXPECT_GT(r.expansions, 0);
  // Repeated searches reuse the buffers and give the same path.
  EXPECT_EQ(astar.search(map, {1, 4, 1.5}, {9, 4, 1.5}).path, r.path);
}

// The weighted heuristic (Config::heuristic_weight): in a forest the path is at most that factor
// longer than plain A*'s shortest grid path, found with a fraction of its expansions.
TEST(GridAStar, TheWeightedHeuristicExpandsLessForANearShortestPath) {
  SyntheticScene scene({20.0, 20.0, 3.0});
  scene.forest(ObstacleDensity::kHigh, 31);
  const EsdfMap& map = scene.finish();
  GridAStar::Config c;
  c.clearance_m = 0.3;
  c.heuristic_weight = 1.0;
  GridAStar plain(c);
  c.heuristic_weight = 1.5;
  GridAStar weighted(c);
  const VisibilityChecker roomy(map, 0.6, true), free(map, 0.3, true);
  std::mt19937 rng(11);
  std::uniform_real_distribution<double> uxy(1.5, 18.5), uz(1.0, 2.0);
  long plain_expansions = 0, weighted_expansions = 0;
  int searches = 0;
  while (searches < 10) {
    const Eigen::Vector3d start(uxy(rng), uxy(rng), uz(rng)), goal(uxy(rng), uxy(rng), uz(rng));
    if ((goal - start).norm() < 8.0 || !roomy.isFree(start) || !roomy.isFree(goal)) continue;
    const GridAStar::Result a = plain.search(map, start, goal), b = weighted.search(map, start, goal);
    ASSERT_EQ(a.status, b.status);
    if (a.status != SearchStatus::kSuccess) continue;
    ++searches;
    for (const Eigen::Vector3d& p : b.path) EXPECT_TRUE(free.isFree(p) || p == start || p == goal);
    EXPECT_LE(pathLength(b.path), 1.5 * pathLength(a.path) + 1e-9);
    plain_expansions += a.expansions;
    weighted_expansions += b.expansions;
  }
  EXPECT_LT(weighted_expansions, plain_expansions / 3);
  std::printf("10 forest searches: %ld expansions plain, %ld weighted\n", plain_expansions, weighted_expansions);
}

TEST(GridAStar, ReportsNoPathBudgetAndObstacles) {
  SyntheticScene scene({10.0, 8.0, 3.0});
  scene.box({4.8, -1.0, -1.0}, {5.2, 9.0, 4.0});  // a wall with no opening
  const EsdfMap& map = scene.finish();
  GridAStar::Config c;
  c.search_margin_m = 1.0;
  GridAStar astar(c);
  EXPECT_EQ(astar.search(map, {1, 4, 1.5}, {9, 4, 1.5}).status, SearchStatus::kNoPath);
  EXPECT_EQ(astar.search(map, {5, 4, 1.5}, {9, 4, 1.5}).status, SearchStatus::kStartInObstacle);
  EXPECT_EQ(astar.search(map, {1, 4, 1.5}, {5, 4, 1.5}).status, SearchStatus::kGoalInObstacle);
  EXPECT_EQ(astar.search(map, {1, 4, 1.5}, {90, 4, 1.5}).status, SearchStatus::kOutOfMap);
  EXPECT_EQ(astar.search(map, {NAN, 4, 1.5}, {9, 4, 1.5}).status, SearchStatus::kInvalidInput);
  c.max_expansions = 10;
  EXPECT_EQ(GridAStar(c).search(map, {1, 4, 1.5}, {4, 4, 1.5}).status, SearchStatus::kBudgetExhausted);
}

// The height band holds the voxels whose centres lie in it. A wall topped at 2.0 m under a band
// ending at 2.32 m leaves 0.32 m, too little for a clearance of 0.35 m; the voxel holding the band's
// top (centre 2.35 m, 0.4 m above the wall's top voxel) lies half a voxel outside it, and once let
// the search over the wall where the optimiser's band face would not (a flight failed 15 times so).
TEST(GridAStar, KeepsToTheHeightBand) {
  SyntheticScene scene({10.0, 8.0, 4.0});
  scene.box({4.8, -1.0, -1.0}, {5.2, 9.0, 2.0});  // a wall with no opening, 2 m high
  const EsdfMap& map = scene.finish();
  GridAStar::Config c;
  c.search_margin_m = 1.0;
  c.clearance_m = 0.35;
  c.max_z_m = 2.32;
  EXPECT_EQ(GridAStar(c).search(map, {1, 4, 1.5}, {9, 4, 1.5}).status, SearchStatus::kNoPath);
  c.max_z_m = 2.5;  // room over the wall
  const GridAStar::Result r = GridAStar(c).search(map, {1, 4, 1.5}, {9, 4, 1.5});
  ASSERT_EQ(r.status, SearchStatus::kSuccess);
  double top = 0.0;
  for (const auto& p : r.path) top = std::max(top, p.z());
  EXPECT_GT(top, 2.3);
  EXPECT_LE(top, 2.5);
}

}  // namespace
}  // namespace topo_planner
