#include "topo_planner/topo_replan/server_link.h"

#include <algorithm>
#include <cmath>

namespace topo_planner {

bool ServerLink::set(const ServerSetpoint& setpoint) {
  if (!std::isfinite(setpoint.stamp_s) || !setpoint.position.allFinite() || !setpoint.velocity.allFinite()) return false;
  if (std::isfinite(setpoint.arrival_s) && setpoint.stamp_s - setpoint.arrival_s > config_.timeout_s) return false;
  if (latest_ && setpoint.stamp_s < latest_->stamp_s) return false;  // out of order
  latest_ = setpoint;
  return true;
}

bool ServerLink::freshAt(double t) const { return latest_ && std::abs(t - latest_->stamp_s) <= config_.timeout_s; }

std::optional<Eigen::Vector3d> ServerLink::holdAt(double t) const {
  if (latest_ && (latest_->mode == ServerSetpoint::Mode::kHold || latest_->mode == ServerSetpoint::Mode::kBeforeFirst) &&
      std::abs(t - latest_->stamp_s) <= config_.timeout_s + 1.0)
    return latest_->position;
  return std::nullopt;
}

void ServerLink::shift(const InputMonitor::TimeJump& jump) {
  if (latest_) jump.shiftStamp(&latest_->stamp_s);
  jump.shiftStamp(&anchor_s_);
}

ServerLink::Verdict ServerLink::judge(double t, const ExecTrajectory* current, const ExecTrajectory* previous,
                                      const std::function<FlatState(double)>& commanded_at) {
  Verdict v;
  if (!freshAt(t)) return v;
  const ServerSetpoint& sp = *latest_;
  // A setpoint sampled before the last re-anchoring predates it: nothing new.
  if (sp.stamp_s <= anchor_s_) return v;
  // The server should follow the current trajectory once its start (plus the message latency) has
  // passed ("settled"), the one it replaced until then.
  const bool settled = current && sp.stamp_s >= current->start_time_s + config_.grace_s;
  std::string why;
  if (sp.mode == ServerSetpoint::Mode::kStopping) {
    why = "it stops on its own (watchdog or end stop)";
  } else if (sp.mode == ServerSetpoint::Mode::kTrajectory) {
    const ExecTrajectory* on = nullptr;  // the trajectory of ours it follows
    if (sp.own_session && current && sp.trajectory_id == current->id) on = current;
    if (sp.own_session && !settled && previous && sp.trajectory_id == previous->id) on = previous;
    if (!on && (!current || settled)) {
      why = "it follows a trajectory this planner did not command (or no longer commands)";
    } else if (on && sp.velocity.norm() > config_.stopped_speed_mps) {
      // On our trajectory: keep the timing in step with the server's (a clock step each side saw
      // at another moment and shifted by another estimate of the time between calls).
      const double tau = sp.stamp_s - on->start_time_s, d = on->spline.duration();
      auto error = [&](double delta) {
        return (on->spline.evaluate(std::clamp(tau + delta, 0.0, d)) - sp.position).norm();
      };
      if (error(0.0) > 0.01) {
        double best = 0.0, best_error = error(0.0);
        const double range = config_.max_resync_s;
        for (double delta = -range; delta <= range; delta += 0.005)
          if (const double e = error(delta); e < best_error) best = delta, best_error = e;
        for (double delta = best - 0.005; delta <= best + 0.005; delta += 0.0005)
          if (const double e = error(delta); e < best_error) best = delta, best_error = e;
        if (best_error <= 0.01 && best != 0.0) {
          v.resync_s = best;
          ++resyncs_;
        }
      }
    }
  } else if (sp.mode == ServerSetpoint::Mode::kHold && settled) {
    const FlatState commanded = commanded_at(sp.stamp_s);
    if (commanded.velocity.norm() > config_.stopped_speed_mps)
      why = "it holds while the commanded trajectory moves";
    else if ((commanded.position - sp.position).norm() > config_.position_tolerance_m)
      why = "it holds away from the commanded position";
  }
  if (why.empty()) {
    reported_ = false;
    return v;
  }
  v.why = why;
  if (sp.mode != ServerSetpoint::Mode::kHold) {
    v.kind = Verdict::Kind::kDiverged;
    v.first_report = !reported_;
    reported_ = true;
    return v;
  }
  reported_ = false;
  v.kind = Verdict::Kind::kHolds;
  v.hold = sp.position;
  return v;
}

}  // namespace topo_planner
