// Point clouds as the nodes receive them: a sensor_msgs/PointCloud2 with any fields (names, offsets,
// datatypes), point and row steps, width, height, byte order and data length, through
// pointCloud2ToPoints (the mapping node, plan_manage/ros_conversions.h) into
// OccupancyMap::fusePointCloud, and through cloudToPoints (the simulator's true map,
// uav_sim/ros/conversions.h). The message fields are built from the bytes (fuzz_input.h); the point
// data is what is left.
#include <sensor_msgs/PointCloud2.h>
#include <sensor_msgs/PointField.h>

#include "fuzz_input.h"
#include "topo_planner/plan_env/occupancy_map.h"
#include "topo_planner/plan_manage/ros_conversions.h"
#include "topo_planner/uav_sim/ros/conversions.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace topo_planner;
  fuzz::FuzzInput in(data, size);
  sensor_msgs::PointCloud2 cloud;
  const int num_fields = in.byte() % 6;
  uint32_t offset = 0;
  for (int i = 0; i < num_fields; ++i) {
    sensor_msgs::PointField f;
    f.name = in.choice({"x", "y", "z", "intensity", "rgb"});
    f.datatype = in.integer<uint8_t>(sensor_msgs::PointField::FLOAT32);
    f.offset = in.integer<uint32_t>(offset);
    f.count = in.integer<uint32_t>(1);
    offset = f.offset + (f.datatype == sensor_msgs::PointField::FLOAT64 ? 8 : 4);
    cloud.fields.push_back(f);
  }
  cloud.point_step = in.integer<uint32_t>(offset);
  cloud.width = in.integer<uint32_t>(4);
  cloud.height = in.integer<uint32_t>(1);
  cloud.row_step = in.integer<uint32_t>(cloud.width * cloud.point_step);
  cloud.is_bigendian = in.flag();
  const Eigen::Vector3d origin(in.number(0.0), in.number(0.0), in.number(1.0));
  cloud.data = in.rest();

  std::vector<Eigen::Vector3d> points;
  if (pointCloud2ToPoints(cloud, &points) == ConversionStatus::kOk) {
    TOPO_PLANNER_FUZZ_CHECK(points.size() == size_t(cloud.width) * cloud.height);
    OccupancyMap::Config config;  // config/mapping.yaml's sensor model, a small window
    config.size_m = Eigen::Vector3d(6.0, 6.0, 3.0);
    config.origin_m = Eigen::Vector3d(-3.0, -3.0, -0.5);
    std::string why;
    std::unique_ptr<OccupancyMap> map = OccupancyMap::create(config, &why);
    TOPO_PLANNER_FUZZ_CHECK(map != nullptr);
    const FusionResult r = map->fusePointCloud(points, origin);
    TOPO_PLANNER_FUZZ_CHECK(r.rays >= 0 && r.invalid >= 0);
  }
  std::string why;
  if (cloudToPoints(cloud, &points, &why)) {
    TOPO_PLANNER_FUZZ_CHECK(points.size() == size_t(cloud.width) * cloud.height);
  } else {
    TOPO_PLANNER_FUZZ_CHECK(!why.empty());
  }
  return 0;
}
