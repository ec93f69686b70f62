// The mapping's conversions of untrusted messages (plan_manage/ros_conversions.h): CameraInfo
// intrinsics and depth images, each refusal with its status and the output untouched.
#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <functional>

#include "topo_planner/plan_manage/ros_conversions.h"

namespace topo_planner {
namespace {

sensor_msgs::CameraInfo goodInfo() {
  sensor_msgs::CameraInfo m;
  m.width = 640, m.height = 480;
  m.K = {385.0, 0.0, 320.5, 0.0, 386.0, 240.5, 0.0, 0.0, 1.0};
  return m;
}

TEST(CameraInfoToPinhole, TakesKAndTheSize) {
  PinholeCamera c;
  ASSERT_EQ(cameraInfoToPinhole(goodInfo(), &c), ConversionStatus::kOk);
  EXPECT_EQ(c.width, 640);
  EXPECT_EQ(c.height, 480);
  EXPECT_EQ(c.fx, 385.0);
  EXPECT_EQ(c.fy, 386.0);
  EXPECT_EQ(c.cx, 320.5);
  EXPECT_EQ(c.cy, 240.5);
  sensor_msgs::CameraInfo full = goodInfo();  // a region of interest that is the whole image is fine
  full.roi.width = 640, full.roi.height = 480;
  EXPECT_EQ(cameraInfoToPinhole(full, &c), ConversionStatus::kOk);
}

TEST(CameraInfoToPinhole, RefusesWhatItCannotUseAndKeepsTheOutput) {
  auto bad = [](const std::function<void(sensor_msgs::CameraInfo*)>& change) {
    sensor_msgs::CameraInfo m = goodInfo();
    change(&m);
    PinholeCamera c;
    c.fx = 123.0;
    const ConversionStatus s = cameraInfoToPinhole(m, &c);
    EXPECT_EQ(c.fx, 123.0);  // untouched
    return s;
  };
  EXPECT_EQ(bad([](sensor_msgs::CameraInfo* m) { m->K[0] = NAN; }), ConversionStatus::kInvalidCameraInfo);
  EXPECT_EQ(bad([](sensor_msgs::CameraInfo* m) { m->K[2] = INFINITY; }), ConversionStatus::kInvalidCameraInfo);
  EXPECT_EQ(bad([](sensor_msgs::CameraInfo* m) { m->K[0] = 0.0; }), ConversionStatus::kInvalidCameraInfo);
  EXPECT_EQ(bad([](sensor_msgs::CameraInfo* m) { m->K[4] = -386.0; }), ConversionStatus::kInvalidCameraInfo);
  EXPECT_EQ(bad([](sensor_msgs::CameraInfo* m) { m->width = 0; }), ConversionStatus::kInvalidCameraInfo);
  EXPECT_EQ(bad([](sensor_msgs::CameraInfo* m) { m->height = 1u << 20; }), ConversionStatus::kInvalidCameraInfo);
  EXPECT_EQ(bad([](sensor_msgs::CameraInfo* m) { m->binning_x = 2; }), ConversionStatus::kInvalidCameraInfo);
  EXPECT_EQ(bad([](sensor_msgs::CameraInfo* m) { m->roi.x_offset = 10, m->roi.width = 320, m->roi.height = 240; }),
            ConversionStatus::kInvalidCameraInfo);
}

sensor_msgs::Image depth16(uint32_t w, uint32_t h, uint16_t mm) {
  sensor_msgs::Image m;
  m.encoding = "16UC1", m.width = w, m.height = h, m.step = 2 * w;
  m.data.resize(size_t(m.step) * h);
  for (size_t i = 0; i < size_t(w) * h; ++i) std::memcpy(m.data.data() + 2 * i, &mm, 2);
  return m;
}

TEST(DepthImageToView, RefusesEncodingsSizesAndSteps) {
  std::vector<uint8_t> swap;
  DepthImageView view;
  EXPECT_EQ(depthImageToView(depth16(8, 6, 1000), DepthScales(), &swap, &view), ConversionStatus::kOk);
  sensor_msgs::Image m = depth16(8, 6, 1000);
  m.encoding = "rgb8";
  EXPECT_EQ(depthImageToView(m, DepthScales(), &swap, &view), ConversionStatus::kUnsupportedEncoding);
  m = depth16(8, 6, 1000);
  m.step = 8;  // shorter than a row
  EXPECT_EQ(depthImageToView(m, DepthScales(), &swap, &view), ConversionStatus::kTruncatedData);
  m = depth16(8, 6, 1000);
  m.data.resize(20);  // fewer bytes than step * height
  EXPECT_EQ(depthImageToView(m, DepthScales(), &swap, &view), ConversionStatus::kTruncatedData);
  m = depth16(8, 6, 1000);
  m.width = m.height = 0;
  EXPECT_EQ(depthImageToView(m, DepthScales(), &swap, &view), ConversionStatus::kEmptyImage);
}

}  // namespace
}  // namespace topo_planner
