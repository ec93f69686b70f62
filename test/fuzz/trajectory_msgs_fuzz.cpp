// The planner's and the trajectory server's message inputs. The first byte picks the message:
//   0: topo_planner/Bspline -> fromMsg (plan_manage/trajectory_conversions.h) -> SetpointGenerator::add
//      and sample(), as TrajServer::bsplineCallback and its timer do;
//   1: geometry_msgs/PoseStamped (rviz 2D Nav Goal) -> goalFromMsg -> ReplanFsm::setGoals;
//   2: nav_msgs/Path (waypoints) -> goalsFromMsg -> ReplanFsm::setGoals.
// The message fields are built from the bytes (fuzz_input.h); stamps are set as the wire sets them
// (sec and nsec as sent, not normalised).
#include "fuzz_input.h"
#include "topo_planner/plan_manage/trajectory_conversions.h"

namespace {

using topo_planner::fuzz::FuzzInput;

ros::Time stamp(FuzzInput& in) {
  ros::Time t;
  t.sec = in.integer<uint32_t>(100);
  t.nsec = in.integer<uint32_t>(0);
  return t;
}

void fuzzBspline(FuzzInput& in) {
  using namespace topo_planner;
  Bspline msg;
  msg.header.frame_id = in.choice({"world", "", "map"});
  msg.planner_session = in.integer<uint64_t>(1);
  msg.trajectory_id = in.integer<int64_t>(1);
  msg.start_time = stamp(in);
  msg.order = in.integer<int32_t>(3);
  msg.knot_span_s = in.number(0.1);
  msg.has_heading_target = in.flag();
  msg.heading_target.x = in.number(5.0);
  msg.heading_target.y = in.number(0.0);
  msg.heading_target.z = in.number(1.0);
  msg.reanchor = in.flag();
  const size_t n = in.integer<uint16_t>(8);
  msg.control_points.resize(n);
  for (size_t i = 0; i < n; ++i) {
    msg.control_points[i].x = in.number(0.2 * double(i));
    msg.control_points[i].y = in.number(0.0);
    msg.control_points[i].z = in.number(1.0);
  }
  ReceivedTrajectory r;
  std::string why;
  if (!fromMsg(msg, &r, &why)) {
    TOPO_PLANNER_FUZZ_CHECK(!why.empty());
    return;
  }
  TOPO_PLANNER_FUZZ_CHECK(r.spline.isValid());
  SetpointGenerator generator{SetpointGenerator::Config()};
  generator.setVehiclePose(r.spline.evaluate(0.0), 0.0);
  if (!generator.add(r.planner_session, r.id, r.start_time_s, r.spline, r.heading_target, r.reanchor)) return;
  // The server's timer: the period, then a few steps across the trajectory and past its end.
  const double t0 = r.start_time_s;
  const double T = r.spline.duration();
  Setpoint sp;
  for (double t : {t0 - 0.01, t0, t0 + 0.01, t0 + 0.5 * T, t0 + T, t0 + T + 0.01, t0 + T + 5.0})
    if (generator.sample(t, &sp)) {
      TOPO_PLANNER_FUZZ_CHECK(sp.state.position.allFinite() && sp.state.velocity.allFinite());
      TOPO_PLANNER_FUZZ_CHECK(std::isfinite(sp.yaw));
    }
}

topo_planner::ReplanFsm& fsm() {
  static std::unique_ptr<topo_planner::ReplanFsm> f = [] {
    std::string why;
    auto made = topo_planner::ReplanFsm::create(topo_planner::ReplanFsm::Config(), &why);
    TOPO_PLANNER_FUZZ_CHECK(made != nullptr);
    return made;
  }();
  return *f;
}

void fuzzGoal(FuzzInput& in) {
  using namespace topo_planner;
  geometry_msgs::PoseStamped msg;
  msg.header.frame_id = in.choice({"world", "", "map"});
  msg.header.stamp = stamp(in);
  msg.pose.position.x = in.number(5.0);
  msg.pose.position.y = in.number(0.0);
  msg.pose.position.z = in.number(0.0);
  msg.pose.orientation.w = in.number(1.0);
  Eigen::Vector3d goal;
  std::string why;
  if (!goalFromMsg(msg, "world", 1.0, &goal, &why)) {
    TOPO_PLANNER_FUZZ_CHECK(!why.empty());
    return;
  }
  const GoalStatus status = fsm().setGoals({goal});
  if (!goal.allFinite()) TOPO_PLANNER_FUZZ_CHECK(status == GoalStatus::kInvalidInput);
}

void fuzzPath(FuzzInput& in) {
  using namespace topo_planner;
  nav_msgs::Path msg;
  msg.header.frame_id = in.choice({"world", "", "map"});
  msg.header.stamp = stamp(in);
  const size_t n = in.integer<uint16_t>(3);
  msg.poses.resize(n);
  for (size_t i = 0; i < n; ++i) {
    msg.poses[i].pose.position.x = in.number(double(i));
    msg.poses[i].pose.position.y = in.number(0.0);
    msg.poses[i].pose.position.z = in.number(1.0);
  }
  std::vector<Eigen::Vector3d> goals;
  std::string why;
  if (!goalsFromMsg(msg, "world", &goals, &why)) {
    TOPO_PLANNER_FUZZ_CHECK(!why.empty() && (n > kMaxWaypoints || !msg.header.frame_id.empty()));
    return;
  }
  TOPO_PLANNER_FUZZ_CHECK(goals.size() == n);
  const GoalStatus status = fsm().setGoals(goals);
  if (goals.empty()) TOPO_PLANNER_FUZZ_CHECK(status == GoalStatus::kInvalidInput);
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  FuzzInput in(data, size);
  switch (in.byte() % 3) {
    case 0: fuzzBspline(in); break;
    case 1: fuzzGoal(in); break;
    default: fuzzPath(in); break;
  }
  return 0;
}
