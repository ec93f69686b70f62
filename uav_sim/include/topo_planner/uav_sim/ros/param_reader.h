#pragma once
// Parameter reading of every node (the readXParams() functions): the config struct's value
// is the ROS default, a parameter of the wrong type is an error (nh.param would silently fall back to
// the default), and private parameters nobody asked for are reported as likely typos.

#include <ros/console.h>
#include <ros/node_handle.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <set>
#include <sstream>
#include <string>
#include <vector>

#include "topo_planner/uav_sim/quadrotor.h"

namespace topo_planner {

class ParamReader {
 public:
  explicit ParamReader(const ros::NodeHandle& nh) : nh_(nh) {}

  template <typename T>
  void read(const std::string& name, T& value) {
    known_.insert(nh_.resolveName(name));
    const T default_value = value;
    nh_.param(name, value, default_value);
    T probe;
    if (nh_.hasParam(name) && !nh_.getParam(name, probe)) {
      errors_ << name << " has the wrong type; ";
      value = default_value;
    }
  }
  /// An unsigned value (seeds): read as int, must be >= 0.
  void readUnsigned(const std::string& name, uint32_t& value) {
    int v = int(value);
    read(name, v);
    if (v < 0)
      errors_ << name << " must be >= 0; ";
    else
      value = uint32_t(v);
  }
  /// A list of 3 numbers.
  void readVector3(const std::string& name, Eigen::Vector3d& v) {
    std::vector<double> d{v.x(), v.y(), v.z()};
    read(name, d);
    if (d.size() != 3) {
      errors_ << name << " must be a list of 3 numbers; ";
      return;
    }
    v = Eigen::Vector3d(d[0], d[1], d[2]);
  }
  /// A rigid transform as `<prefix>/translation_m` [x, y, z] and `<prefix>/quaternion_xyzw`.
  void readTransform(const std::string& prefix, Eigen::Isometry3d& T) {
    const Eigen::Quaterniond q0(T.linear());
    Eigen::Vector3d t = T.translation();
    std::vector<double> q{q0.x(), q0.y(), q0.z(), q0.w()};
    readVector3(prefix + "/translation_m", t);
    read(prefix + "/quaternion_xyzw", q);
    if (q.size() != 4) {
      errors_ << prefix << "/quaternion_xyzw must hold 4 numbers; ";
      return;
    }
    Eigen::Quaterniond quat(q[3], q[0], q[1], q[2]);
    const double n = quat.norm();
    if (!std::isfinite(n) || std::abs(n - 1.0) > 1e-2 || !t.allFinite()) {
      errors_ << prefix << " must be finite with a unit quaternion [x, y, z, w]; ";
      return;
    }
    quat.coeffs() /= n;
    T.setIdentity();
    T.linear() = quat.toRotationMatrix();
    T.translation() = t;
  }

  /// Parameters under this private sub-namespace are read elsewhere (not reported as unknown).
  void skipNamespace(const std::string& sub) { skipped_.insert(nh_.resolveName(sub) + "/"); }

  bool has(const std::string& name) const { return nh_.hasParam(name); }
  std::ostringstream& errors() { return errors_; }

  /// Logs unknown private parameters (ROS_WARN) and, with the config's own range check `range_errors`
  /// ("" when valid), every error (ROS_ERROR). Returns true when there is none.
  bool finish(const char* node, const std::string& range_errors) {
    std::vector<std::string> all;
    if (nh_.getParamNames(all)) {
      const std::string prefix = nh_.getNamespace() + "/";
      for (const std::string& p : all)
        if (p.compare(0, prefix.size(), prefix) == 0 && !known_.count(p) &&
            std::none_of(skipped_.begin(), skipped_.end(),
                         [&](const std::string& s) { return p.compare(0, s.size(), s) == 0; }))
          ROS_WARN("%s: ignoring unknown parameter %s (typo?)", node, p.c_str());
    }
    std::string why = errors_.str();
    if (!range_errors.empty()) why += range_errors + "; ";
    if (why.empty()) return true;
    ROS_ERROR("%s: invalid parameters in %s: %s", node, nh_.getNamespace().c_str(),
              why.substr(0, why.size() - 2).c_str());
    return false;
  }

 private:
  const ros::NodeHandle& nh_;
  std::set<std::string> known_;
  std::set<std::string> skipped_;
  std::ostringstream errors_;
};

/// Reads vehicle/* (the airframe: config/vehicle.yaml, loaded into both the simulator and the
/// controller so that the controller's model is the simulated vehicle unless told otherwise).
inline void readVehicleParams(ParamReader& r, Quadrotor::Config* vehicle) {
  Quadrotor::Config& v = *vehicle;
  r.read("vehicle/mass_kg", v.mass_kg);
  r.readVector3("vehicle/inertia_kgm2", v.inertia_kgm2);
  r.read("vehicle/arm_length_m", v.arm_length_m);
  r.read("vehicle/thrust_coefficient", v.thrust_coefficient);
  r.read("vehicle/moment_coefficient", v.moment_coefficient);
  r.read("vehicle/motor_time_constant_s", v.motor_time_constant_s);
  r.read("vehicle/max_rotor_speed_radps", v.max_rotor_speed_radps);
  r.read("vehicle/min_rotor_speed_radps", v.min_rotor_speed_radps);
  r.readVector3("vehicle/drag_coefficient", v.drag_coefficient);
  r.read("vehicle/gravity_mps2", v.gravity_mps2);
}

}  // namespace topo_planner
