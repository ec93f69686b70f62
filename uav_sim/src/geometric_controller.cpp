#include "topo_planner/uav_sim/geometric_controller.h"

#include <Eigen/Dense>
#include <cmath>
#include <sstream>

namespace topo_planner {

namespace {
constexpr double kRotorAngles[4] = {M_PI / 4, 3 * M_PI / 4, 5 * M_PI / 4, 7 * M_PI / 4};
constexpr double kSpin[4] = {1.0, -1.0, 1.0, -1.0};

Eigen::Vector3d vee(const Eigen::Matrix3d& m) { return Eigen::Vector3d(m(2, 1), m(0, 2), m(1, 0)); }

bool finiteCommand(const TrackingReference& c) {
  return c.position.allFinite() && c.velocity.allFinite() && c.acceleration.allFinite() && c.jerk.allFinite() &&
         std::isfinite(c.yaw) && std::isfinite(c.yaw_rate);
}
}  // namespace

bool GeometricController::Config::validate(std::string* why) const {
  std::ostringstream err;
  for (const Eigen::Vector3d* g : {&position_gain, &velocity_gain, &attitude_gain, &rate_gain})
    if (!(g->allFinite() && (g->array() > 0.0).all())) {
      err << "gains must be positive; ";
      break;
    }
  if (!(max_tilt_rad > 0.0 && max_tilt_rad < M_PI / 2)) err << "max_tilt_rad must be in (0, pi/2); ";
  if (!(min_thrust_ratio > 0.0 && max_thrust_ratio > 1.0 && min_thrust_ratio < 1.0))
    err << "need 0 < min_thrust_ratio < 1 < max_thrust_ratio (a zero thrust vector has no direction); ";
  const std::string s = err.str();
  if (why) *why = s.empty() ? "" : s.substr(0, s.size() - 2);
  return s.empty();
}

GeometricController::GeometricController(const Config& config, const Quadrotor::Config& vehicle)
    : config_(config), vehicle_(vehicle) {
  Eigen::Matrix4d a;
  for (int i = 0; i < 4; ++i) {
    const double x = vehicle.arm_length_m * std::cos(kRotorAngles[i]), y = vehicle.arm_length_m * std::sin(kRotorAngles[i]);
    a.col(i) << 1.0, y, -x, kSpin[i] * vehicle.moment_coefficient;
  }
  allocation_inverse_ = a.inverse();
}

Eigen::Vector4d GeometricController::mix(double thrust, const Eigen::Vector3d& moment) const {
  const Eigen::Vector4d f = allocation_inverse_ * Eigen::Vector4d(thrust, moment.x(), moment.y(), moment.z());
  Eigen::Vector4d w;
  for (int i = 0; i < 4; ++i) w[i] = std::sqrt(std::max(0.0, f[i]) / vehicle_.thrust_coefficient);
  return w.cwiseMax(vehicle_.min_rotor_speed_radps).cwiseMin(vehicle_.max_rotor_speed_radps);
}

GeometricController::Output GeometricController::compute(const Quadrotor::State& state,
                                                         const TrackingReference& command_in) const {
  Output out;
  TrackingReference command = command_in;
  if (!finiteCommand(command)) {  // hold position rather than fly NaN
    command = TrackingReference();
    command.position = state.position;
    const Eigen::Matrix3d R = state.orientation.toRotationMatrix();
    command.yaw = std::atan2(R(1, 0), R(0, 0));
    out.saturated = true;
  }
  const double m = vehicle_.mass_kg, g = vehicle_.gravity_mps2;
  const Eigen::Matrix3d R = state.orientation.toRotationMatrix();
  const Eigen::Vector3d e_x = state.position - command.position, e_v = state.velocity - command.velocity;

  // Desired thrust vector, limited in tilt and size.
  Eigen::Vector3d acc = -config_.position_gain.cwiseProduct(e_x) - config_.velocity_gain.cwiseProduct(e_v) +
                        command.acceleration + Eigen::Vector3d(0.0, 0.0, g);
  const double min_z = config_.min_thrust_ratio * g;
  if (acc.z() < min_z) {
    acc.z() = min_z;
    out.saturated = true;
  }
  const double horizontal = acc.head<2>().norm(), max_horizontal = acc.z() * std::tan(config_.max_tilt_rad);
  if (horizontal > max_horizontal) {
    acc.head<2>() *= max_horizontal / horizontal;
    out.saturated = true;
  }
  if (acc.norm() > config_.max_thrust_ratio * g) {
    acc *= config_.max_thrust_ratio * g / acc.norm();
    out.saturated = true;
  }
  const Eigen::Vector3d force = m * acc;
  const Eigen::Vector3d b3 = force.normalized();
  const Eigen::Vector3d heading(std::cos(command.yaw), std::sin(command.yaw), 0.0);
  Eigen::Vector3d b2 = b3.cross(heading);
  if (b2.norm() < 1e-6) b2 = b3.cross(Eigen::Vector3d::UnitX());
  b2.normalize();
  Eigen::Matrix3d Rd;
  Rd << b2.cross(b3), b2, b3;
  out.desired_attitude = Rd;
  out.thrust = force.dot(R.col(2));

  // Desired body rates from the jerk (differential flatness) and the yaw rate.
  const double f_des = std::max(force.norm(), 1e-6);
  const Eigen::Vector3d h = (m / f_des) * (command.jerk - b3.dot(command.jerk) * b3);
  const Eigen::Vector3d omega_d(-h.dot(Rd.col(1)), h.dot(Rd.col(0)), command.yaw_rate * b3.z());

  const Eigen::Vector3d e_R = 0.5 * vee(Rd.transpose() * R - R.transpose() * Rd);
  const Eigen::Vector3d e_w = state.angular_velocity - R.transpose() * Rd * omega_d;
  const Eigen::Vector3d& J = vehicle_.inertia_kgm2;
  out.moment = -config_.attitude_gain.cwiseProduct(J).cwiseProduct(e_R) - config_.rate_gain.cwiseProduct(J).cwiseProduct(e_w) +
               state.angular_velocity.cross(J.cwiseProduct(state.angular_velocity));
  out.rotor_speed = mix(out.thrust, out.moment);
  return out;
}

}  // namespace topo_planner
