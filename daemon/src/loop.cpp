// SPDX-License-Identifier: Apache-2.0
#include "cpm/daemon/loop.hpp"

#include <time.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>

#include "cpm/kinematics/workspace.hpp"
#include "cpm/path/program.hpp"

namespace cpm::daemon {

using cpm_msgs::state_t;

namespace {

std::int64_t now_ns() noexcept {
  timespec ts{};
  clock_gettime(CLOCK_MONOTONIC, &ts);  // vDSO: no system call
  return std::int64_t{ts.tv_sec} * 1000000000 + ts.tv_nsec;
}

void put(double* dst, const Vec3& v) noexcept {
  dst[0] = v.x();
  dst[1] = v.y();
  dst[2] = v.z();
}

bool inside(const Vec3& p, const Vec3& lo, const Vec3& hi, int& axis, double& value, double& limit) noexcept {
  for (int i = 0; i < 3; ++i) {
    if (p[i] < lo[i]) { axis = i; value = p[i]; limit = lo[i]; return false; }
    if (p[i] > hi[i]) { axis = i; value = p[i]; limit = hi[i]; return false; }
  }
  return true;
}

}  // namespace

ControlLoop::ControlLoop(const DaemonConfig& config, Backend& backend, const ctl::Machine& machine,
                         const ctl::Controller& controller)
    : cfg_(config),
      backend_(&backend),
      dt_(1.0 / config.loop.rate_hz),
      model_(machine, controller),
      homing_(config.homing),
      stats_(config.loop.rate_hz) {
  ctl::check_delay_fits(machine.actuation_delay(), config.loop.rate_hz);
  ctl::check_delay_fits(controller.lookahead(), config.loop.rate_hz);
  pub_.state.mode = static_cast<std::int8_t>(Mode::init);
  pub_.state.segment_id = -1;
  pub_.state.last_segment_id = -1;
  pub_.state.fault_axis = -1;
  pub_.state.fault_cycle = -1;
  pub_.state.homing_axis = -1;
  // Absolute encoders know their zero from the start (HomingSequence); the
  // others wait for homing, and until then the loop holds and moves each
  // actuator on its own.
  ramp_.active = !homing_.all_homed();
  ramp_.task = false;
}

StartCheck check_start(const ctl::Trajectory& tr, const Vec3& end_velocity, const LimitsConfig& limits,
                       double dt) noexcept {
  const ctl::TrajectorySample s = tr.sample(0.0);
  StartCheck c;
  c.velocity_step = (s.v - end_velocity).norm();
  c.acceleration = s.a.norm();
  // With a relative margin for the rounding of a segment's own samples.
  c.velocity_allowed = limits.acceleration * dt * (1.0 + 1e-6) + 1e-9;
  c.acceleration_allowed = limits.acceleration * (1.0 + 1e-6) + 1e-9;
  return c;
}

void ControlLoop::enter(Mode m) noexcept {
  if (m != Mode::stopping) underrun_.pending = false;
  mode_.enter(m);
}

void ControlLoop::latch(std::uint32_t bit, int axis, double value, double limit, std::int64_t k,
                        const char* cause) noexcept {
  // The backend's own words for the faults it reports (e.g. which drive lost
  // its heartbeat), else the kinematic cause, which says what the value and
  // limit measure (fault_report: a stroke in m, an elbow angle in rad). Only
  // the first fault's words are kept: asked for only then.
  constexpr std::uint32_t kBackendWords = kFaultDrive | kFaultBackendIo | kFaultEstop | kFaultLimitSwitch;
  const char* why = !fault_.active() && (bit & kBackendWords) ? backend_->fault_text() : cause;
  fault_.set(bit, axis, value, limit, k, why);
  saturated_cycles_ = {};
  underrun_.pending = false;
  if (mode_.now() != Mode::fault) {
    if (queue_.playing()) finish_segment();
    flush_queue();
    // Homing ends: the actuator being homed stays unhomed.
    if (homing_.axis() >= 0) homing_.end(false);
    jog_.target.setZero();
    transfer_.cancel();
    enter(Mode::fault);
  }
}

void ControlLoop::flush_queue() noexcept { queue_.flush(); }

void ControlLoop::finish_segment() noexcept {
  tracking_.finish(queue_.at(0).id);
  queue_.pop();
}

bool ControlLoop::start_next_segment(std::int64_t k) noexcept {
  if (!queue_.start(k)) return false;
  tracking_.begin();
  return true;
}

void ControlLoop::start_stop(std::int64_t k) noexcept {
  if (ramp_.active) {
    // A ramp motion (homing, a jog, anything before homing): its speed goes
    // to zero at the stop's deceleration (trajectory()); a homing stopped
    // leaves its actuator unhomed.
    if (homing_.axis() >= 0) homing_.end(false);
    jog_.target.setZero();
    flush_queue();
    enter(Mode::stopping);
    return;
  }
  // Decelerate along the reference's current direction of motion at the
  // configured rate, from where the reference is now.
  stop_.start(io_.ref.p, io_.ref.v, cfg_.limits.stop_deceleration, k, 0.0);
  if (queue_.playing()) finish_segment();
  flush_queue();
  enter(Mode::stopping);
}

void ControlLoop::start_underrun_stop(const Segment& s, std::int64_t k, double late) noexcept {
  // The stream's last chunk ended at speed and nothing follows it: decelerate
  // from where and how fast the chunk ended, `late` s ago (the profile is
  // continuous with the chunk: nothing jumps), then latch the fault at rest.
  const Vec3 v_end = std::get_if<StreamTrajectory>(&s.traj)->end_velocity();
  stop_.start(s.end, v_end, cfg_.limits.stop_deceleration, k, late);
  const double v = v_end.norm();
  finish_segment();  // `s` is the playing segment: read above, cleared here
  flush_queue();
  enter(Mode::stopping);
  underrun_.arm(k, v);
}

void ControlLoop::ramp_in_actuators() noexcept {
  jog_.box_ready = false;  // the next actuator jog computes its own
  if (ramp_.active && !ramp_.task) return;  // already there
  // From the actuator reference the task space last had: nothing jumps.
  ramp_.reset(io_.d_ref);
  ramp_.task = false;
  ramp_.active = true;
  if (homing_.all_homed()) return;
  // Leaving the task space: the actuator law starts from the force the
  // task law gave.
  transfer_.request();
}

void ControlLoop::leave_ramp() noexcept {
  // In the task space, hold where the ramp came to rest.
  if (!homing_.all_homed()) return;  // the actuator space holds on the ramp itself
  hold_ = io_.ref.p;
  queue_.end_at_rest(hold_);
  ramp_.active = false;
}

void ControlLoop::ramp_box(Vec3& lo, Vec3& hi) const noexcept {
  if (ramp_.task) {
    lo = cfg_.limits.workspace_min;
    hi = cfg_.limits.workspace_max;
    return;
  }
  if (homing_.all_homed() && jog_.box_ready) {
    lo = jog_.box_lo;
    hi = jog_.box_hi;
    return;
  }
  const kin::Strokes& s = model_.machine().model().strokes;
  for (int i = 0; i < 3; ++i) {
    lo[i] = homing_.homed[i] ? s.min[i] : -std::numeric_limits<double>::infinity();
    hi[i] = homing_.homed[i] ? s.max[i] : std::numeric_limits<double>::infinity();
  }
}

ctl::TrajectorySample ControlLoop::reference(std::int64_t k) noexcept {
  ctl::TrajectorySample r;
  switch (mode_.now()) {
    case Mode::moving: {
      while (queue_.playing()) {
        const Segment& s = queue_.at(0);
        const ctl::Trajectory* tr = s.get();
        const double t = static_cast<double>(k - queue_.start_cycle()) * dt_;
        // [0, duration): the end sample itself is the hold that follows.
        if (t < tr->duration() - 1e-9) {
          if (auto* p = std::get_if<const path::Plan*>(&s.traj)) {
            // A program: where on it, for the state's program line.
            const path::PathSample ps = (*p)->sample_path(t);
            program_line_ = path::line_of(**p, ps.segment);
            return ps.ref;
          }
          return tr->sample(t);
        }
        // Finished: the next segment starts now, at its own t = 0.
        hold_ = s.end;
        const bool starved = queue_.count() == 1 && std::holds_alternative<StreamTrajectory>(s.traj) &&
                             std::get_if<StreamTrajectory>(&s.traj)->end_velocity().norm() > kStreamRestSpeed;
        if (starved) {
          // The commander's next chunk is late: the stream would stop dead.
          start_underrun_stop(s, k, t - tr->duration());
          return reference(k);
        }
        finish_segment();
        if (!start_next_segment(k)) break;
      }
      enter(Mode::holding);
      r.p = hold_;
      return r;
    }
    case Mode::stopping: {
      bool at_rest = false;
      r = stop_.sample(k, dt_, 0.0, at_rest);
      if (at_rest) {
        hold_ = r.p;
        queue_.end_at(hold_);
        r.v.setZero();
        if (underrun_.pending) {
          // At rest: now the drives may go off (brakes on) without a jolt.
          underrun_.pending = false;
          latch(kFaultStreamUnderrun, -1, underrun_.speed, kStreamRestSpeed, underrun_.cycle);
          return r;
        }
        enter(mode_.after_stop());
      }
      return r;
    }
    case Mode::holding:
      r.p = hold_;
      return r;
    default:
      // Drives off: the setpoint follows the measurement, so enabling starts from it.
      r.p = io_.estimate_ok ? io_.est.p : hold_;
      hold_ = r.p;
      queue_.end_at(hold_);
      return r;
  }
}

ctl::TrajectorySample ControlLoop::reference_ahead(std::int64_t k, double ahead) const noexcept {
  // The profiles of reference(), sampled `ahead` s after cycle k, without
  // their side effects (a segment finishes, a stop ends, when reference()
  // reaches them). A segment that follows another starts at the first cycle
  // at or after its predecessor's end, as reference() starts it.
  if (mode_.now() == Mode::moving && queue_.playing()) {
    double t = static_cast<double>(k - queue_.start_cycle()) * dt_ + ahead;
    for (int i = 0; i < queue_.count(); ++i) {
      const Segment& s = queue_.at(i);
      const ctl::Trajectory* tr = s.get();
      const double played = std::ceil((tr->duration() - 1e-9) / dt_ - 1e-9) * dt_;
      if (t < played) return tr->sample(t);
      t -= played;
    }
    ctl::TrajectorySample r;  // past the queue's end: the hold there
    r.p = queue_.at(queue_.count() - 1).end;
    return r;
  }
  if (mode_.now() == Mode::stopping) {
    bool at_rest = false;
    return stop_.sample(k, dt_, ahead, at_rest);
  }
  return io_.ref;  // holding, enabling: the hold point, which does not move
}

void ControlLoop::record_schedule(bool overrun, std::int64_t skipped) noexcept {
  stats_.schedule(overrun, skipped);
  overruns_.record(overrun, cfg_.loop.max_consecutive_overruns);
}

void ControlLoop::cycle(std::int64_t k, std::int64_t latency_ns) noexcept {
  // The phases of loop.hpp, in order; each timed into its statistics series
  // (the commands are timed with the estimate, as they always were; homing
  // and jog with the trajectory, whose reference they steer).
  PhaseTimes t{};
  stats_.latency(latency_ns);
  t[0] = now_ns();
  if (mode_.now() == Mode::init) enter(Mode::disabled);
  read_inputs(k);
  t[kSeriesRead] = now_ns();
  estimate(k);
  apply_commands(k);
  t[kSeriesEstimate] = now_ns();
  homing(k);
  jog(k);
  trajectory(k);
  t[kSeriesTrajectory] = now_ns();
  inverse_kinematics();
  t[kSeriesInverseKinematics] = now_ns();
  control(k);
  t[kSeriesController] = now_ns();
  safety(k);
  t[kSeriesSafety] = now_ns();
  write_outputs(k);
  t[kSeriesWrite] = now_ns();
  publish(k);
  t[kSeriesPublish] = now_ns();
  finish_cycle(k, t);
}

void ControlLoop::read_inputs(std::int64_t k) noexcept {
  io_.read_result = backend_->read(k, io_.in);
  io_.backend_ok = io_.read_result == BackendResult::ok && io_.backend_write_ok;
  io_.raw = Vec3(io_.in.position[0], io_.in.position[1], io_.in.position[2]);
  // A drive that lost its position (it rebooted) must be homed again; the
  // loop falls back to the actuator space, from the reference it has.
  for (int i = 0; i < 3; ++i)
    if (io_.in.position_lost[i] && homing_.homed[i] && cfg_.homing.axes[i].method != HomingMethod::absolute) {
      ramp_in_actuators();
      homing_.homed[i] = false;
    }
}

void ControlLoop::estimate(std::int64_t k) noexcept {
  io_.cin.d = io_.raw + homing_.offset;
  io_.cin.d_dot = Vec3(io_.in.velocity[0], io_.in.velocity[1], io_.in.velocity[2]);
  // The direction each actuator last moved in, for the model's backlash.
  for (int i = 0; i < 3; ++i)
    if (std::abs(io_.cin.d_dot[i]) > 1e-6) io_.cin.kin.dir[i] = io_.cin.d_dot[i] > 0 ? 1 : -1;
  io_.cin.kin.t = static_cast<double>(k) * dt_;
  io_.estimate_status = io_.read_result == BackendResult::ok
                            ? model_.machine().task_state(io_.cin.d, io_.cin.d_dot, io_.cin.kin, io_.est)
                            : Status::failure(Fault::not_finite);
  io_.estimate_ok = io_.estimate_status.ok();
}

void ControlLoop::apply_commands(std::int64_t k) noexcept {
  if (requests_.shutdown_requested() && mode_.now() != Mode::fault && mode_.now() != Mode::disabled) {
    flush_queue();
    enter(Mode::disabled);
  }
  handle_commands(k);
}

void ControlLoop::homing(std::int64_t k) noexcept {
  if (mode_.now() != Mode::homing || homing_.axis() < 0) {
    homing_.request = {};
    return;
  }
  const int i = homing_.axis();
  AxisHoming::Inputs h;
  h.t = static_cast<double>(k) * dt_;
  h.raw = io_.raw[i];
  h.reference = ramp_.p[i] - homing_.offset[i];
  h.reference_at_rest = ramp_.v[i] == 0.0;
  h.home_switch = io_.in.home_switch[static_cast<std::size_t>(i)];
  h.index = io_.in.index_pulse[static_cast<std::size_t>(i)];
  h.drive = io_.in.drive_homing[static_cast<std::size_t>(i)];
  const AxisHoming::Outcome o = homing_.axis_homing.step(h, homing_.request);
  if (homing_.axis_homing.event_seen() && homing_.offset[i] != homing_.axis_homing.offset()) {
    // The homing event: the actuator's zero is known. The reference and the
    // reading move together, so nothing moves on the machine.
    const double delta = homing_.axis_homing.offset() - homing_.offset[i];
    homing_.offset[i] = homing_.axis_homing.offset();
    io_.cin.d[i] += delta;
    ramp_.p[i] += delta;
  }
  if (o == AxisHoming::Outcome::failed) {
    const AxisHoming::Failure& f = homing_.axis_homing.failure();
    latch(kFaultHoming, i, f.value, f.limit, k, f.cause);
    return;
  }
  if (o != AxisHoming::Outcome::homed) return;
  homing_.homed[static_cast<std::size_t>(i)] = true;
  homing_.request = {};
  if (homing_.more()) {
    begin_axis_homing(k);
    return;
  }
  homing_.end(true);
  enter(Mode::holding);
}

void ControlLoop::jog(std::int64_t k) noexcept {
  // The deadman: a jog holds for jog.keepalive after its command.
  if (mode_.now() == Mode::jogging) jog_.deadman(k);
}

void ControlLoop::trajectory(std::int64_t k) noexcept {
  if (!ramp_.active) {
    io_.ref = reference(k);
    return;
  }
  Vec3 lo, hi;
  ramp_box(lo, hi);
  switch (mode_.now()) {
    case Mode::homing: {
      const int i = homing_.axis();
      const double acc = cfg_.homing.axes[static_cast<std::size_t>(i)].acceleration;
      if (homing_.request.kind == AxisHoming::Request::Kind::drive) {
        // The drive moves itself: the reference follows it.
        ramp_.step(Vec3::Zero(), acc, lo, hi, dt_);
        ramp_.p[i] = io_.cin.d[i];
        ramp_.v[i] = 0.0;
      } else if (homing_.request.kind == AxisHoming::Request::Kind::position) {
        Vec3 target = ramp_.p;
        target[i] = homing_.request.position + homing_.offset[i];
        ramp_.step_to(target, homing_.request.speed, acc, dt_);
      } else {
        Vec3 v = Vec3::Zero();
        v[i] = homing_.request.velocity;
        ramp_.step(v, acc, lo, hi, dt_);
      }
      break;
    }
    case Mode::jogging:
      ramp_.step(jog_.target, cfg_.jog.acceleration, lo, hi, dt_);
      if (jog_.target.isZero(0.0) && ramp_.at_rest()) enter(Mode::holding);
      break;
    case Mode::stopping: {
      ramp_.step(Vec3::Zero(), std::max(cfg_.jog.acceleration, cfg_.limits.stop_deceleration), lo, hi, dt_);
      if (ramp_.at_rest()) {
        enter(mode_.after_stop());
      }
      break;
    }
    case Mode::holding:
    case Mode::enabling:
    case Mode::moving:
      break;
    default:
      // Drives off: the reference follows the measurement.
      if (homing_.all_homed()) {
        ramp_.active = false;
        io_.ref = reference(k);
        return;
      }
      ramp_.task = false;
      ramp_.reset(io_.cin.d);
      break;
  }
  if (ramp_.task) {
    io_.ref.p = ramp_.p;
    io_.ref.v = ramp_.v;
    io_.ref.a = ramp_.a;
  } else {
    reference_of_actuators(ramp_.p, ramp_.v, ramp_.a);
  }
  // A ramp motion in the task space (a jog, or the first hold after homing)
  // ends at rest: the hold point takes over.
  if (mode_.now() == Mode::holding && homing_.all_homed() && ramp_.at_rest()) leave_ramp();
}

void ControlLoop::reference_of_actuators(const Vec3& d, const Vec3& d_dot, const Vec3& d_dd) noexcept {
  ctl::TaskState ts;
  if (model_.machine().task_state(d, d_dot, io_.cin.kin, ts).ok()) {
    io_.ref.p = ts.p;
    io_.ref.v = ts.p_dot;
    io_.ref.a = ts.J * d_dd;
  }
  // else (an unhomed actuator far off): the last reference stays on show.
}

void ControlLoop::inverse_kinematics() noexcept {
  if (ramp_.active && !ramp_.task) {
    // The ramp is the actuator reference itself.
    io_.d_ref = ramp_.p;
    io_.ik_status = Status{};
    return;
  }
  io_.ik_status = kin::inverse(model_.machine().kinematics(), io_.ref.p, io_.cin.kin, io_.d_ref);
}

void ControlLoop::control(std::int64_t k) noexcept {
  io_.powered = mode_.drives_on();
  io_.control_status = Status{};
  const bool actuator_law = !homing_.all_homed();
  if (io_.powered) {
    // The law changes (homing done, or a position lost): fade the difference.
    transfer_.law(actuator_law);
    if (actuator_law) {
      control_actuators();
    } else {
      // With an actuation delay in the model the command acts from t + tau:
      // the controller aims at the reference then.
      const double ahead = model_.controller().lookahead();
      io_.cin.ref = ahead > 0.0 && !ramp_.active ? reference_ahead(k, ahead) : io_.ref;
      io_.control_status = model_.step(io_.cin, io_.cout);
    }
    fade_transfer(k);
    return;
  }
  transfer_.off(actuator_law);
  saturated_cycles_ = {};
  io_.cout.force.setZero();
  io_.cout.force_unlimited.setZero();
  io_.cout.saturated = {false, false, false};
  io_.cout.d_ref = io_.d_ref;
  io_.cout.d_dot_ref.setZero();
}

void ControlLoop::control_actuators() noexcept {
  // Each actuator on its own PD law toward the ramp, plus the force that
  // holds the platform's weight (at the estimate when it has one, else at
  // the middle of the workspace: the weight hardly changes with the pose).
  const ctl::Gains& g = cfg_.homing.actuator_gains;
  Vec3 hold = Vec3::Zero();
  const Vec3 at = io_.estimate_ok ? io_.est.p : Vec3(0.5 * (cfg_.limits.workspace_min + cfg_.limits.workspace_max));
  if (!model_.machine().holding_command(at, io_.cin.kin, hold).ok()) hold.setZero();
  Vec3 f = g.kp.cwiseProduct(io_.d_ref - io_.cin.d) + g.kd.cwiseProduct(ramp_.v - io_.cin.d_dot) + hold;
  if (mode_.now() == Mode::homing && homing_.axis() >= 0 && homing_.drive_homes(homing_.axis()))
    f[homing_.axis()] = 0.0;  // the drive drives itself
  io_.cout.force_unlimited = f;
  limit_force(f);
  io_.cout.d_ref = io_.d_ref;
  io_.cout.d_dot_ref = ramp_.v;
  model_.sent().push(io_.cin.kin.t, io_.cout.force);
}

void ControlLoop::fade_transfer(std::int64_t k) noexcept {
  // Bumpless: the new law starts from the force the old one gave (the force
  // written last cycle); the difference fades out linearly.
  const Vec3 written(io_.out.force[0], io_.out.force[1], io_.out.force[2]);
  if (!transfer_.fade(k, written, io_.cout.force_unlimited, dt_, cfg_.controller.transfer_time)) return;
  limit_force(io_.cout.force_unlimited + transfer_.now());
  // What the drives are given is what the prediction across a delay uses.
  model_.sent().amend_last(io_.cout.force);
}

void ControlLoop::limit_force(const Vec3& f) noexcept {
  const double lim = model_.machine().force_limit();
  for (int i = 0; i < 3; ++i) {
    io_.cout.saturated[static_cast<std::size_t>(i)] = std::abs(f[i]) > lim;
    io_.cout.force[i] = std::clamp(f[i], -lim, lim);
  }
}

void ControlLoop::safety(std::int64_t k) noexcept {
  latch_input_faults(k);
  if (!io_.powered || mode_.now() == Mode::fault) return;
  // The error is measured before any latch below ends the segment it
  // belongs to; in the actuator space, of the actuators (the platform's
  // position is not known).
  const double error = homing_.all_homed() ? (io_.ref.p - io_.est.p).norm() : (io_.d_ref - io_.cin.d).norm();
  latch_motion_faults(k, error);
  latch_saturation(k);
  finish_enabling(k);
  if (queue_.playing()) tracking_.add(error);
}

void ControlLoop::latch_input_faults(std::int64_t k) noexcept {
  if (io_.read_result != BackendResult::ok) latch(kFaultBackendIo, -1, static_cast<double>(io_.read_result), 0, k);
  for (int i = 0; i < 3; ++i)
    if (io_.in.drive_fault[i]) latch(kFaultDrive, i, io_.in.statusword[i], 0, k);
  if (io_.in.estop) latch(kFaultEstop, -1, 1, 0, k);
  for (int i = 0; i < 3; ++i)
    if (io_.in.limit_switch[i]) latch(kFaultLimitSwitch, i, 1, 0, k);
  if (overruns_.take()) latch(kFaultOverrun, -1, overruns_.consecutive(), cfg_.loop.max_consecutive_overruns, k);
  // Before homing an actuator's reading may be anything: no pose to estimate.
  if (io_.read_result == BackendResult::ok && !io_.estimate_status.ok() && homing_.all_homed())
    latch(kFaultEstimate, io_.estimate_status.index, io_.estimate_status.value, io_.estimate_status.limit, k,
          cpm::fault_name(io_.estimate_status.fault));
}

void ControlLoop::latch_motion_faults(std::int64_t k, double error) noexcept {
  if (!io_.ik_status.ok())
    latch(kFaultController, io_.ik_status.index, io_.ik_status.value, io_.ik_status.limit, k, cpm::fault_name(io_.ik_status.fault));
  else if (!io_.control_status.ok())
    latch(kFaultController, io_.control_status.index, io_.control_status.value, io_.control_status.limit, k,
          cpm::fault_name(io_.control_status.fault));
  if (error > cfg_.limits.following_error) latch(kFaultFollowingError, -1, error, cfg_.limits.following_error, k);
  if (!homing_.all_homed()) {
    // The actuator space: the strokes of the homed actuators, the speed of all.
    const kin::Strokes& st = model_.machine().model().strokes;
    for (int i = 0; i < 3 && mode_.now() != Mode::fault; ++i) {
      if (!homing_.homed[static_cast<std::size_t>(i)]) continue;
      if (io_.cin.d[i] < st.min[i]) latch(kFaultSoftLimit, i, io_.cin.d[i], st.min[i], k, "stroke_low");
      else if (io_.cin.d[i] > st.max[i]) latch(kFaultSoftLimit, i, io_.cin.d[i], st.max[i], k, "stroke_high");
    }
    const double speed = io_.cin.d_dot.norm();
    if (speed > cfg_.limits.overspeed) latch(kFaultOverspeed, -1, speed, cfg_.limits.overspeed, k);
    return;
  }
  int axis = -1;
  double v = 0, lim = 0;
  // The reference never passes the soft limits (validation, the jog's box);
  // the platform follows it within its tracking error, so it may pass one it
  // stops at by that much.
  const Vec3 slack = Vec3::Constant(kSoftLimitSlack);
  if (!inside(io_.est.p, cfg_.limits.workspace_min - slack, cfg_.limits.workspace_max + slack, axis, v, lim)) {
    // Reported against the limit as configured.
    lim = v < cfg_.limits.workspace_min[axis] ? cfg_.limits.workspace_min[axis] : cfg_.limits.workspace_max[axis];
    latch(kFaultSoftLimit, axis, v, lim, k);
  }
  // The machine's own workspace (strokes, limb reach, elbow singularity):
  // the reference one cycle ahead is checked first, so that a path running
  // towards a stroke end or a singularity stops before the platform (which
  // follows the reference within micrometres) gets there.
  if (mode_.now() != Mode::fault) {
    const Vec3 ahead = io_.ref.p + io_.ref.v * dt_;
    const ctl::Machine& machine = model_.machine();
    const Status wr = kin::check_pose(machine.kinematics(), machine.model().strokes, ahead, io_.cin.kin);
    const Status wm = wr.ok() ? kin::check_pose(machine.kinematics(), machine.model().strokes, io_.est.p, io_.cin.kin) : wr;
    if (!wm.ok()) latch(kFaultSoftLimit, wm.index, wm.value, wm.limit, k, cpm::fault_name(wm.fault));
  }
  if (io_.est.p_dot.norm() > cfg_.limits.overspeed) latch(kFaultOverspeed, -1, io_.est.p_dot.norm(), cfg_.limits.overspeed, k);
}

void ControlLoop::latch_saturation(std::int64_t k) noexcept {
  // Force saturation held too long: the axis cannot follow (blocked,
  // overloaded, a gain too high); the following error may not show it yet.
  for (int i = 0; i < 3 && mode_.now() != Mode::fault; ++i) {
    saturated_cycles_[i] = io_.cout.saturated[i] ? saturated_cycles_[i] + 1 : 0;
    const double held = static_cast<double>(saturated_cycles_[i]) * dt_;
    if (held > cfg_.limits.saturation_time + 1e-12) latch(kFaultSaturation, i, held, cfg_.limits.saturation_time, k);
  }
}

void ControlLoop::finish_enabling(std::int64_t k) noexcept {
  if (mode_.now() != Mode::enabling) return;
  if (io_.in.drive_enabled[0] && io_.in.drive_enabled[1] && io_.in.drive_enabled[2]) {
    enter(Mode::holding);
  } else if (const double waited = mode_.enabling_time(k, dt_); waited > cfg_.limits.enable_timeout) {
    latch(kFaultEnableTimeout, -1, waited, cfg_.limits.enable_timeout, k);
  }
}

void ControlLoop::write_outputs(std::int64_t k) noexcept {
  const bool on = mode_.drives_on();
  for (int i = 0; i < 3; ++i) io_.out.force[i] = on ? io_.cout.force[i] : 0.0;
  io_.out.enable = on;
  // The actuator a drive homes itself: its own homing mode, started.
  for (int i = 0; i < 3; ++i) {
    const bool drive_homes = on && mode_.now() == Mode::homing && homing_.drive_homes(i);
    io_.out.axis_drive[static_cast<std::size_t>(i)] = drive_homes ? AxisDrive::homing : AxisDrive::torque;
    io_.out.start_homing[static_cast<std::size_t>(i)] = drive_homes;
  }
  const BackendResult rw = backend_->write(k, io_.out);
  io_.backend_write_ok = rw == BackendResult::ok;
  if (rw != BackendResult::ok) latch(kFaultBackendIo, -1, static_cast<double>(rw), 0, k);
}

void ControlLoop::publish(std::int64_t k) noexcept {
  fill_state(k);
  if (cfg_.lcm.state_decimation <= 1 || k % cfg_.lcm.state_decimation == 0) {
    if (!ch_.snapshots.push(pub_.state)) pub_.dropped++;
  }
  const auto every = std::max<std::int64_t>(1, std::lround(cfg_.loop.rate_hz / 10.0));
  if (k % every == 0) publish_drives(k);
}

void ControlLoop::publish_drives(std::int64_t k) noexcept {
  backend_->diagnostics(pub_.diagnostics);
  const BackendDiagnostics& d = pub_.diagnostics;
  cpm_msgs::drives_t& m = pub_.drives;
  m.utime = 0;  // stamped by the publisher
  m.cycle = k;
  m.backend = d.backend;
  for (std::size_t i = 0; i < 3; ++i) {
    const DriveDiagnostics& v = d.drive[i];
    m.node_id[i] = static_cast<std::int16_t>(v.node_id);
    m.nmt_state[i] = v.nmt;
    m.cia402_state[i] = v.cia402;
    m.statusword[i] = v.statusword;
    m.controlword[i] = v.controlword;
    m.mode_display[i] = v.mode_display;
    m.enabled[i] = io_.in.drive_enabled[i];
    m.fault[i] = io_.in.drive_fault[i];
    m.homed[i] = homing_.homed[i];
    m.heartbeat_age_ms[i] =
        v.heartbeat_age_ns < 0 ? -1 : static_cast<std::int32_t>(std::min<std::int64_t>(v.heartbeat_age_ns / 1000000, INT32_MAX));
    m.master_faults[i] = static_cast<std::int32_t>(v.master_faults);
    m.emcy_count[i] = static_cast<std::int32_t>(std::min<std::uint32_t>(v.emcy_count, INT32_MAX));
    m.last_emcy_code[i] = v.last_emcy_code;
    m.last_emcy_register[i] = v.last_emcy_register;
    m.position[i] = io_.cin.d[static_cast<Eigen::Index>(i)];
    m.force[i] = io_.out.force[i];
    m.limit_low[i] = d.limit_low[i];
    m.limit_high[i] = d.limit_high[i];
    m.home_switch[i] = io_.in.home_switch[i];
  }
  m.bus_state = d.bus_state;
  m.error_frames = static_cast<std::int64_t>(d.error_frames);
  m.tx_error_counter = d.tx_error_counter;
  m.rx_error_counter = d.rx_error_counter;
  m.rx_dropped = static_cast<std::int64_t>(d.rx_dropped);
  m.tx_failures = static_cast<std::int64_t>(d.tx_failures);
  m.bus_load = d.bus_load;
  m.estop = io_.in.estop;
  (void)ch_.drives.push(m);  // a full ring drops this view; the next comes in 0.1 s
}

void ControlLoop::finish_cycle(std::int64_t k, const PhaseTimes& t) noexcept {
  stats_.cycle(t);
  // Statistics once a second (copied whole; the ring holds a few).
  const auto per_second = static_cast<std::int64_t>(std::lround(cfg_.loop.rate_hz));
  if (per_second > 0 && (k + 1) % per_second == 0) (void)ch_.stats.push(stats_.sums());
  stats_.completed();
}

void ControlLoop::fill_state(std::int64_t k) noexcept {
  state_t& s = pub_.state;
  s.utime = 0;  // stamped by the publisher with the wall clock
  s.cycle = k;
  s.t = static_cast<double>(k) * dt_;
  s.mode = static_cast<std::int8_t>(mode_.now());
  s.controller = static_cast<std::int8_t>(model_.controller().law());
  put(s.position, io_.est.p);
  put(s.velocity, io_.est.p_dot);
  put(s.position_ref, io_.ref.p);
  put(s.velocity_ref, io_.ref.v);
  put(s.acceleration_ref, io_.ref.a);
  const Vec3 e = io_.ref.p - io_.est.p;
  put(s.position_error, e);
  s.position_error_norm = e.norm();
  put(s.d, io_.cin.d);
  put(s.d_dot, io_.cin.d_dot);
  put(s.d_ref, io_.d_ref);
  put(s.d_dot_ref, io_.cout.d_dot_ref);
  for (int i = 0; i < 3; ++i) {
    s.force[i] = io_.out.force[i];
    s.saturated[i] = io_.out.enable && io_.cout.saturated[i];
  }
  s.faults = static_cast<std::int32_t>(fault_.bits());
  s.first_fault = static_cast<std::int32_t>(fault_.first());
  s.fault_axis = static_cast<std::int8_t>(fault_.axis());
  s.fault_value = fault_.value();
  s.fault_limit = fault_.limit();
  s.fault_cycle = fault_.cycle();
  static_assert(sizeof s.fault_text == FaultLatch::kTextBytes);
  std::memcpy(s.fault_text, fault_.text(), FaultLatch::kTextBytes);
  if (queue_.playing()) {
    const Segment& seg = queue_.at(0);
    s.segment_id = seg.id;
    s.segment_elapsed = static_cast<double>(k - queue_.start_cycle()) * dt_;
    s.segment_duration = seg.get()->duration();
    s.program_line = std::holds_alternative<const path::Plan*>(seg.traj) ? program_line_ : 0;
  } else {
    s.program_line = 0;
    s.segment_id = -1;
    s.segment_elapsed = 0;
    s.segment_duration = 0;
  }
  s.queue_depth = static_cast<std::int16_t>(queue_.playing() ? queue_.count() - 1 : queue_.count());
  put(s.queue_end, queue_.end());
  put(s.queue_end_velocity, queue_.end_velocity());
  put(s.queue_end_acceleration, queue_.end_acceleration());
  for (std::size_t i = 0; i < 3; ++i) s.homed[i] = homing_.homed[i];
  s.homing_axis = static_cast<std::int8_t>(homing_.axis());
  s.homing_phase = static_cast<std::int8_t>(homing_.axis() >= 0 ? homing_.axis_homing.phase() : HomingPhase::idle);
  s.control_space = homing_.all_homed() ? state_t::SPACE_TASK : state_t::SPACE_ACTUATOR;
  s.jog_frame = jog_.frame;
  put(s.jog_velocity, mode_.now() == Mode::jogging ? jog_.target : Vec3::Zero());
  s.jog_keepalive_left = mode_.now() == Mode::jogging ? std::max<double>(0.0, static_cast<double>(jog_.deadline - k) * dt_) : 0.0;
  put(s.transfer_force, transfer_.now());
  s.last_segment_id = tracking_.last_id();
  s.last_segment_rmse = tracking_.last_rmse();
  s.last_segment_max = tracking_.last_max();
  s.last_segment_cycles = tracking_.last_cycles();
  const cpm_msgs::loop_stats_t& st = stats_.sums();
  s.cycles = st.cycles + 1;
  s.overruns = st.overruns;
  s.skipped = st.skipped;
  s.max_latency_ns = st.max_ns[kSeriesLatency];
  s.max_cycle_ns = st.max_ns[kSeriesCycle];
  s.dropped_snapshots = pub_.dropped;
}

}  // namespace cpm::daemon
