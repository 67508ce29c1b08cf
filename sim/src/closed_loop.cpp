// SPDX-License-Identifier: Apache-2.0
#include "cpm/sim/closed_loop.hpp"

#include <cmath>

namespace cpm::sim {

void LoopOptions::validate() const {
  if (!std::isfinite(rate_hz) || rate_hz < 1.0 || rate_hz > 1e6)
    throw Error("loop: rate must be within 1 Hz .. 1 MHz");
  if (!std::isfinite(duration)) throw Error("loop: duration must be finite");
}

RunResult run_closed_loop(const ctl::Controller& controller, Plant& plant,
                          const ctl::Trajectory& trajectory, const LoopOptions& options) {
  options.validate();
  const double dt = 1.0 / options.rate_hz;
  const double T = options.duration >= 0.0 ? options.duration : trajectory.duration();
  const long n = std::lround(T * options.rate_hz);
  RunResult r;
  if (options.keep_log) r.log.reserve(static_cast<std::size_t>(n));
  // The run starts at rest: the drives were holding the platform there, so
  // under an actuation delay that holding force acts until the first
  // command does (as the controller, with its model, believes too).
  const ctl::TrajectorySample start = trajectory.sample(0.0);
  Vec3 held = Vec3::Zero(), believed = Vec3::Zero();
  Status sr = plant.truth().holding_command(start.p, {}, held);
  if (sr) sr = controller.model().holding_command(start.p, {}, believed);
  if (sr) sr = plant.reset(start.p, Vec3::Zero(), held);
  if (!sr) {
    r.fault = sr;
    return r;
  }
  double sum_e2 = 0.0, sum_v2 = 0.0;
  Vec3 sum_axis = Vec3::Zero();
  // Delays longer than the command histories keep are refused here, not in the loop.
  ctl::check_delay_fits(plant.truth().actuation_delay(), options.rate_hz);
  ctl::check_delay_fits(controller.lookahead(), options.rate_hz);
  const double ahead = controller.lookahead();
  ctl::ControlInput in;
  ctl::ControlOutput out;
  ctl::ControllerState state;
  state.reset(believed);
  // The controller knows only what it commands: it takes the direction of
  // motion (for backlash compensation) from its own reference velocity (the
  // actuator axes are the task axes to within a milliradian), not from the plant.
  const kin::DirectionTracker direction;
  for (long k = 0; k < n; ++k) {
    const double t = k * dt;
    const EncoderReading enc = plant.read();
    in.d = enc.d;
    in.d_dot = enc.d_dot;
    const ctl::TrajectorySample ref = trajectory.sample(t);
    // The controller aims at where the reference will be when its command acts.
    in.ref = ahead > 0.0 ? trajectory.sample(t + ahead) : ref;
    in.kin.t = t;
    direction.update(ref.v, in.kin);
    if (Status s = controller.step(in, state, out); !s) {
      r.fault = s;
      r.fault_time = t;
      break;
    }
    const Vec3 e = ref.p - plant.position();
    const Vec3 ev = ref.v - plant.velocity();
    sum_e2 += e.squaredNorm();
    sum_v2 += ev.squaredNorm();
    sum_axis += e.cwiseAbs2();
    r.metrics.position_max = std::max(r.metrics.position_max, e.norm());
    r.metrics.velocity_max = std::max(r.metrics.velocity_max, ev.norm());
    r.metrics.samples++;
    if (out.saturated[0] || out.saturated[1] || out.saturated[2]) r.metrics.saturated_samples++;
    if (options.keep_log)
      r.log.push_back({t, enc.d, enc.d_dot, out.force, plant.position(), plant.velocity(),
                       ref.p, ref.v});
    if (Status s = plant.step(out.force, dt); !s) {
      r.fault = s;
      r.fault_time = t + dt;
      break;
    }
  }
  if (r.metrics.samples > 0) {
    const double ns = static_cast<double>(r.metrics.samples);
    r.metrics.position_rmse = std::sqrt(sum_e2 / ns);
    r.metrics.velocity_rmse = std::sqrt(sum_v2 / ns);
    r.metrics.position_rms_axis = (sum_axis / ns).cwiseSqrt();
  }
  return r;
}

io::MotionData to_motion_data(const std::vector<LogRow>& log, double rate_hz) {
  io::MotionData m;
  m.rate = rate_hz;
  m.info.metadata["source"] = "cpm sim";
  m.t.reserve(log.size());
  for (const LogRow& r : log) {
    m.t.push_back(r.t);
    m.d.push_back(r.d);
    m.v.push_back(r.d_dot);
    m.f.push_back(r.force);
  }
  return m;
}

void write_motion_log(const std::string& path, const std::vector<LogRow>& log, double rate_hz) {
  io::write_motion(path, to_motion_data(log, rate_hz));
}

}  // namespace cpm::sim
