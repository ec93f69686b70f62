// Parameter validation: the configs the nodes read from their YAML files (config/*.yaml through the
// ROS parameter server), built field by field from the bytes (fuzz_input.h), then checked by their
// validate() and, when accepted, taken on as the loaders do:
//   MappingServer::Config (readMappingParams): validate, then MappingServer::buildMaps' steps
//     (OccupancyMap::create, EsdfMap::create, the slice height inside the window, a full ESDF);
//   ReplanFsm::Config (readPlannerParams' fsm/, replan/, search/, optimizer/, route/): validate, then
//     ReplanFsm::create;
//   SetpointGenerator::Config (the trajectory server): validate;
//   PlannerSettings (readPlannerParams' own fields): validate, then the planner node's timers
//   (ros::Duration of the periods) and trajectory markers (lineStrip at vis_sample_s).
// The property: a config validate() accepts builds its objects without crashing, and within
// max_memory_mb (kept small here, so that a memory bug shows up against the fuzzer's RSS limit).
#include <ros/time.h>

#include "fuzz_input.h"
#include "topo_planner/plan_manage/mapping_server.h"
#include "topo_planner/plan_manage/planner_settings.h"
#include "topo_planner/plan_manage/trajectory_conversions.h"
#include "topo_planner/topo_replan/replan_fsm.h"
#include "topo_planner/topo_replan/setpoint_generator.h"

namespace {

using topo_planner::fuzz::FuzzInput;

void fuzzMapping(FuzzInput& in) {
  using namespace topo_planner;
  MappingServer::Config c;
  OccupancyMap::Config& m = c.occupancy;
  m.resolution_m = in.number(0.2);
  m.size_m = Eigen::Vector3d(in.number(6.0), in.number(6.0), in.number(3.0));
  m.origin_m = Eigen::Vector3d(in.number(-3.0), in.number(-3.0), in.number(-0.5));
  m.prob_hit = in.number(m.prob_hit);
  m.prob_miss = in.number(m.prob_miss);
  m.prob_min = in.number(m.prob_min);
  m.prob_max = in.number(m.prob_max);
  m.prob_occupied = in.number(m.prob_occupied);
  m.min_ray_length_m = in.number(m.min_ray_length_m);
  m.max_ray_length_m = in.number(m.max_ray_length_m);
  m.depth_pixel_skip = in.integer(m.depth_pixel_skip);
  m.max_image_pixels = in.integer(m.max_image_pixels);
  m.merge_rays = in.flag();
  m.project_free_space = in.flag();
  m.max_memory_mb = std::min(in.number(8.0), 8.0);  // the documented bound, kept below the RSS limit
  EsdfMap::Config& e = c.esdf;
  e.max_distance_m = in.number(e.max_distance_m);
  e.inflate_radius_m = in.number(e.inflate_radius_m);
  e.unknown_as_occupied = in.flag();
  e.num_threads = std::min(in.integer(1), 4);  // validate allows 64; the fuzzer runs on one core
  PinholeCamera& cam = c.camera;
  cam.width = in.integer(cam.width);
  cam.height = in.integer(cam.height);
  cam.fx = in.number(cam.fx);
  cam.fy = in.number(cam.fy);
  cam.cx = in.number(cam.cx);
  cam.cy = in.number(cam.cy);
  c.depth_scales.uint16_m = in.number(c.depth_scales.uint16_m);
  c.frame_id = in.choice({"world", "", "map"});
  c.sync_queue_size = in.integer(c.sync_queue_size);
  c.sync_max_interval_s = in.number(c.sync_max_interval_s);
  c.cloud_sensor_origin_m = Eigen::Vector3d(in.number(0.0), in.number(0.0), in.number(0.0));
  c.cloud_max_pose_age_s = in.number(c.cloud_max_pose_age_s);
  c.recenter_on_vehicle = in.flag();
  c.recenter_threshold_m = in.number(c.recenter_threshold_m);
  c.occupancy_publish_rate_hz = in.number(c.occupancy_publish_rate_hz);
  c.esdf_publish_rate_hz = in.number(c.esdf_publish_rate_hz);
  c.esdf_slice_height_m = in.number(c.esdf_slice_height_m);
  c.status_period_s = in.number(c.status_period_s);
  if (in.flag()) {  // extrinsic/matrix_row_major: any 4x4 with last row 0 0 0 1 (orthonormality is validate's)
    Eigen::Matrix4d M = c.T_body_camera.matrix();
    for (int i = 0; i < 12; ++i) M(i / 4, i % 4) = in.number(M(i / 4, i % 4));
    c.T_body_camera.matrix() = M;
  }

  std::string why;
  if (!c.validate(&why)) {
    TOPO_PLANNER_FUZZ_CHECK(!why.empty());
    return;
  }
  std::unique_ptr<OccupancyMap> occ = OccupancyMap::create(c.occupancy, &why);
  TOPO_PLANNER_FUZZ_CHECK(occ != nullptr);  // validate() accepted the same config
  std::shared_ptr<OccupancyMap> shared(std::move(occ));
  std::unique_ptr<EsdfMap> esdf = EsdfMap::create(c.esdf, shared, &why);
  if (!esdf) {
    TOPO_PLANNER_FUZZ_CHECK(!why.empty());
    return;
  }
  // MappingServer::buildMaps: the slice height inside the window (in metres), then its voxel row.
  const GridGeometry& g = shared->geometry();
  if (!(c.esdf_slice_height_m >= g.windowMin().z() && c.esdf_slice_height_m < g.windowMax().z())) return;
  const int slice_z = g.indexOf(Eigen::Vector3d(0, 0, c.esdf_slice_height_m)).z();
  TOPO_PLANNER_FUZZ_CHECK(slice_z >= g.windowBox().min.z() - 1 && slice_z <= g.windowBox().max.z() + 1);
  if (g.windowBox().volume() <= 200000) esdf->updateAll();
}

void fuzzPlanner(FuzzInput& in) {
  using namespace topo_planner;
  ReplanFsm::Config f;
  f.takeover_delay_s = in.number(f.takeover_delay_s);
  f.max_takeover_delay_s = in.number(f.max_takeover_delay_s);
  f.replan_interval_s = in.number(f.replan_interval_s);
  f.safety_clearance_m = in.number(f.safety_clearance_m);
  f.safety_sample_s = in.number(f.safety_sample_s);
  f.brake_acc_mps2 = in.number(f.brake_acc_mps2);
  f.max_brake_acc_mps2 = in.number(f.max_brake_acc_mps2);
  f.emergency_margin_s = in.number(f.emergency_margin_s);
  f.goal_clearance_m = in.number(f.goal_clearance_m);
  f.goal_tolerance_m = in.number(f.goal_tolerance_m);
  f.stopped_speed_mps = in.number(f.stopped_speed_mps);
  f.max_plan_failures = in.integer(f.max_plan_failures);
  f.escape_clearance_m = in.number(f.escape_clearance_m);
  f.escape_min_clearance_m = in.number(f.escape_min_clearance_m);
  f.escape_speed_mps = in.number(f.escape_speed_mps);
  f.max_escape_length_m = in.number(f.max_escape_length_m);
  f.commit_to_known_space = in.flag();
  f.known_start_radius_m = in.number(f.known_start_radius_m);
  f.commit_margin_m = in.number(f.commit_margin_m);
  f.depth_timeout_s = in.number(f.depth_timeout_s);
  f.odom_timeout_s = in.number(f.odom_timeout_s);
  f.odom_max_age_s = in.number(f.odom_max_age_s);
  f.max_tracking_error_m = in.number(f.max_tracking_error_m);
  f.time_jump_threshold_s = in.number(f.time_jump_threshold_s);
  f.waypoint_reached_radius_m = in.number(f.waypoint_reached_radius_m);
  f.global_route = in.flag();
  f.reroute_after_failures = in.integer(f.reroute_after_failures);
  f.route_check_length_m = in.number(f.route_check_length_m);
  f.route_check_interval_s = in.number(f.route_check_interval_s);
  f.backoff_length_m = in.number(f.backoff_length_m);
  f.max_backoff_length_m = in.number(f.max_backoff_length_m);
  f.backoff_speed_mps = in.number(f.backoff_speed_mps);
  f.max_backoffs = in.integer(f.max_backoffs);
  f.max_look_holds = in.integer(f.max_look_holds);
  f.mission_timeout_s = in.number(f.mission_timeout_s);
  f.route.cell_voxels = in.integer(f.route.cell_voxels);
  f.route.preferred_clearance_m = in.number(f.route.preferred_clearance_m);
  f.route.clearance_weight = in.number(f.route.clearance_weight);
  f.route.heuristic_weight = in.number(f.route.heuristic_weight);
  f.route.min_z_m = in.number(f.route.min_z_m);
  f.route.max_z_m = in.number(f.route.max_z_m);
  f.route.end_clearance_m = in.number(f.route.end_clearance_m);
  f.route.max_expansions = in.integer(f.route.max_expansions);
  f.reference.max_vel_mps = in.number(f.reference.max_vel_mps);
  f.reference.max_acc_mps2 = in.number(f.reference.max_acc_mps2);
  f.reference.max_segment_length_m = in.number(f.reference.max_segment_length_m);
  TopoReplanner::Config& p = f.replanner;
  p.horizon_m = in.number(p.horizon_m);
  p.reference_clearance_m = in.number(p.reference_clearance_m);
  p.local_goal_margin_m = in.number(p.local_goal_margin_m);
  p.max_local_goal_extension_m = in.number(p.max_local_goal_extension_m);
  p.control_point_spacing_m = in.number(p.control_point_spacing_m);
  p.guide_timing_ratio = in.number(p.guide_timing_ratio);
  p.max_search_start_offset_m = in.number(p.max_search_start_offset_m);
  p.min_start_clearance_m = in.number(p.min_start_clearance_m);
  p.num_threads = std::min(in.integer(1), 4);  // worker threads: kept few, the fuzzer runs on one core
  p.search.clearance_m = in.number(p.search.clearance_m);
  p.search.max_paths = in.integer(p.search.max_paths);
  p.search.max_length_ratio = in.number(p.search.max_length_ratio);
  p.search.roadmap.max_time_s = in.number(p.search.roadmap.max_time_s);
  p.optimizer.clearance_m = in.number(p.optimizer.clearance_m);
  p.optimizer.max_iterations = in.integer(p.optimizer.max_iterations);
  p.optimizer.max_time_s = in.number(p.optimizer.max_time_s);
  p.optimizer.l2c = in.number(p.optimizer.l2c);
  p.optimizer.max_vel_mps = in.number(p.optimizer.max_vel_mps);
  p.optimizer.max_acc_mps2 = in.number(p.optimizer.max_acc_mps2);
  p.astar.clearance_m = in.number(p.astar.clearance_m);
  f.rest_retry_interval_s = in.number(f.rest_retry_interval_s);  // read last: the corpus keeps its layout
  f.moving_retry_interval_s = in.number(f.moving_retry_interval_s);
  p.optimizer.feasibility_margin = in.number(p.optimizer.feasibility_margin);
  p.optimizer.stretched_retry = in.flag();
  p.optimizer.guide_phase_fallback = in.flag();
  p.astar.margin_doublings = in.integer(p.astar.margin_doublings);

  std::string why;
  if (!f.validate(&why)) {
    TOPO_PLANNER_FUZZ_CHECK(!why.empty());
    return;
  }
  std::unique_ptr<ReplanFsm> fsm = ReplanFsm::create(f, &why);
  TOPO_PLANNER_FUZZ_CHECK(fsm != nullptr);  // validate() accepted the same config
}

void fuzzSetpoints(FuzzInput& in) {
  using namespace topo_planner;
  SetpointGenerator::Config s;
  s.moving_speed_mps = in.number(s.moving_speed_mps);
  s.stop_acc_mps2 = in.number(s.stop_acc_mps2);
  s.stop_jerk_mps3 = in.number(s.stop_jerk_mps3);
  s.max_time_step_s = in.number(s.max_time_step_s);
  s.nominal_period_s = in.number(s.nominal_period_s);
  s.hold_before_first_trajectory = in.flag();
  s.max_takeover_gap_m = in.number(s.max_takeover_gap_m);
  s.max_takeover_velocity_gap_mps = in.number(s.max_takeover_velocity_gap_mps);
  std::string why;
  if (!s.validate(&why)) TOPO_PLANNER_FUZZ_CHECK(!why.empty());
}

void fuzzPlannerNode(FuzzInput& in) {
  using namespace topo_planner;
  PlannerSettings c;
  c.goal_height_m = in.number(c.goal_height_m);
  c.plan_period_s = in.number(c.plan_period_s);
  c.safety_period_s = in.number(c.safety_period_s);
  c.vis_sample_s = in.number(c.vis_sample_s);
  c.reference_speed_ratio = in.number(c.reference_speed_ratio);
  const int goals = in.byte() % 4;
  for (int i = 0; i < goals; ++i) c.goals.emplace_back(in.number(1.0), in.number(1.0), in.number(1.0));
  std::string why;
  if (!c.validate(&why)) {
    TOPO_PLANNER_FUZZ_CHECK(!why.empty());
    return;
  }
  // PlannerServer::create's timers (ros::Duration throws beyond its 32-bit seconds).
  TOPO_PLANNER_FUZZ_CHECK(ros::Duration(c.plan_period_s).toSec() > 0.0);
  TOPO_PLANNER_FUZZ_CHECK(ros::Duration(c.safety_period_s).toSec() > 0.0);
  // The trajectory markers, over a trajectory of up to a day (a long mission's reference).
  const double knot_span_s = std::min(std::abs(in.number(0.1)), 8640.0);
  if (!(knot_span_s > 0.0)) return;
  const UniformBspline spline = UniformBspline::straightLine(Eigen::Vector3d::Zero(), Eigen::Vector3d(1.0, 2.0, 3.0),
                                                             16, 3, knot_span_s);
  const visualization_msgs::Marker strip = lineStrip(spline, c.vis_sample_s, "world", "trajectory", 0, 0.1, 1, 1, 1);
  TOPO_PLANNER_FUZZ_CHECK(strip.points.size() >= 2 && strip.points.size() <= 5000);
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  static const bool time_initialised = (ros::Time::init(), true);  // lineStrip stamps with ros::Time::now()
  (void)time_initialised;
  FuzzInput in(data, size);
  switch (in.byte() % 4) {
    case 0: fuzzMapping(in); break;
    case 1: fuzzPlanner(in); break;
    case 2: fuzzSetpoints(in); break;
    default: fuzzPlannerNode(in); break;
  }
  return 0;
}
