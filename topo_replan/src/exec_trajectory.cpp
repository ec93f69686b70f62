#include "topo_planner/topo_replan/exec_trajectory.h"

#include <algorithm>

namespace topo_planner {

FlatState ExecTrajectory::stateAt(double t) const {
  const double tau = std::clamp(t - start_time_s, 0.0, spline.duration());
  FlatState st;
  st.position = spline.evaluate(tau);
  const UniformBspline vel = spline.derivative();
  st.velocity = vel.evaluate(tau);
  if (vel.degree() >= 1) {
    const UniformBspline acc = vel.derivative();
    st.acceleration = acc.evaluate(tau);
    if (acc.degree() >= 1) st.jerk = acc.derivative().evaluate(tau);
  }
  if (tau >= spline.duration()) st.velocity = st.acceleration = st.jerk = Eigen::Vector3d::Zero();
  return st;
}

double ExecTrajectory::referenceTimeAt(double t, const PolynomialTrajectory& reference) const {
  if (manoeuvre()) return 0.0;
  const double d = spline.duration();
  const double frac = d > 0.0 ? std::clamp((t - start_time_s) / d, 0.0, 1.0) : 1.0;
  const double estimate = reference_start_s + frac * (reference_end_s - reference_start_s);
  // The local trajectory is timed differently from the reference (detours, time reallocation): take
  // the reference point closest to where the vehicle will be, near the proportional estimate.
  const Eigen::Vector3d p = spline.evaluate(std::clamp(t - start_time_s, 0.0, d));
  double best = estimate, best_d2 = (reference.position(estimate) - p).squaredNorm();
  for (double s = std::max(0.0, estimate - 2.0); s <= std::min(reference.duration(), estimate + 2.0); s += 0.01) {
    const double d2 = (reference.position(s) - p).squaredNorm();
    if (d2 < best_d2) best = s, best_d2 = d2;
  }
  return best;
}

}  // namespace topo_planner
