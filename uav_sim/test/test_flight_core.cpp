// The simulated quadrotor under the geometric controller: hover and circle tracking within stated
// errors, physics sanity checks, and bad commands.
#include <gtest/gtest.h>

#include <cmath>

#include "topo_planner/uav_sim/geometric_controller.h"

namespace topo_planner {
namespace {

constexpr double kDt = 0.001;  // 1 kHz

struct Sim {
  Quadrotor quad{Quadrotor::Config()};
  GeometricController ctrl{GeometricController::Config(), Quadrotor::Config()};
  // Runs the controller at 1 kHz (as the node does) for `seconds`, following command(t).
  template <typename CommandFn>
  double run(double t0, double seconds, CommandFn&& command, double settle = 0.0) {
    double max_error = 0.0;
    const int steps = int(std::lround(seconds / kDt));
    for (int k = 0; k < steps; ++k) {
      const double t = t0 + k * kDt;
      const TrackingReference c = command(t);
      quad.setRotorSpeedCommand(ctrl.compute(quad.state(), c).rotor_speed);
      quad.step(kDt);
      if (t - t0 >= settle) max_error = std::max(max_error, (quad.state().position - command(t + kDt).position).norm());
    }
    return max_error;
  }
};

TEST(Quadrotor, FreeFallAndHoverPhysics) {
  Quadrotor q{Quadrotor::Config()};
  // Rotors at hover speed: stays put.
  for (int k = 0; k < 1000; ++k) q.step(kDt);
  EXPECT_LT(q.state().position.norm(), 1e-6);
  // Rotors at minimum: falls at about g (minus the little thrust and drag).
  q.setRotorSpeedCommand(Eigen::Vector4d::Zero());
  Quadrotor::State s = q.state();
  s.rotor_speed.setZero();
  q.setState(s);
  for (int k = 0; k < 500; ++k) q.step(kDt);
  EXPECT_NEAR(q.state().velocity.z(), -9.81 * 0.5, 0.25);
  EXPECT_NEAR(q.state().orientation.w(), 1.0, 1e-9);  // no torque, no rotation
  // A NaN rotor command is ignored.
  q.setRotorSpeedCommand(Eigen::Vector4d::Constant(NAN));
  EXPECT_TRUE(q.rotorSpeedCommand().allFinite());
}

TEST(GeometricController, MixerReproducesThrustAndMoments) {
  const Quadrotor::Config v;
  GeometricController ctrl(GeometricController::Config(), v);
  const double thrust = 12.0;
  const Eigen::Vector3d moment(0.05, -0.03, 0.01);
  const Eigen::Vector4d w = ctrl.mix(thrust, moment);
  // Forces back from the rotor speeds, through the quadrotor's own model (one step of derivative).
  Quadrotor q(v);
  Quadrotor::State s;
  s.rotor_speed = w;
  q.setState(s);
  q.setRotorSpeedCommand(w);
  q.step(1e-6);
  const Eigen::Vector3d w_dot = q.state().angular_velocity / 1e-6;
  EXPECT_NEAR(v.thrust_coefficient * w.squaredNorm(), thrust, 1e-6);
  for (int k = 0; k < 3; ++k) EXPECT_NEAR(w_dot[k] * v.inertia_kgm2[k], moment[k], 1e-4);
}

TEST(GeometricController, HoversAndRecoversFromAnOffset) {
  Sim sim;
  Quadrotor::State s;
  s.position = {0.5, -0.3, 0.8};
  s.orientation = Eigen::Quaterniond(Eigen::AngleAxisd(0.17, Eigen::Vector3d(1, 1, 0).normalized()));
  s.rotor_speed.setConstant(sim.quad.hoverRotorSpeed());
  sim.quad.setState(s);
  TrackingReference hold;
  hold.position = {0.0, 0.0, 1.0};
  hold.yaw = 0.5;
  sim.run(0.0, 5.0, [&](double) { return hold; });
  EXPECT_LT((sim.quad.state().position - hold.position).norm(), 0.01);
  EXPECT_LT(sim.quad.state().velocity.norm(), 0.01);
  const Eigen::Matrix3d R = sim.quad.state().orientation.toRotationMatrix();
  EXPECT_NEAR(std::atan2(R(1, 0), R(0, 0)), 0.5, 0.01);
  // Holding for 2 more seconds: stays within 5 mm.
  EXPECT_LT(sim.run(5.0, 2.0, [&](double) { return hold; }), 0.005);
}

TEST(GeometricController, TracksACircle) {
  // Radius 1.5 m at 2 m/s (centripetal acceleration 2.7 m/s^2), yaw along the velocity.
  const double r = 1.5, speed = 2.0, w = speed / r;
  auto circle = [&](double t) {
    TrackingReference c;
    c.position = {r * std::cos(w * t), r * std::sin(w * t), 1.5};
    c.velocity = {-r * w * std::sin(w * t), r * w * std::cos(w * t), 0.0};
    c.acceleration = {-r * w * w * std::cos(w * t), -r * w * w * std::sin(w * t), 0.0};
    c.jerk = {r * w * w * w * std::sin(w * t), -r * w * w * w * std::cos(w * t), 0.0};
    c.yaw = w * t + M_PI / 2;
    c.yaw_rate = w;
    return c;
  };
  Sim sim;
  Quadrotor::State s;
  s.position = circle(0.0).position;
  s.velocity = circle(0.0).velocity;
  s.rotor_speed.setConstant(sim.quad.hoverRotorSpeed());
  sim.quad.setState(s);
  // Two laps; after a 1 s transient the position error stays below 5 cm.
  const double laps = 2.0 * (2.0 * M_PI / w);
  EXPECT_LT(sim.run(0.0, laps, circle, 1.0), 0.05);
}

TEST(GeometricController, NonFiniteCommandHoldsPosition) {
  Sim sim;
  Quadrotor::State s;
  s.position = {1.0, 2.0, 3.0};
  s.rotor_speed.setConstant(sim.quad.hoverRotorSpeed());
  sim.quad.setState(s);
  TrackingReference bad;
  bad.position = {NAN, 0.0, 0.0};
  const GeometricController::Output o = sim.ctrl.compute(sim.quad.state(), bad);
  EXPECT_TRUE(o.saturated);
  EXPECT_TRUE(o.rotor_speed.allFinite());
  sim.run(0.0, 2.0, [&](double) { return bad; });
  EXPECT_LT((sim.quad.state().position - s.position).norm(), 0.05);
}

TEST(GeometricController, TiltAndThrustAreLimited) {
  Sim sim;
  TrackingReference far;
  far.position = {100.0, 0.0, 1.0};  // a huge step: the thrust vector saturates at max_tilt
  const GeometricController::Output o = sim.ctrl.compute(sim.quad.state(), far);
  EXPECT_TRUE(o.saturated);
  const double tilt = std::acos(o.desired_attitude(2, 2));
  EXPECT_NEAR(tilt, GeometricController::Config().max_tilt_rad, 1e-6);
  std::string why;
  GeometricController::Config bad;
  bad.max_tilt_rad = 2.0;
  EXPECT_FALSE(bad.validate(&why));
  bad = GeometricController::Config();
  bad.min_thrust_ratio = 0.0;
  EXPECT_FALSE(bad.validate(&why));
  // A command far below: the thrust vector is clamped to the minimum, still vertical and finite.
  TrackingReference below;
  below.position = {0.0, 0.0, -100.0};
  const GeometricController::Output low = sim.ctrl.compute(sim.quad.state(), below);
  EXPECT_TRUE(low.rotor_speed.allFinite() && low.moment.allFinite());
  EXPECT_NEAR(low.desired_attitude.col(2).z(), 1.0, 1e-9);
  Quadrotor::Config weak;
  weak.max_rotor_speed_radps = 100.0;
  EXPECT_FALSE(weak.validate(&why));
}

}  // namespace
}  // namespace topo_planner
