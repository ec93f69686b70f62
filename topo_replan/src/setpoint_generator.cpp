#include "topo_replan/setpoint_generator.h"

#include <algorithm>
#include <cmath>

namespace topo_planner {

bool SetpointGenerator::Config::validate(std::string* why) const {
  auto bad = [&](const char* m) {
    if (why) *why = m;
    return false;
  };
  if (!(max_yaw_rate_radps > 0.0) || !std::isfinite(max_yaw_rate_radps)) return bad("max_yaw_rate_radps must be positive");
  if (!(lookahead_s > 0.0) || !std::isfinite(lookahead_s)) return bad("lookahead_s must be positive");
  if (!(min_displacement_m >= 0.0) || !std::isfinite(min_displacement_m)) return bad("min_displacement_m must be >= 0");
  if (max_queued < 1) return bad("max_queued must be >= 1");
  return true;
}

bool SetpointGenerator::add(int64_t id, double start_time_s, const UniformBspline& spline) {
  if (!std::isfinite(start_time_s) || id <= last_id_ || !spline.isValid() || spline.degree() < 3) return false;
  Entry e{id, start_time_s, spline, spline.derivative(), {}, {}};
  e.acc = e.vel.derivative();
  e.jerk = e.acc.derivative();
  while (!queue_.empty() && queue_.back().start >= start_time_s) queue_.pop_back();
  if (int(queue_.size()) >= config_.max_queued) queue_.pop_front();
  queue_.push_back(std::move(e));
  last_id_ = id;
  return true;
}

void SetpointGenerator::setYaw(double yaw) {
  if (std::isfinite(yaw)) yaw_ = yaw;
}

bool SetpointGenerator::sample(double t, Setpoint* out) {
  if (!std::isfinite(t)) return false;
  // The newest queued trajectory whose start has come takes over.
  while (!queue_.empty() && queue_.front().start <= t) {
    current_ = std::move(queue_.front());
    queue_.pop_front();
    active_ = true;
  }
  if (!active_) return false;
  const double duration = current_.pos.duration();
  const double tau = std::clamp(t - current_.start, 0.0, duration);
  Setpoint sp;
  sp.trajectory_id = current_.id;
  sp.holding = t - current_.start > duration;
  sp.state.position = current_.pos.evaluate(tau);
  if (!sp.holding) {
    sp.state.velocity = current_.vel.evaluate(tau);
    sp.state.acceleration = current_.acc.evaluate(tau);
    sp.state.jerk = current_.jerk.evaluate(tau);
  }

  // Heading along the displacement over the look-ahead, rate limited.
  const double dt = last_t_ < 0.0 ? 0.0 : std::max(0.0, t - last_t_);
  last_t_ = t;
  const Eigen::Vector3d ahead = current_.pos.evaluate(std::min(duration, tau + config_.lookahead_s)) - sp.state.position;
  double target = yaw_;
  if (ahead.head<2>().norm() >= config_.min_displacement_m) target = std::atan2(ahead.y(), ahead.x());
  const double error = std::remainder(target - yaw_, 2.0 * M_PI);
  const double step = std::clamp(error, -config_.max_yaw_rate_radps * dt, config_.max_yaw_rate_radps * dt);
  yaw_ = std::remainder(yaw_ + step, 2.0 * M_PI);
  sp.yaw = yaw_;
  sp.yaw_rate = dt > 0.0 ? step / dt : 0.0;
  *out = sp;
  return true;
}

}  // namespace topo_planner
