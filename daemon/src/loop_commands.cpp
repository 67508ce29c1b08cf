// SPDX-License-Identifier: Apache-2.0
// The loop's commands (as LinuxCNC keeps command.c apart from control.c):
// each one's legality in the current mode and its transition, answered
// with an Ack. Called from apply_commands() in the cycle: real-time, no
// allocation, noexcept.
#include <algorithm>
#include <cmath>
#include <limits>

#include "cpm/daemon/loop.hpp"
#include "cpm/kinematics/workspace.hpp"

namespace cpm::daemon {

void ControlLoop::reply(const Command& c, Refusal refusal, const char* msg, const ctl::Machine* retired) noexcept {
  Ack a;
  a.id = c.id;
  a.source = c.source;
  a.code = c.code;
  a.accepted = refusal == Refusal::none;
  a.refusal = refusal;
  a.message = msg;
  a.mode = mode_.now();
  a.queue_depth = static_cast<std::int16_t>(queue_.count());
  a.retired = retired;
  a.queue_end = queue_.end();
  a.queue_end_velocity = queue_.end_velocity();
  a.queue_end_acceleration = queue_.end_acceleration();
  a.cycle = commands_cycle_;
  // The LCM thread drains 64 acks per millisecond at least; a full ring
  // would lose only the ack, never the command's effect.
  (void)ch_.acks.push(a);
}

void ControlLoop::handle_commands(std::int64_t k) noexcept {
  commands_cycle_ = k;
  // A stop rung in from the server's stop listener: before any command.
  if (requests_.take_stop() && (mode_.now() == Mode::moving || mode_.now() == Mode::homing || mode_.now() == Mode::jogging))
    start_stop(k);
  // A bounded number per cycle keeps the cycle's time bounded.
  for (int n = 0; n < kCommandsPerCycle; ++n) {
    const Command* c = ch_.commands.front();
    if (!c) return;
    handle(*c, k);
    ch_.commands.release();
  }
}

void ControlLoop::handle(const Command& c, std::int64_t k) noexcept {
  switch (c.kind) {
    case CommandKind::ping: return accept(c, "pong");
    case CommandKind::enable: return handle_enable(c, k);
    case CommandKind::disable: return handle_disable(c, k);
    case CommandKind::stop: return handle_stop(c, k);
    case CommandKind::reset: return handle_reset(c);
    case CommandKind::select_controller: return handle_select(c);
    case CommandKind::load_model: return handle_load(c);
    case CommandKind::home: return handle_home(c, k);
    case CommandKind::jog: return handle_jog(c, k);
    case CommandKind::set_params: return handle_settings(c);
    case CommandKind::segment: return handle_segment(c, k);
    case CommandKind::none: return;
  }
}

void ControlLoop::hold_where_measured() noexcept {
  hold_ = io_.est.p;
  queue_.end_at(hold_);
  ramp_.reset(io_.cin.d);  // (the actuator space's hold)
}

void ControlLoop::handle_enable(const Command& c, std::int64_t k) noexcept {
  if (mode_.now() == Mode::fault) return refuse(c, Refusal::fault_active, "a fault is latched: reset first");
  if (mode_.now() != Mode::disabled) return refuse(c, Refusal::illegal_in_mode, "enable is legal only when disabled");
  hold_where_measured();  // resynchronise: nothing jumps
  model_.restart();       // the drives were given nothing while off
  enter(Mode::enabling);
  mode_.enabling_from(k);
  accept(c, "enabling");
}

void ControlLoop::handle_disable(const Command& c, std::int64_t k) noexcept {
  if (mode_.now() == Mode::enabling || mode_.now() == Mode::holding) {
    flush_queue();
    enter(Mode::disabled);
    accept(c, "disabled");
  } else if (mode_.now() == Mode::moving || mode_.now() == Mode::homing || mode_.now() == Mode::jogging) {
    start_stop(k);
    mode_.disable_after_stop();
    accept(c, "stopping, then disabling");
  } else if (mode_.now() == Mode::stopping) {
    mode_.disable_after_stop();
    accept(c, "disabling once stopped");
  } else if (mode_.now() == Mode::fault) {
    refuse(c, Refusal::illegal_in_mode, "in fault the drives are already off");
  } else {
    refuse(c, Refusal::illegal_in_mode, "already disabled");
  }
}

void ControlLoop::handle_stop(const Command& c, std::int64_t k) noexcept {
  if (mode_.now() == Mode::moving || mode_.now() == Mode::homing || mode_.now() == Mode::jogging) {
    start_stop(k);
    accept(c, "stopping");
  } else if (mode_.now() == Mode::holding || mode_.now() == Mode::stopping) {
    flush_queue();
    accept(c, "already at rest or stopping; queue cleared");
  } else {
    refuse(c, Refusal::illegal_in_mode, "stop needs the drives enabled (holding, moving, homing, jogging or stopping)");
  }
}

void ControlLoop::handle_reset(const Command& c) noexcept {
  if (mode_.now() != Mode::fault) return refuse(c, Refusal::illegal_in_mode, "no fault latched");
  if (io_.in.estop) return refuse(c, Refusal::fault_active, "the e-stop chain is still open");
  if (io_.in.drive_fault[0] || io_.in.drive_fault[1] || io_.in.drive_fault[2])
    return refuse(c, Refusal::fault_active, "a drive still reports a fault");
  if (!io_.backend_ok) return refuse(c, Refusal::fault_active, "the backend still reports an I/O error (bus, GPIO)");
  fault_.clear();
  saturated_cycles_ = {};
  overruns_.clear();
  hold_where_measured();
  enter(Mode::disabled);
  accept(c, "fault reset; disabled, setpoint at the measured position");
}

void ControlLoop::handle_select(const Command& c) noexcept {
  if (mode_.now() != Mode::disabled && mode_.now() != Mode::holding)
    return refuse(c, Refusal::illegal_in_mode, "select the controller when disabled or holding");
  // While holding in the task space the new law starts from the force the
  // old one gave: the difference is faded out (bumpless).
  if (mode_.now() == Mode::holding && homing_.all_homed() && !ramp_.active) transfer_.request();
  model_.select(*c.controller);
  accept(c, mode_.now() == Mode::holding ? "controller selected; the force difference fades out" : "controller selected");
}

void ControlLoop::handle_load(const Command& c) noexcept {
  // Refused, the unused model goes back so that it is freed.
  if (mode_.now() != Mode::disabled) return refuse(c, Refusal::illegal_in_mode, "load a model only when disabled", c.machine);
  accept(c, "model loaded", model_.load(*c.machine, *c.controller));
}

void ControlLoop::handle_segment(const Command& c, std::int64_t k) noexcept {
  if (!homing_.all_homed()) {
    refuse(c, Refusal::not_homed,
          "not every actuator is homed: the platform's position is not known; home the machine first (cpm home)");
    return;
  }
  if (mode_.now() != Mode::holding && mode_.now() != Mode::moving) {
    refuse(c, Refusal::illegal_in_mode, "trajectories are accepted only when holding or moving");
    return;
  }
  if (queue_.count() >= kQueueCapacity) {
    refuse(c, Refusal::queue_full, "the trajectory queue is full");
    return;
  }
  if ((c.segment.start - queue_.end()).norm() > 1e-6) {
    refuse(c, Refusal::not_continuous,
          "the segment does not start where the queue ends (the state changed meanwhile)");
    return;
  }
  const ctl::Trajectory* tr = c.segment.get();
  if (!c.segment.allow_step && !check_start(*tr, queue_.end_velocity(), cfg_.limits, dt_).ok()) {
    refuse(c, Refusal::not_continuous,
          "the segment does not start with the velocity and acceleration the queue ends with (a step the "
          "acceleration limit does not allow in one period)");
    return;
  }
  queue_.push(c.segment, c.id);  // the command's id is the segment's
  if (mode_.now() == Mode::holding) {
    enter(Mode::moving);
    start_next_segment(k);
  }
  accept(c, "queued");
}

void ControlLoop::handle_home(const Command& c, std::int64_t k) noexcept {
  if (mode_.now() != Mode::holding) {
    refuse(c, Refusal::illegal_in_mode,
          mode_.now() == Mode::homing ? "homing already runs" : "homing needs the drives enabled and the platform at rest (holding)");
    return;
  }
  // The configured order, filtered by the request; absolute actuators asked
  // for are not in the order: homed already.
  if (homing_.plan(cfg_.homing, c.home_axes) == 0)
    return accept(c, "nothing to home: the actuators asked for have absolute encoders");
  ramp_in_actuators();
  enter(Mode::homing);
  begin_axis_homing(k);
  accept(c, "homing");
}

void ControlLoop::begin_axis_homing(std::int64_t k) noexcept {
  const int i = homing_.begin_next();
  const AxisHomingConfig& h = cfg_.homing.axes[static_cast<std::size_t>(i)];
  // A drive that homes itself redefines its own counts: no offset of ours.
  if (h.method == HomingMethod::drive) {
    homing_.offset[i] = 0.0;
    io_.cin.d[i] = io_.raw[i];
    ramp_.p[i] = io_.raw[i];
    ramp_.v[i] = 0.0;
  }
  homing_.axis_homing.start(h, static_cast<double>(k) * dt_, io_.in.home_switch[static_cast<std::size_t>(i)]);
}

void ControlLoop::handle_jog(const Command& c, std::int64_t k) noexcept {
  if (mode_.now() != Mode::holding && mode_.now() != Mode::jogging) {
    refuse(c, Refusal::illegal_in_mode, "jogging needs the drives enabled and no other motion (holding or jogging)");
    return;
  }
  const bool machine_frame = c.jog_frame == kJogMachineFrame;
  if (machine_frame && !homing_.all_homed()) {
    refuse(c, Refusal::not_homed,
          "a jog in the machine frame needs every actuator homed (the platform's position); jog the actuators, or home first");
    return;
  }
  const double speed = machine_frame ? c.jog_velocity.norm() : c.jog_velocity.cwiseAbs().maxCoeff();
  if (speed > cfg_.jog.max_velocity * (1.0 + 1e-9)) {
    refuse(c, Refusal::limit, "the jog is faster than jog.max_velocity");
    return;
  }
  if (mode_.now() == Mode::jogging && machine_frame != ramp_.task && !ramp_.at_rest()) {
    refuse(c, Refusal::illegal_in_mode, "the jog in the other frame is still moving: let it stop first");
    return;
  }
  // Where the jog starts from, in its frame.
  if (mode_.now() == Mode::holding || machine_frame != ramp_.task || !ramp_.active) {
    // The ramp starts at rest; a target of the other frame means nothing in
    // this one (and must not drive it if this command is refused).
    jog_.target.setZero();
    if (machine_frame) {
      // From the hold point, or where the other frame's jog came to rest.
      ramp_.reset(mode_.now() == Mode::holding ? hold_ : io_.ref.p);
      ramp_.task = true;
      ramp_.active = true;
    } else {
      ramp_in_actuators();
    }
  }
  // Refused outside the workspace: toward an end the reference is at (or
  // beyond), nothing moves. An actuator jog once homed moves the platform
  // too: its box keeps the platform in the workspace (computed here, for
  // this command's velocity, and kept only if the command is taken).
  Vec3 lo, hi;
  unsigned by_workspace = 0;
  const bool actuator_box = !machine_frame && homing_.all_homed();
  if (actuator_box) {
    by_workspace = actuator_jog_box(c.jog_velocity, lo, hi);
  } else {
    ramp_box(lo, hi);
  }
  for (int i = 0; i < 3; ++i) {
    const double v = c.jog_velocity[i];
    const bool up = v > 0.0 && ramp_.p[i] >= hi[i] - 1e-9, down = v < 0.0 && ramp_.p[i] <= lo[i] + 1e-9;
    if (up || down) {
      if (mode_.now() == Mode::holding && homing_.all_homed()) {
        ramp_.active = false;  // nothing moved: the task space holds as before
      }
      const bool workspace = machine_frame || (by_workspace & (1u << (2 * i + (up ? 1 : 0)))) != 0;
      refuse(c, Refusal::workspace,
            machine_frame ? "the jog leads out of the workspace (limits.workspace_min/max): the platform is at its edge"
            : workspace   ? "the actuator jog would take the platform out of the workspace (limits.workspace_min/max): "
                            "it is at the edge this actuator moves it across; jog in the machine frame along the edge"
                          : "the jog leads beyond the actuator's stroke: the actuator is at its end");
      return;
    }
  }
  if (actuator_box) jog_.keep_box(lo, hi);
  jog_.take(c.jog_frame, c.jog_velocity, k + static_cast<std::int64_t>(std::ceil(cfg_.jog.keepalive / dt_ - 1e-9)));
  if (mode_.now() == Mode::holding) {
    flush_queue();
    enter(Mode::jogging);
  }
  accept(c, "jogging");
}

void ControlLoop::handle_settings(const Command& c) noexcept {
  const bool at_rest = mode_.now() == Mode::disabled || mode_.now() == Mode::holding || mode_.now() == Mode::fault ||
                       mode_.now() == Mode::init || mode_.now() == Mode::enabling;
  if (!at_rest && !c.while_moving) {
    refuse(c, Refusal::illegal_in_mode,
          "this parameter may change only when disabled or holding: what moves now was checked against its old value");
    return;
  }
  cfg_.limits = c.settings.limits;
  cfg_.jog = c.settings.jog;
  cfg_.controller.transfer_time = c.settings.transfer_time;
  accept(c, "set");
}

unsigned ControlLoop::actuator_jog_box(const Vec3& v_target, Vec3& lo, Vec3& hi) const noexcept {
  // Each end of each actuator's interval around d0, the reference now:
  // end 2i + 0 toward -d_i, 2i + 1 toward +d_i. An end the jog drives to
  // reaches the workspace's face (the inverse kinematics of the platform
  // point on the face, the other coordinates where they are: exact for a
  // one-actuator jog, whatever the model's effects) or the stroke's end;
  // an end it does not drive to gets the distance the reference still
  // needs to stop there, nothing if it does not move that way.
  const kin::KinematicModel& km = model_.machine().kinematics();
  const kin::Strokes& st = model_.machine().model().strokes;
  const Vec3& wmin = cfg_.limits.workspace_min;
  const Vec3& wmax = cfg_.limits.workspace_max;
  const Vec3 d0 = ramp_.p;
  lo = hi = d0;
  Vec3 x0;
  if (!kin::forward(km, d0, io_.cin.kin, x0).ok()) return 0x3fu;  // no platform point: nothing moves
  std::array<double, 6> reach{};
  std::array<Vec3, 6> moved{};  // the platform's displacement at each end (m)
  unsigned by_workspace = 0;
  for (std::size_t e = 0; e < 6; ++e) {
    const int i = static_cast<int>(e / 2);
    const double sign = (e % 2) ? 1.0 : -1.0;
    kin::KinematicInputs in = io_.cin.kin;
    in.dir[e / 2] = static_cast<std::int8_t>(sign);
    double face = 0.0;
    Vec3 xf = x0;
    xf[i] = sign > 0 ? wmax[i] : wmin[i];
    Vec3 df;
    if (sign * (xf[i] - x0[i]) > 0.0 && kin::inverse(km, xf, in, df).ok()) face = std::max(0.0, sign * (df[i] - d0[i]));
    const double stroke = std::max(0.0, sign > 0 ? st.max[i] - d0[i] : d0[i] - st.min[i]);
    double r = std::min(face, stroke);
    if (face <= stroke) by_workspace |= 1u << e;
    if (!(sign * v_target[i] > 0.0)) {
      const double v = sign * ramp_.v[i];
      const double stop = v > 0.0 ? v * v / (2.0 * cfg_.jog.acceleration) + v * dt_ : 0.0;
      r = std::min(r, stop);
    }
    reach[e] = r;
    Vec3 d = d0, x;
    d[i] += sign * r;
    moved[e] = r > 0.0 && kin::forward(km, d, in, x).ok() ? Vec3(x - x0) : Vec3::Zero();
  }
  // An actuator also moves the platform across the other faces (a plane not
  // square to its axis): where the ends together would cross a face, shrink
  // every end that moves toward it in proportion (the map is near-linear).
  std::array<double, 6> keep;
  keep.fill(1.0);
  for (std::size_t f = 0; f < 6; ++f) {
    const int k = static_cast<int>(f / 2);
    const double sign = (f % 2) ? 1.0 : -1.0;
    const double room = std::max(0.0, sign > 0 ? wmax[k] - x0[k] : x0[k] - wmin[k]);
    double total = 0.0;  // one end of each actuator at a time: the farther one
    for (std::size_t e = 0; e < 6; e += 2) total += std::max({0.0, sign * moved[e][k], sign * moved[e + 1][k]});
    if (total <= room * (1.0 + 1e-9)) continue;
    const double share = room / total;
    for (std::size_t e = 0; e < 6; ++e)
      if (sign * moved[e][k] > 0.0) {
        keep[e] = std::min(keep[e], share);
        if (e / 2 != f / 2 || share < 1.0 - 1e-6) by_workspace |= 1u << e;
      }
  }
  for (int i = 0; i < 3; ++i) {
    const std::size_t down = 2 * static_cast<std::size_t>(i), up = down + 1;
    lo[i] = d0[i] - reach[down] * keep[down];
    hi[i] = d0[i] + reach[up] * keep[up];
  }
  return by_workspace;
}

}  // namespace cpm::daemon
