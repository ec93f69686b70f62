// Depth images as the mapping node receives them: a sensor_msgs/Image (16UC1/mono16 millimetres,
// 32FC1 metres, any encoding string, width, height, row step, byte order and data length), an
// optional sensor_msgs/CameraInfo and the camera pose, through depthImageToView, cameraInfoToPinhole
// and poseToIsometry (plan_manage/ros_conversions.h) into OccupancyMap::fuseDepthImage, as
// MappingServer::fuseDepth does. The message fields are built from the bytes (fuzz_input.h); the
// pixel data is what is left.
#include <sensor_msgs/CameraInfo.h>
#include <sensor_msgs/Image.h>

#include "fuzz_input.h"
#include "topo_planner/plan_env/occupancy_map.h"
#include "topo_planner/plan_manage/ros_conversions.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace topo_planner;
  fuzz::FuzzInput in(data, size);
  sensor_msgs::Image image;
  image.encoding = in.choice({"16UC1", "32FC1", "mono16", "8UC1", "16SC1", "32FC3", "bgr8", ""});
  image.width = in.integer<uint32_t>(32);
  image.height = in.integer<uint32_t>(24);
  const uint32_t bpp = image.encoding == "32FC1" ? 4 : 2;
  image.step = in.integer<uint32_t>(image.width * bpp);
  image.is_bigendian = in.flag();

  PinholeCamera camera;  // camera/* parameters, fitted to the image as a configured camera would be
  camera.width = int(std::min<uint32_t>(image.width, 1u << 20));
  camera.height = int(std::min<uint32_t>(image.height, 1u << 20));
  camera.fx = camera.fy = 0.5 * camera.width + 1.0;
  camera.cx = 0.5 * camera.width;
  camera.cy = 0.5 * camera.height;
  if (in.flag()) {
    sensor_msgs::CameraInfo info;
    info.width = in.integer<uint32_t>(image.width);
    info.height = in.integer<uint32_t>(image.height);
    info.K = {in.number(camera.fx), 0.0, in.number(camera.cx), 0.0, in.number(camera.fy), in.number(camera.cy),
              0.0, 0.0, 1.0};
    info.binning_x = in.integer<uint32_t>(0);
    info.binning_y = in.integer<uint32_t>(0);
    info.roi.x_offset = in.integer<uint32_t>(0);
    info.roi.width = in.integer<uint32_t>(0);
    info.roi.height = in.integer<uint32_t>(0);
    PinholeCamera from_info;
    if (cameraInfoToPinhole(info, &from_info) == ConversionStatus::kOk) {
      TOPO_PLANNER_FUZZ_CHECK(from_info.valid());
      camera = from_info;
    }
  }
  geometry_msgs::Pose pose;  // a camera at 1 m height looking along world +x (optical z)
  pose.position.x = in.number(-2.0);
  pose.position.y = in.number(0.0);
  pose.position.z = in.number(1.0);
  pose.orientation.x = in.number(-0.5);
  pose.orientation.y = in.number(0.5);
  pose.orientation.z = in.number(-0.5);
  pose.orientation.w = in.number(0.5);
  image.data = in.rest();

  DepthImageView view;
  std::vector<uint8_t> swapped;
  const ConversionStatus status = depthImageToView(image, DepthScales(), &swapped, &view);
  if (status != ConversionStatus::kOk) return 0;
  // The view's pixels lie inside the buffer it points to.
  const size_t buffer = view.data == swapped.data() ? swapped.size() : image.data.size();
  TOPO_PLANNER_FUZZ_CHECK(view.width > 0 && view.height > 0);
  TOPO_PLANNER_FUZZ_CHECK(view.row_step_bytes * size_t(view.height - 1) + view.bytesPerPixel() * size_t(view.width) <=
                          buffer);
  Eigen::Isometry3d T_world_camera;
  if (poseToIsometry(pose, &T_world_camera) != ConversionStatus::kOk) return 0;

  OccupancyMap::Config config;  // config/mapping.yaml's sensor model, a small window
  config.size_m = Eigen::Vector3d(6.0, 6.0, 3.0);
  config.origin_m = Eigen::Vector3d(-3.0, -3.0, -0.5);
  config.depth_pixel_skip = 1;
  config.max_image_pixels = 1 << 16;
  std::string why;
  std::unique_ptr<OccupancyMap> map = OccupancyMap::create(config, &why);
  TOPO_PLANNER_FUZZ_CHECK(map != nullptr);
  const FusionResult r = map->fuseDepthImage(view, camera, T_world_camera);
  TOPO_PLANNER_FUZZ_CHECK(r.rays >= 0 && r.invalid >= 0);
  return 0;
}
