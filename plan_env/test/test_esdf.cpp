// ESDF against brute force, incremental against full recompute, gradients against finite differences.
#include <gtest/gtest.h>

#include <random>

#include "topo_planner/plan_env/distance_transform.h"
#include "topo_planner/plan_env/esdf_map.h"
#include "topo_planner/plan_env/synthetic_scene.h"
#include "test_helpers.h"

namespace topo_planner {
namespace {

// Brute-force signed distance between voxel centres, truncated at max_d.
std::vector<double> bruteForce(const OccupancyMap& map, double max_d, bool unknown_as_occupied) {
  const GridGeometry& g = map.geometry();
  const VoxelBox w = g.windowBox();
  std::vector<Eigen::Vector3i> voxels;
  std::vector<bool> site;
  Eigen::Vector3i i;
  for (i.z() = w.min.z(); i.z() <= w.max.z(); ++i.z())
    for (i.y() = w.min.y(); i.y() <= w.max.y(); ++i.y())
      for (i.x() = w.min.x(); i.x() <= w.max.x(); ++i.x()) {
        voxels.push_back(i);
        const VoxelState s = map.state(i);
        site.push_back(s == VoxelState::kOccupied || (unknown_as_occupied && s == VoxelState::kUnknown));
      }
  std::vector<double> out(voxels.size());
  for (size_t a = 0; a < voxels.size(); ++a) {
    double best = INFINITY;
    for (size_t b = 0; b < voxels.size(); ++b)
      if (site[b] != site[a]) best = std::min(best, (voxels[a] - voxels[b]).cast<double>().norm() * g.resolution());
    best = std::min(best, max_d);
    out[a] = site[a] ? -best : best;
  }
  return out;
}

std::vector<double> fieldInScanOrder(const EsdfMap& esdf) {
  const VoxelBox w = esdf.geometry().windowBox();
  std::vector<double> out;
  Eigen::Vector3i i;
  for (i.z() = w.min.z(); i.z() <= w.max.z(); ++i.z())
    for (i.y() = w.min.y(); i.y() <= w.max.y(); ++i.y())
      for (i.x() = w.min.x(); i.x() <= w.max.x(); ++i.x()) {
        double d = NAN;
        esdf.distance(i, &d);
        out.push_back(d);
      }
  return out;
}

TEST(DistanceTransform, LowerEnvelopeMatchesBruteForce) {
  std::mt19937 rng(7);
  std::uniform_int_distribution<int32_t> val(0, 2000);
  std::uniform_real_distribution<float> coin(0.0f, 1.0f);
  for (int trial = 0; trial < 400; ++trial) {
    const int n = 1 + trial % 57;
    std::vector<int32_t> f(n), d(n), v(n);
    std::vector<int64_t> zn(n + 1), zd(n + 1);
    const float p_empty = trial % 4 == 0 ? 0.95f : 0.4f;
    for (int32_t& x : f) x = coin(rng) < p_empty ? kNoSite : val(rng) % (1 + trial * 5);
    lowerEnvelopeTransform(f.data(), d.data(), n, v.data(), zn.data(), zd.data());
    for (int q = 0; q < n; ++q) {
      int64_t best = kNoSite;
      for (int p = 0; p < n; ++p)
        if (f[p] < kNoSite) best = std::min<int64_t>(best, int64_t(q - p) * (q - p) + f[p]);
      ASSERT_EQ(d[q], best) << "trial " << trial << " q " << q;
    }
  }
}

TEST(DistanceTransform, BinaryLineMatchesBruteForce) {
  std::mt19937 rng(9);
  std::uniform_real_distribution<float> coin(0.0f, 1.0f);
  for (int trial = 0; trial < 300; ++trial) {
    const int n = 1 + trial % 45;
    const int32_t cap = 1 + trial % 30;
    std::vector<uint8_t> site(n);
    std::vector<int32_t> d(n);
    for (auto& s : site) s = coin(rng) < 0.1f + 0.003f * trial;
    binaryLineTransform(site.data(), d.data(), n, cap);
    for (int q = 0; q < n; ++q) {
      int32_t best = kNoSite;
      for (int p = 0; p < n; ++p)
        if (site[p]) best = std::min(best, (q - p) * (q - p));
      ASSERT_EQ(d[q], best >= cap ? kNoSite : best) << "trial " << trial << " q " << q;
    }
    // The pair version: the same for the sites, and for the non-sites.
    std::vector<float> pos(n), neg(n);
    binaryLineTransformPair(site.data(), pos.data(), neg.data(), n, cap);
    for (int q = 0; q < n; ++q) {
      int32_t best_free = kNoSite;
      for (int p = 0; p < n; ++p)
        if (!site[p]) best_free = std::min(best_free, (q - p) * (q - p));
      ASSERT_EQ(pos[q], d[q] >= kNoSite ? INFINITY : float(d[q]));
      ASSERT_EQ(neg[q], best_free >= cap ? INFINITY : float(best_free));
    }
  }
}

TEST(DistanceTransform, BoundedSearchEqualsTruncatedEnvelope) {
  std::mt19937 rng(8);
  std::uniform_int_distribution<int32_t> val(0, 30);
  std::uniform_real_distribution<float> coin(0.0f, 1.0f);
  for (int trial = 0; trial < 300; ++trial) {
    const int n = 1 + trial % 41;
    const int32_t cap = 1 + trial % 50;
    std::vector<int32_t> f(n), exact(n), bounded(n), v(n);
    std::vector<int64_t> zn(n + 1), zd(n + 1);
    for (int32_t& x : f) x = coin(rng) < 0.3f ? 0 : (coin(rng) < 0.1f ? kNoSite : val(rng));
    lowerEnvelopeTransform(f.data(), exact.data(), n, v.data(), zn.data(), zd.data());
    boundedLineTransform(f.data(), bounded.data(), n, cap);
    for (int q = 0; q < n; ++q) ASSERT_EQ(bounded[q], std::min(exact[q], cap)) << "trial " << trial << " q " << q;
  }
}

class EsdfBruteForce : public ::testing::TestWithParam<std::tuple<double, double, bool>> {};

TEST_P(EsdfBruteForce, FullFieldIsExactAtVoxelCentres) {
  const double p_occ = std::get<0>(GetParam());
  const double max_d = std::get<1>(GetParam());
  const bool unknown_as_occupied = std::get<2>(GetParam());
  std::mt19937 rng(1234 + int(p_occ * 100) + int(max_d * 10));
  for (int trial = 0; trial < 3; ++trial) {
    auto occ = test::makeMap({1.4, 1.2, 1.0}, {-0.7 + 0.1 * trial, -0.3, 0.2});
    ASSERT_TRUE(occ);
    test::randomFill(occ.get(), p_occ, &rng, unknown_as_occupied ? 0.1 : 0.05);
    auto esdf = test::makeEsdf(occ, max_d, unknown_as_occupied, 1 + trial % 2);
    ASSERT_TRUE(esdf);
    esdf->updateAll();
    const std::vector<double> expected = bruteForce(*occ, max_d, unknown_as_occupied);
    const std::vector<double> got = fieldInScanOrder(*esdf);
    ASSERT_EQ(expected.size(), got.size());
    int negative = 0, positive = 0;
    for (size_t k = 0; k < got.size(); ++k) {
      ASSERT_NEAR(got[k], expected[k], 1e-5) << "voxel " << k;
      negative += expected[k] < 0;
      positive += expected[k] > 0;
    }
    EXPECT_GT(positive, 0);
    if (p_occ > 0.0) {
      EXPECT_GT(negative, 0);
    }
  }
}

INSTANTIATE_TEST_SUITE_P(Densities, EsdfBruteForce,
                         // 10 m truncation: the lower-envelope path; 0.35 m and 0.8 m: the windowed path.
                         ::testing::Values(std::make_tuple(0.02, 10.0, false), std::make_tuple(0.2, 10.0, false),
                                           std::make_tuple(0.7, 10.0, false), std::make_tuple(0.1, 0.35, false),
                                           std::make_tuple(0.1, 10.0, true), std::make_tuple(0.02, 0.8, false),
                                           std::make_tuple(0.3, 0.8, false), std::make_tuple(0.1, 0.8, true)));

TEST(Esdf, EmptyMapIsTruncatedEverywhere) {
  auto occ = test::makeMap({1.0, 1.0, 1.0}, {0, 0, 0});
  auto esdf = test::makeEsdf(occ, 0.5);
  esdf->updateAll();
  for (float d : esdf->distances()) EXPECT_FLOAT_EQ(d, 0.5f);
}

class EsdfIncremental : public ::testing::TestWithParam<double> {};

TEST_P(EsdfIncremental, IncrementalUpdateEqualsFullRecompute) {
  const double max_d = GetParam();
  std::mt19937 rng(99);
  // Long in x, so that even the 4 m truncation (40-voxel margins) leaves room for partial updates.
  auto occ = test::makeMap({max_d < 1.0 ? 3.0 : 12.0, 2.6, 2.0}, {-1.5, -1.0, 0.0});
  test::randomFill(occ.get(), 0.08, &rng);
  auto incremental = test::makeEsdf(occ, max_d);
  incremental->updateAll();
  const int nx = occ->geometry().size().x();
  std::uniform_int_distribution<int> coord(0, 29);
  std::uniform_int_distribution<int> coord_x(0, nx - 1);
  std::uniform_int_distribution<int> extent(0, 4);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  const Eigen::Vector3i origin = occ->geometry().originIndex();
  int partial_updates = 0;
  for (int round = 0; round < 25; ++round) {
    // Change a random small box: add and remove obstacles.
    const Eigen::Vector3i lo = origin + Eigen::Vector3i(coord_x(rng), coord(rng) % 26, coord(rng) % 20);
    const VoxelBox box =
        VoxelBox::fromCorners(lo, lo + Eigen::Vector3i(extent(rng), extent(rng), extent(rng))).intersection(
            occ->geometry().windowBox());
    Eigen::Vector3i i;
    for (i.z() = box.min.z(); i.z() <= box.max.z(); ++i.z())
      for (i.y() = box.min.y(); i.y() <= box.max.y(); ++i.y())
        for (i.x() = box.min.x(); i.x() <= box.max.x(); ++i.x())
          occ->setState(i, u(rng) < 0.5 ? VoxelState::kOccupied : VoxelState::kFree);
    const EsdfUpdateStats stats = incremental->update(box);
    partial_updates += !stats.full;
    auto full = test::makeEsdf(occ, max_d);
    full->updateAll();
    ASSERT_EQ(full->distances().size(), incremental->distances().size());
    for (size_t k = 0; k < full->distances().size(); ++k)
      ASSERT_FLOAT_EQ(incremental->distances()[k], full->distances()[k]) << "round " << round << " address " << k;
  }
  EXPECT_GT(partial_updates, max_d < 1.0 ? 20 : 5);  // the updates really were local
}

// 0.45 m: the windowed path; 4 m: the lower-envelope path (40 voxels), both with partial updates.
INSTANTIATE_TEST_SUITE_P(Truncations, EsdfIncremental, ::testing::Values(0.45, 4.0));

TEST(Esdf, FusionChangedBoxKeepsFieldExact) {
  auto occ = test::makeMap({6.0, 4.0, 3.0}, {-1.0, -2.0, -0.5});
  auto esdf = test::makeEsdf(occ, 0.6);
  esdf->updateAll();
  const PinholeCamera cam = test::smallCamera();
  for (int frame = 0; frame < 4; ++frame) {
    const auto T = test::cameraLookingAlongX({0.0, 0.1 * frame, 1.0});
    const auto depth = test::renderBox(cam, T, {2.05, -0.45, 0.55}, {2.65, 0.45, 1.45});
    const FusionResult r = occ->fuseDepthImage(test::viewOf(depth, cam), cam, T);
    ASSERT_EQ(r.status, MapStatus::kSuccess);
    esdf->update(r.changed_box);
  }
  auto full = test::makeEsdf(occ, 0.6);
  full->updateAll();
  for (size_t k = 0; k < full->distances().size(); ++k) ASSERT_FLOAT_EQ(esdf->distances()[k], full->distances()[k]);
}

TEST(Esdf, TrilinearGradientMatchesFiniteDifferences) {
  std::mt19937 rng(5);
  auto occ = test::makeMap({2.0, 2.0, 2.0}, {-1.0, -1.0, -1.0});
  test::randomFill(occ.get(), 0.03, &rng);
  auto esdf = test::makeEsdf(occ, 1.5);
  esdf->updateAll();
  std::uniform_real_distribution<double> pos(-0.85, 0.85);
  const double res = 0.1, h = 1e-5;
  int checked = 0;
  while (checked < 300) {
    const Eigen::Vector3d p(pos(rng), pos(rng), pos(rng));
    // Stay away from the cell faces of the interpolation grid, where the gradient jumps.
    const Eigen::Vector3d t = p / res - Eigen::Vector3d::Constant(0.5);
    const Eigen::Vector3d frac = t - t.array().floor().matrix();
    if ((frac.array() < 0.01).any() || (frac.array() > 0.99).any()) continue;
    const DistanceQuery q = esdf->query(p);
    ASSERT_EQ(q.status, QueryStatus::kOk);
    for (int k = 0; k < 3; ++k) {
      Eigen::Vector3d e = Eigen::Vector3d::Zero();
      e[k] = h;
      const double fd = (esdf->query(p + e).distance - esdf->query(p - e).distance) / (2 * h);
      ASSERT_NEAR(q.gradient[k], fd, 1e-4 * std::max(1.0, std::abs(fd))) << "axis " << k << " at " << p.transpose();
    }
    ++checked;
  }
}

TEST(Esdf, InterpolationIsExactAtVoxelCentresAndSignedInside) {
  auto occ = test::makeMap({2.0, 2.0, 2.0}, {-1.0, -1.0, -1.0});
  // A solid 6x6x6 block of voxels in the middle; everything else free.
  const VoxelBox w = occ->geometry().windowBox();
  Eigen::Vector3i i;
  for (i.z() = w.min.z(); i.z() <= w.max.z(); ++i.z())
    for (i.y() = w.min.y(); i.y() <= w.max.y(); ++i.y())
      for (i.x() = w.min.x(); i.x() <= w.max.x(); ++i.x())
        occ->setState(i, ((i.array() >= -3).all() && (i.array() <= 2).all()) ? VoxelState::kOccupied
                                                                              : VoxelState::kFree);
  auto esdf = test::makeEsdf(occ, 1.0);
  esdf->updateAll();
  // Centre voxel (0,0,0) is 3 voxels from the nearest free voxel (-4 or 3 on some axis).
  double d;
  ASSERT_EQ(esdf->distance(Eigen::Vector3i(0, 0, 0), &d), QueryStatus::kOk);
  EXPECT_NEAR(d, -0.3, 1e-6);
  ASSERT_EQ(esdf->distance(Eigen::Vector3i(6, 0, 0), &d), QueryStatus::kOk);
  EXPECT_NEAR(d, 0.4, 1e-6);
  const DistanceQuery q = esdf->query(occ->geometry().centerOf(Eigen::Vector3i(6, 0, 0)));
  EXPECT_NEAR(q.distance, 0.4, 1e-6);
  EXPECT_GT(q.gradient.x(), 0.5);  // pointing away from the block
  // Zero crossing on the face between voxels 2 (occupied) and 3 (free): x = 0.3.
  EXPECT_NEAR(esdf->query({0.3, 0.05, 0.05}).distance, 0.0, 1e-6);
  EXPECT_TRUE(esdf->isInflatedOccupied(Eigen::Vector3i(4, 0, 0)));   // 0.2 m from the block
  EXPECT_FALSE(esdf->isInflatedOccupied(Eigen::Vector3i(5, 0, 0)));  // 0.3 m
}

TEST(Esdf, QueriesReportOutOfMapAndUnknown) {
  auto occ = test::makeMap({1.0, 1.0, 1.0}, {0, 0, 0});
  auto esdf = test::makeEsdf(occ, 0.5);
  esdf->updateAll();
  EXPECT_EQ(esdf->query({0.5, 0.5, 0.5}).status, QueryStatus::kUnknown);
  EXPECT_EQ(esdf->query({-0.5, 0.5, 0.5}).status, QueryStatus::kOutOfMap);
  EXPECT_EQ(esdf->query({0.02, 0.5, 0.5}).status, QueryStatus::kOutOfMap);  // needs a voxel outside to interpolate
  EXPECT_EQ(esdf->query({NAN, 0.5, 0.5}).status, QueryStatus::kInvalidInput);
  EXPECT_EQ(esdf->query({1e30, 0.5, 0.5}).status, QueryStatus::kOutOfMap);
  EXPECT_EQ(esdf->nearest({INFINITY, 0, 0}).status, QueryStatus::kInvalidInput);
  double d;
  EXPECT_EQ(esdf->distance(Eigen::Vector3i(100, 0, 0), &d), QueryStatus::kOutOfMap);
  EXPECT_TRUE(esdf->isInflatedOccupied(Eigen::Vector3d(-5.0, 0.0, 0.0)));
}

TEST(Esdf, ScrolledWindowRecomputesToTheSameField) {
  std::mt19937 rng(3);
  auto occ = test::makeMap({2.0, 2.0, 1.0}, {0, 0, 0});
  test::randomFill(occ.get(), 0.05, &rng);
  auto esdf = test::makeEsdf(occ, 0.5);
  esdf->updateAll();
  occ->setOriginIndex(occ->geometry().originIndex() + Eigen::Vector3i(7, -3, 2));
  ASSERT_GT(occ->countState(VoxelState::kOccupied), 0u);  // the obstacles that stayed
  const EsdfUpdateStats stats = esdf->update(VoxelBox());
  EXPECT_TRUE(stats.full);
  auto fresh = test::makeEsdf(occ, 0.5);
  fresh->updateAll();
  EXPECT_EQ(fresh->distances(), esdf->distances());
}

// The walk out of an obstacle's clearance goes straight away from a pillar, never loses distance,
// and stops at the first point where the target holds; it refuses where the field is flat.
TEST(Esdf, AscendDistanceLeavesThePillarRadially) {
  SyntheticScene scene(Eigen::Vector3d(6.0, 6.0, 2.0));
  scene.pillar(3.0, 3.0, 0.5);
  const EsdfMap& esdf = scene.finish();
  const Eigen::Vector3d from(3.62, 3.31, 1.0);  // about 0.25 m from the nearest pillar voxel
  const Eigen::Vector2d radial = (from.head<2>() - Eigen::Vector2d(3.0, 3.0)).normalized();
  auto distance = [&](const Eigen::Vector3d& p) { return esdf.query(p).distance; };
  std::vector<Eigen::Vector3d> path;
  ASSERT_TRUE(ascendDistance(esdf, from, [&](const Eigen::Vector3d& p) { return distance(p) >= 0.6; }, 1.0, &path));
  ASSERT_GE(path.size(), 2u);
  EXPECT_EQ(path.front(), from);
  EXPECT_GE(distance(path.back()), 0.6);
  EXPECT_LT(distance(path[path.size() - 2]), 0.6);
  for (size_t i = 1; i < path.size(); ++i) {
    EXPECT_GE(distance(path[i]), distance(path[i - 1]) - 1e-9);
    EXPECT_NEAR((path[i] - path[i - 1]).norm(), 0.05, 1e-9);
    const Eigen::Vector2d out = path[i].head<2>() - Eigen::Vector2d(3.0, 3.0);
    EXPECT_GT(out.normalized().dot(radial), 0.95) << "step " << i;  // away from the axis (voxelised pillar)
    EXPECT_NEAR(path[i].z(), 1.0, 1e-6);                             // no vertical component
  }
  // Too short a walk allowed: false, with the walk so far.
  EXPECT_FALSE(ascendDistance(esdf, from, [&](const Eigen::Vector3d& p) { return distance(p) >= 0.6; }, 0.1, &path));
  EXPECT_LE(path.size(), 3u);
  // Beyond the truncation the field is flat: nowhere to go.
  SyntheticScene empty(Eigen::Vector3d(6.0, 6.0, 2.0));
  const EsdfMap& flat = empty.finish();
  EXPECT_FALSE(ascendDistance(flat, {3, 3, 1}, [](const Eigen::Vector3d&) { return false; }, 1.0, &path));
  // Already done: the path is the start alone. Outside the map: false.
  EXPECT_TRUE(ascendDistance(esdf, from, [](const Eigen::Vector3d&) { return true; }, 1.0, &path));
  EXPECT_EQ(path.size(), 1u);
  EXPECT_FALSE(ascendDistance(esdf, {30, 3, 1}, [](const Eigen::Vector3d&) { return true; }, 1.0, &path));
  EXPECT_FALSE(ascendDistance(esdf, {NAN, 3, 1}, [](const Eigen::Vector3d&) { return true; }, 1.0, &path));
}

}  // namespace
}  // namespace topo_planner
