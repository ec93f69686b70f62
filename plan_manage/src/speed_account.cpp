#include "topo_planner/plan_manage/speed_account.h"

#include <algorithm>
#include <cmath>

namespace topo_planner {

const char* toString(SlowCause cause) {
  switch (cause) {
    case SlowCause::kHeld: return "held";
    case SlowCause::kBraking: return "braking";
    case SlowCause::kCommitment: return "commitment";
    case SlowCause::kTakeover: return "takeover";
    case SlowCause::kTracking: return "tracking";
    case SlowCause::kLimits: return "limits";
    case SlowCause::kTiming: return "timing";
  }
  return "unknown";
}

bool SpeedAccount::Config::validate(std::string* why) const {
  std::string e;
  auto positive = [&](double x, const char* name) {
    if (!(std::isfinite(x) && x > 0.0)) e += std::string(name) + " must be positive; ";
  };
  positive(max_vel_mps, "max_vel_mps");
  positive(max_acc_mps2, "max_acc_mps2");
  positive(held_speed_mps, "held_speed_mps");
  positive(held_acc_mps2, "held_acc_mps2");
  positive(max_gap_s, "max_gap_s");
  if (!(fast_fraction > 0.0 && fast_fraction <= 1.0)) e += "fast_fraction must be in (0, 1]; ";
  if (!(limit_fraction > 0.0 && limit_fraction <= 1.0)) e += "limit_fraction must be in (0, 1]; ";
  if (!(std::isfinite(takeover_window_s) && takeover_window_s >= 0.0)) e += "takeover_window_s must be >= 0; ";
  if (!(std::isfinite(takeover_loss_mps) && takeover_loss_mps >= 0.0)) e += "takeover_loss_mps must be >= 0; ";
  if (max_trajectories < 2) e += "max_trajectories must be at least 2; ";
  if (why) *why = e.empty() ? "" : e.substr(0, e.size() - 2);
  return e.empty();
}

double SpeedAccount::Totals::slow() const {
  double sum = 0.0;
  for (const double s : slow_s) sum += s;
  return sum;
}

double SpeedAccount::Totals::share(SlowCause cause) const {
  const double all = slow();
  return all > 0.0 ? slow_s[size_t(cause)] / all : 0.0;
}

SpeedAccount::SpeedAccount() : SpeedAccount(Config()) {}
SpeedAccount::SpeedAccount(const Config& config) : config_(config) {}

void SpeedAccount::addTrajectory(const Trajectory& trajectory) {
  if (!std::isfinite(trajectory.start_s) || std::isnan(trajectory.brake_start_s) || !trajectory.spline.isValid())
    return;
  for (Trajectory& t : trajectories_)
    if (t.session == trajectory.session && t.id == trajectory.id) {
      t = trajectory;
      return;
    }
  trajectories_.push_back(trajectory);
  while (trajectories_.size() > config_.max_trajectories) trajectories_.pop_front();
}

void SpeedAccount::setSetpoint(const Setpoint& setpoint) {
  if (!setpoint.velocity.allFinite() || !setpoint.acceleration.allFinite()) return;
  setpoint_ = setpoint;
  have_setpoint_ = true;
}

const SpeedAccount::Trajectory* SpeedAccount::find(uint64_t session, int64_t id) const {
  for (auto it = trajectories_.rbegin(); it != trajectories_.rend(); ++it)
    if (it->session == session && it->id == id) return &*it;
  return nullptr;
}

const SpeedAccount::Trajectory* SpeedAccount::replaced(const Trajectory& traj) const {
  const Trajectory* best = nullptr;
  for (const Trajectory& t : trajectories_)
    if (t.session == traj.session && t.id != traj.id && t.start_s < traj.start_s && (!best || t.start_s > best->start_s))
      best = &t;
  return best;
}

namespace {
double speedOf(const UniformBspline& spline, double tau) {
  if (tau < 0.0 || tau > spline.duration()) return 0.0;
  return spline.derivative().evaluate(tau).norm();
}
}  // namespace

SlowCause SpeedAccount::classify(double t, double speed, bool* fast) const {
  const double v_fast = config_.fast_fraction * config_.max_vel_mps;
  *fast = speed >= v_fast;
  if (!have_setpoint_ || setpoint_.mode == Mode::kHold) return SlowCause::kHeld;
  if (setpoint_.mode == Mode::kStopping) return SlowCause::kBraking;
  const Trajectory* traj = find(setpoint_.session, setpoint_.trajectory_id);
  if (traj && traj->kind == TrajectoryKind::kBraking) return SlowCause::kBraking;
  if (traj && traj->kind == TrajectoryKind::kManoeuvre) return SlowCause::kHeld;
  const Eigen::Vector3d& v = setpoint_.velocity;
  const Eigen::Vector3d& a = setpoint_.acceleration;
  const double cmd_speed = v.norm();
  if (traj && t >= traj->brake_start_s && traj->brake_start_s < traj->start_s + traj->spline.duration() - 1e-6)
    return SlowCause::kCommitment;
  if (cmd_speed < config_.held_speed_mps && a.norm() < config_.held_acc_mps2) return SlowCause::kHeld;
  if (traj && t - traj->start_s <= config_.takeover_window_s) {
    const Trajectory* before = replaced(*traj);
    // A plan that took over from the committed stop of the one before (its brake point passed
    // first): the speed it starts from was lost to the commitment.
    if (before && before->kind == TrajectoryKind::kPlan && before->brake_start_s < traj->start_s - 1e-6 &&
        before->brake_start_s < before->start_s + before->spline.duration() - 1e-6)
      return SlowCause::kCommitment;
    if (before && before->kind == TrajectoryKind::kPlan && t < before->brake_start_s) {
      const double would = speedOf(before->spline, t - before->start_s);
      if (would - cmd_speed > config_.takeover_loss_mps) return SlowCause::kTakeover;
    }
  }
  if (cmd_speed >= v_fast) return SlowCause::kTracking;
  const double limit = config_.limit_fraction * config_.max_acc_mps2;
  double along = 0.0, normal = a.norm();
  if (cmd_speed > 1e-6) {
    along = a.dot(v) / cmd_speed;
    normal = (a - along * v / cmd_speed).norm();
  }
  if (std::abs(along) >= limit || normal >= limit) return SlowCause::kLimits;
  return SlowCause::kTiming;
}

void SpeedAccount::addSpeed(double t_s, double speed_mps) {
  if (!std::isfinite(t_s) || !std::isfinite(speed_mps)) return;
  if (have_sample_ && t_s > last_t_s_ && t_s - last_t_s_ <= config_.max_gap_s) {
    const double dt = t_s - last_t_s_;
    bool fast = false;
    const SlowCause cause = classify(last_t_s_, last_speed_mps_, &fast);
    totals_.total_s += dt;
    if (fast)
      totals_.fast_s += dt;
    else
      totals_.slow_s[size_t(cause)] += dt;
  }
  if (!have_sample_ || t_s >= last_t_s_) {
    have_sample_ = true;
    last_t_s_ = t_s;
    last_speed_mps_ = speed_mps;
  }
}

}  // namespace topo_planner
