#pragma once
// Rigid-body quadrotor in the world frame (z up), X configuration, for the closed-loop simulation:
// four rotors with first-order speed dynamics, thrust k_f w^2 and drag torque k_m w^2 per rotor,
// linear body-frame air drag, integrated with classical Runge-Kutta 4. The controller commands rotor
// speeds; GeometricController::mix turns thrust and moments into them.

#include <Eigen/Geometry>
#include <string>

namespace topo_planner {

class Quadrotor {
 public:
  struct Config {
    double mass_kg = 0.98;                               ///< [kg]
    Eigen::Vector3d inertia_kgm2{2.64e-3, 2.64e-3, 4.96e-3};  ///< principal moments of inertia [kg m^2]
    double arm_length_m = 0.17;                          ///< rotor centre to body centre [m]
    double thrust_coefficient = 8.55e-6;                 ///< k_f: thrust = k_f w^2 [N s^2]
    double moment_coefficient = 1.6e-2;                  ///< k_m: drag torque = k_m * thrust [m]
    double motor_time_constant_s = 0.02;                 ///< first-order rotor speed lag [s]
    double max_rotor_speed_radps = 1100.0;               ///< [rad/s]
    double min_rotor_speed_radps = 50.0;                 ///< [rad/s]
    Eigen::Vector3d drag_coefficient{0.10, 0.10, 0.15};  ///< linear air drag per body axis [N s/m]
    double gravity_mps2 = 9.81;                          ///< [m/s^2]

    bool validate(std::string* why) const;
  };
  struct State {
    Eigen::Vector3d position = Eigen::Vector3d::Zero();
    Eigen::Vector3d velocity = Eigen::Vector3d::Zero();            ///< world frame [m/s]
    Eigen::Quaterniond orientation = Eigen::Quaterniond::Identity();  ///< body to world
    Eigen::Vector3d angular_velocity = Eigen::Vector3d::Zero();    ///< body frame [rad/s]
    Eigen::Vector4d rotor_speed = Eigen::Vector4d::Zero();         ///< [rad/s]
    Eigen::Vector3d acceleration = Eigen::Vector3d::Zero();        ///< world frame, of the last step [m/s^2]
  };

  explicit Quadrotor(const Config& config);
  const Config& config() const { return config_; }
  const State& state() const { return state_; }
  void setState(const State& state) { state_ = state; }

  /// Rotor speed commands [rad/s]; clamped to the rotor limits, NaN commands ignored.
  void setRotorSpeedCommand(const Eigen::Vector4d& command);
  const Eigen::Vector4d& rotorSpeedCommand() const { return command_; }
  /// Advances by dt_s (RK4; call at 1 kHz).
  void step(double dt_s);

  /// Rotor speeds that hover (all equal).
  double hoverRotorSpeed() const;

 private:
  struct Derivative {
    Eigen::Vector3d dp, dv;
    Eigen::Vector4d dq;
    Eigen::Vector3d dw;
    Eigen::Vector4d drotor;
  };
  Derivative derivative(const Eigen::Vector3d& v, const Eigen::Vector4d& q, const Eigen::Vector3d& w,
                        const Eigen::Vector4d& rotor) const;

  Config config_;
  State state_;
  Eigen::Vector4d command_ = Eigen::Vector4d::Zero();
};

}  // namespace topo_planner
