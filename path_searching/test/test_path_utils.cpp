#include <gtest/gtest.h>

#include "topo_planner/path_searching/path.h"
#include "topo_planner/path_searching/visibility.h"
#include "topo_planner/plan_env/synthetic_scene.h"

namespace topo_planner {
namespace {

TEST(PathUtils, LengthAndUniformArcLength) {
  const Path p{{0, 0, 0}, {3, 0, 0}, {3, 4, 0}};
  EXPECT_DOUBLE_EQ(pathLength(p), 7.0);
  const Path d = discretizeByArcLength(p, 7);
  ASSERT_EQ(d.size(), 8u);
  // Uniform in arc length: point i lies i metres along the path (point 3 is the corner).
  for (size_t i = 1; i < d.size(); ++i) EXPECT_NEAR(pathLength(Path(d.begin(), d.begin() + long(i) + 1)), double(i), 1e-9);
  EXPECT_TRUE(d.back().isApprox(p.back()));
  EXPECT_TRUE(pointAtArcLength(p, 0.5).isApprox(Eigen::Vector3d(3, 0.5, 0)));
  const Path r = resamplePath(p, 0.4);
  EXPECT_NEAR(pathLength(r), 7.0, 1e-9);
  for (size_t i = 1; i < r.size(); ++i) EXPECT_LE((r[i] - r[i - 1]).norm(), 0.4 + 1e-9);
  EXPECT_NE(std::find_if(r.begin(), r.end(), [](const Eigen::Vector3d& q) { return q.isApprox(Eigen::Vector3d(3, 0, 0)); }),
            r.end());  // the corner is kept
}

class UvdPillar : public ::testing::Test {
 protected:
  UvdPillar() : scene_({10.0, 8.0, 3.0}) {
    scene_.pillar(5.0, 4.0, 0.5);
    checker_ = std::make_unique<VisibilityChecker>(scene_.finish(), 0.2, true);
  }
  SyntheticScene scene_;
  std::unique_ptr<VisibilityChecker> checker_;
};

TEST_F(UvdPillar, SameSideEquivalentOppositeSidesNot) {
  const Eigen::Vector3d s(1, 4, 1.5), g(9, 4, 1.5);
  const Path left_near{s, {5, 5.2, 1.5}, g}, left_far{s, {4, 6.8, 1.5}, {6.5, 6.5, 1.5}, g};
  const Path right{s, {5, 2.6, 1.5}, g};
  EXPECT_TRUE(uniformVisibilityEquivalent(left_near, left_far, *checker_));
  EXPECT_TRUE(uniformVisibilityEquivalent(left_far, left_near, *checker_));
  EXPECT_FALSE(uniformVisibilityEquivalent(left_near, right, *checker_));
  EXPECT_FALSE(uniformVisibilityEquivalent(right, left_far, *checker_));
  EXPECT_TRUE(uniformVisibilityEquivalent(right, right, *checker_));
}

TEST_F(UvdPillar, LineVisibilityReportsTheFirstBlockedVoxel) {
  Eigen::Vector3d block;
  EXPECT_FALSE(checker_->lineVisible({1, 4.05, 1.55}, {9, 4.05, 1.55}, &block));
  // The first voxel within 0.2 m clearance of the 0.5 m pillar, coming from x = 1.
  EXPECT_NEAR(block.x(), 5.0 - 0.7 + 0.05, 0.1001);
  EXPECT_TRUE(checker_->lineVisible({1, 6, 1.5}, {9, 6, 1.5}));
  EXPECT_FALSE(checker_->lineVisible({1, 6, 1.5}, {19, 6, 1.5}));  // leaves the map
  EXPECT_FALSE(checker_->isFree({5.0, 4.0, 1.5}));
  EXPECT_FALSE(checker_->isFree({NAN, 4.0, 1.5}));
}

}  // namespace
}  // namespace topo_planner
