#include "topo_planner/uav_sim/quadrotor.h"

#include <cmath>
#include <sstream>

namespace topo_planner {

namespace {
// X configuration: rotor i at angle 45 + 90 i degrees, spinning alternately (drag torque sign).
constexpr double kRotorAngles[4] = {M_PI / 4, 3 * M_PI / 4, 5 * M_PI / 4, 7 * M_PI / 4};
constexpr double kSpin[4] = {1.0, -1.0, 1.0, -1.0};

Eigen::Vector4d quaternionProduct(const Eigen::Vector4d& q, const Eigen::Vector3d& w) {
  // q (w, x, y, z) times the pure quaternion (0, w).
  return Eigen::Vector4d(-q[1] * w.x() - q[2] * w.y() - q[3] * w.z(), q[0] * w.x() + q[2] * w.z() - q[3] * w.y(),
                         q[0] * w.y() - q[1] * w.z() + q[3] * w.x(), q[0] * w.z() + q[1] * w.y() - q[2] * w.x());
}
}  // namespace

bool Quadrotor::Config::validate(std::string* why) const {
  std::ostringstream err;
  if (!(mass_kg > 0.0)) err << "mass_kg must be positive; ";
  if (!(inertia_kgm2.allFinite() && (inertia_kgm2.array() > 0.0).all())) err << "inertia_kgm2 must be positive; ";
  if (!(arm_length_m > 0.0 && thrust_coefficient > 0.0 && moment_coefficient > 0.0))
    err << "arm_length_m, thrust_coefficient and moment_coefficient must be positive; ";
  if (!(motor_time_constant_s > 0.0)) err << "motor_time_constant_s must be positive; ";
  if (!(max_rotor_speed_radps > min_rotor_speed_radps && min_rotor_speed_radps >= 0.0))
    err << "need 0 <= min_rotor_speed_radps < max_rotor_speed_radps; ";
  if (4.0 * thrust_coefficient * max_rotor_speed_radps * max_rotor_speed_radps <= mass_kg * gravity_mps2)
    err << "the rotors cannot lift the mass; ";
  const std::string s = err.str();
  if (why) *why = s.empty() ? "" : s.substr(0, s.size() - 2);
  return s.empty();
}

Quadrotor::Quadrotor(const Config& config) : config_(config) {
  state_.rotor_speed.setConstant(hoverRotorSpeed());
  command_ = state_.rotor_speed;
}

double Quadrotor::hoverRotorSpeed() const {
  return std::sqrt(config_.mass_kg * config_.gravity_mps2 / (4.0 * config_.thrust_coefficient));
}

void Quadrotor::setRotorSpeedCommand(const Eigen::Vector4d& command) {
  if (!command.allFinite()) return;
  command_ = command.cwiseMax(config_.min_rotor_speed_radps).cwiseMin(config_.max_rotor_speed_radps);
}

Quadrotor::Derivative Quadrotor::derivative(const Eigen::Vector3d& v, const Eigen::Vector4d& q, const Eigen::Vector3d& w,
                                            const Eigen::Vector4d& rotor) const {
  const Config& c = config_;
  const Eigen::Vector4d f = c.thrust_coefficient * rotor.cwiseProduct(rotor);
  Eigen::Vector3d moment = Eigen::Vector3d::Zero();
  for (int i = 0; i < 4; ++i) {
    const double x = c.arm_length_m * std::cos(kRotorAngles[i]), y = c.arm_length_m * std::sin(kRotorAngles[i]);
    moment += Eigen::Vector3d(y * f[i], -x * f[i], kSpin[i] * c.moment_coefficient * f[i]);
  }
  const Eigen::Quaterniond quat(q[0], q[1], q[2], q[3]);
  const Eigen::Matrix3d R = quat.normalized().toRotationMatrix();
  const Eigen::Vector3d drag = R * c.drag_coefficient.cwiseProduct(R.transpose() * v);
  Derivative d;
  d.dp = v;
  d.dv = (R * Eigen::Vector3d(0.0, 0.0, f.sum()) - drag) / c.mass_kg - Eigen::Vector3d(0.0, 0.0, c.gravity_mps2);
  d.dq = 0.5 * quaternionProduct(q, w);
  const Eigen::Vector3d Jw = c.inertia_kgm2.cwiseProduct(w);
  d.dw = (moment - w.cross(Jw)).cwiseQuotient(c.inertia_kgm2);
  d.drotor = (command_ - rotor) / c.motor_time_constant_s;
  return d;
}

void Quadrotor::step(double dt) {
  if (!(dt > 0.0) || !std::isfinite(dt)) return;
  const Eigen::Vector3d p0 = state_.position, v0 = state_.velocity, w0 = state_.angular_velocity;
  const Eigen::Vector4d q0(state_.orientation.w(), state_.orientation.x(), state_.orientation.y(), state_.orientation.z());
  const Eigen::Vector4d r0 = state_.rotor_speed;
  const Derivative k1 = derivative(v0, q0, w0, r0);
  const Derivative k2 = derivative(v0 + 0.5 * dt * k1.dv, q0 + 0.5 * dt * k1.dq, w0 + 0.5 * dt * k1.dw, r0 + 0.5 * dt * k1.drotor);
  const Derivative k3 = derivative(v0 + 0.5 * dt * k2.dv, q0 + 0.5 * dt * k2.dq, w0 + 0.5 * dt * k2.dw, r0 + 0.5 * dt * k2.drotor);
  const Derivative k4 = derivative(v0 + dt * k3.dv, q0 + dt * k3.dq, w0 + dt * k3.dw, r0 + dt * k3.drotor);
  auto avg = [dt](const auto& a, const auto& b, const auto& c, const auto& d) { return (dt / 6.0) * (a + 2.0 * b + 2.0 * c + d); };
  state_.position = p0 + avg(k1.dp, k2.dp, k3.dp, k4.dp);
  state_.velocity = v0 + avg(k1.dv, k2.dv, k3.dv, k4.dv);
  const Eigen::Vector4d q = q0 + avg(k1.dq, k2.dq, k3.dq, k4.dq);
  state_.orientation = Eigen::Quaterniond(q[0], q[1], q[2], q[3]).normalized();
  state_.angular_velocity = w0 + avg(k1.dw, k2.dw, k3.dw, k4.dw);
  state_.rotor_speed = r0 + avg(k1.drotor, k2.drotor, k3.drotor, k4.drotor);
  state_.acceleration = (state_.velocity - v0) / dt;
}

}  // namespace topo_planner
