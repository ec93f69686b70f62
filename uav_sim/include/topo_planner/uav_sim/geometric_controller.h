#pragma once
// Geometric tracking controller on SE(3) (Lee, Leok and McClamroch, "Geometric tracking control of
// a quadrotor UAV on SE(3)", CDC 2010): position and velocity errors give the desired thrust vector
// (with feed-forward acceleration), its direction and the desired yaw give the desired attitude, and
// attitude and body-rate errors give the moments. The thrust vector is limited in tilt and size, and
// mix() maps thrust and moments to rotor speeds of the X-configuration Quadrotor.

#include <Eigen/Geometry>
#include <string>

#include "topo_planner/uav_sim/quadrotor.h"

namespace topo_planner {

/// A tracking reference: what the trajectory server sends (the content of a
/// topo_planner/PositionCommand message; the generated message type lives in this namespace too,
/// hence the other name).
struct TrackingReference {
  Eigen::Vector3d position = Eigen::Vector3d::Zero();
  Eigen::Vector3d velocity = Eigen::Vector3d::Zero();
  Eigen::Vector3d acceleration = Eigen::Vector3d::Zero();
  Eigen::Vector3d jerk = Eigen::Vector3d::Zero();
  double yaw = 0.0;       ///< [rad]
  double yaw_rate = 0.0;  ///< [rad/s]
};

class GeometricController {
 public:
  struct Config {
    Eigen::Vector3d position_gain{10.0, 10.0, 12.0};  ///< k_x / mass [1/s^2]
    Eigen::Vector3d velocity_gain{6.0, 6.0, 7.0};     ///< k_v / mass [1/s]
    Eigen::Vector3d attitude_gain{250.0, 250.0, 60.0};  ///< k_R / inertia [1/s^2]
    Eigen::Vector3d rate_gain{30.0, 30.0, 12.0};    ///< k_Omega / inertia [1/s]
    double max_tilt_rad = 0.7;                     ///< largest angle of the thrust vector from vertical [rad]
    double min_thrust_ratio = 0.2;                 ///< thrust limits as multiples of the hover thrust
    double max_thrust_ratio = 2.2;

    bool validate(std::string* why) const;
  };
  struct Output {
    double thrust = 0.0;                            ///< [N]
    Eigen::Vector3d moment = Eigen::Vector3d::Zero();  ///< body frame [N m]
    Eigen::Vector4d rotor_speed = Eigen::Vector4d::Zero();  ///< [rad/s]
    Eigen::Matrix3d desired_attitude = Eigen::Matrix3d::Identity();
    bool saturated = false;  ///< tilt or thrust limited
  };

  GeometricController(const Config& config, const Quadrotor::Config& vehicle);
  /// Control output for the state and command; a command with NaN/inf is replaced by hovering where
  /// the vehicle is (and saturated is set).
  Output compute(const Quadrotor::State& state, const TrackingReference& command) const;
  /// Rotor speeds giving thrust [N] and body moments [N m], clamped to the rotor limits.
  Eigen::Vector4d mix(double thrust, const Eigen::Vector3d& moment) const;

 private:
  Config config_;
  Quadrotor::Config vehicle_;
  Eigen::Matrix4d allocation_inverse_;  // [f1..f4] = A^-1 [T, Mx, My, Mz]
};

}  // namespace topo_planner
