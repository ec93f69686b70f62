// Closed-loop flights without ROS (plan_manage/sim_flight.h), in simulated time, with the planner,
// mapping, camera and trajectory server configured as in config/*.yaml: the speed work's behaviour
// tests. Deterministic (every planning budget a count), a few seconds of wall time per flight.
#include "topo_planner/plan_manage/sim_flight.h"

#include <gtest/gtest.h>

#include <cstdio>

namespace topo_planner {
namespace {

// Occupied voxel centres (0.1 m) of the boxes [lo, hi] minus the holes.
struct World {
  std::vector<std::pair<Eigen::Vector3d, Eigen::Vector3d>> solids, holes;
  std::vector<Eigen::Vector3d> points() const {
    std::vector<Eigen::Vector3d> out;
    for (const auto& [lo, hi] : solids)
      for (double x = lo.x(); x <= hi.x() + 1e-9; x += 0.1)
        for (double y = lo.y(); y <= hi.y() + 1e-9; y += 0.1)
          for (double z = lo.z(); z <= hi.z() + 1e-9; z += 0.1) {
            const Eigen::Vector3d p(x, y, z);
            bool hole = false;
            for (const auto& [a, b] : holes) hole = hole || ((p.array() >= a.array()).all() && (p.array() <= b.array()).all());
            if (!hole) out.push_back(p);
          }
    return out;
  }
};

SimFlight::Config config(double max_vel) {
  SimFlight::Config c;
  std::string why;
  EXPECT_TRUE(loadSimFlightConfig(TOPO_PLANNER_CONFIG_DIR, max_vel, 2.5, false, &c, &why)) << why;
  c.map.origin_m = Eigen::Vector3d(-16.0, -10.0, 0.3);
  c.map.size_m = Eigen::Vector3d(32.0, 20.0, 3.4);
  c.goal_timeout_s = 60.0;
  return c;
}

// Issue 37, item 3: the way back over a wall whose only window was found on the way out. A wall
// closes the corridor at x = 0 but for one window 3 m aside of the way out, found at once; most of
// the wall is never seen. The way back goes to a goal 15 m aside, where the straight line crosses
// the wall's unseen part (the window is a detour of 5%); max_vel 5. With unknown space weighed (route/unknown_weight), the way back
// goes through the window seen on the way out; as good as known, it went round through space the
// camera had never seen, failing wall after wall (at 4 and 5 m/s the way back timed out in the
// held-out windows world).
TEST(SimFlight, AReturnLegGoesBackThroughTheWindowItCameThrough) {
  World w;
  w.solids.push_back({Eigen::Vector3d(-0.05, -9.95, 0.35), Eigen::Vector3d(0.05, 9.95, 3.65)});
  w.holes.push_back({Eigen::Vector3d(-1.0, 2.4, 0.9), Eigen::Vector3d(1.0, 3.6, 2.1)});  // the window, 1.2 m square
  const Eigen::Vector3d start(-12.0, 6.0, 1.2), there(12.0, 6.0, 1.2), back_to(-12.0, -9.0, 1.2);
  TruthMap::Config tc;
  tc.include_points = {start, there, back_to};
  std::string why;
  const std::shared_ptr<const TruthMap> truth = TruthMap::build(w.points(), tc, &why);
  ASSERT_TRUE(truth) << why;
  double back_s[2] = {0.0, 0.0};
  for (int weighed = 1; weighed >= 0; --weighed) {
    SimFlight::Config c = config(5.0);
    if (!weighed) c.fsm.route.unknown_weight = 0.0;
    // Where the way back crosses the wall.
    bool back = false;
    std::vector<Eigen::Vector3d> crossings;
    Eigen::Vector3d previous = start;
    const SimFlight::Result r = SimFlight::fly(*truth, start, {there, back_to}, c, [&](const SimFlight::Step& s) {
      const Eigen::Vector3d p = s.setpoint.state.position;
      if ((p - there).norm() < 0.6) back = true;
      if (back && previous.x() > 0.0 && p.x() <= 0.0) crossings.push_back(p);
      if (getenv("SIM_TRACE") && (back || s.output) && (std::fmod(s.t_s, 0.5) < 0.005 || s.output))
        std::printf("%d t %.2f (%.1f %.1f %.1f) v %.2f %s\n", weighed, s.t_s, p.x(), p.y(), p.z(), s.setpoint.state.velocity.norm(),
                    s.output && !s.output->message.empty() ? s.output->message.substr(0, 200).c_str() : "");
      previous = p;
    });
    std::printf("unknown weighed %d: %s; %s; the way back %.1f s (oracle %.1f s)\n", weighed, r.message.c_str(),
                formatSimFlight(r).c_str(), r.goals.size() == 2 ? r.goals[1].time_s : NAN,
                r.goals.size() == 2 ? r.goals[1].oracle_time_s : NAN);
    back_s[weighed] = r.goals.size() == 2 && r.goals[1].reached ? r.goals[1].time_s : INFINITY;
    if (!weighed) continue;
    EXPECT_TRUE(r.ok) << r.message;
    EXPECT_EQ(r.collisions, 0);
    ASSERT_EQ(crossings.size(), 1u);
    EXPECT_NEAR(crossings[0].y(), 3.0, 0.6) << "through the window";
    // Back about as fast as a vehicle that knows the map (the way out had to find the window).
    EXPECT_LT(r.goals[1].time_s, 1.5 * r.goals[1].oracle_time_s) << "oracle " << r.goals[1].oracle_time_s << " s";
  }
  EXPECT_LT(back_s[1], 0.8 * back_s[0]) << "weighing unknown space brings it back sooner";
}

}  // namespace
}  // namespace topo_planner
