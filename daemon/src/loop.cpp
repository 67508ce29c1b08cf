#include "cpm/daemon/loop.hpp"

#include <time.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>

#include <cpm_msgs/ack_t.hpp>

#include "cpm/kinematics/workspace.hpp"
#include "cpm/path/program.hpp"

namespace cpm::daemon {

using cpm_msgs::ack_t;
using cpm_msgs::state_t;

const ctl::Trajectory* Segment::get() const noexcept {
  if (auto* c = std::get_if<ctl::CircleTrajectory>(&traj)) return c;
  if (auto* p = std::get_if<ctl::PointToPoint>(&traj)) return p;
  if (auto* s = std::get_if<StreamTrajectory>(&traj)) return s;
  if (auto* p = std::get_if<const path::Plan*>(&traj)) return *p;
  return nullptr;
}

int histogram_bin(std::int64_t ns) noexcept {
  if (ns < 0) ns = 0;
  const std::int64_t us = ns / 1000;
  if (us < 200) return static_cast<int>(us);
  if (us < 2000) return 200 + static_cast<int>((us - 200) / 50);
  return kBins - 1;
}

std::int64_t histogram_bin_floor(int k) noexcept {
  if (k < 200) return std::int64_t{k} * 1000;
  return (200 + std::int64_t{k - 200} * 50) * 1000;
}

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
      machine_(&machine),
      controller_(controller),
      dt_(1.0 / config.loop.rate_hz),
      queue_(std::make_unique<std::array<Segment, kQueueCapacity>>()) {
  ctl::check_delay_fits(machine.actuation_delay(), config.loop.rate_hz);
  ctl::check_delay_fits(controller.lookahead(), config.loop.rate_hz);
  stats_.rate_hz = config.loop.rate_hz;
  for (int s = 0; s < kSeries; ++s) stats_.min_ns[s] = 0;
  state_.mode = static_cast<std::int8_t>(Mode::init);
  state_.segment_id = -1;
  state_.last_segment_id = -1;
  state_.fault_axis = -1;
  state_.fault_cycle = -1;
  state_.homing_axis = -1;
  // Absolute encoders know their zero from the start; the others wait for
  // homing, and until then the loop holds and moves each actuator on its own.
  for (int i = 0; i < 3; ++i) homed_[i] = cfg_.homing.axes[i].method == HomingMethod::absolute;
  ramp_active_ = !all_homed();
  ramp_task_ = false;
}

void segment_end_motion(const Segment& s, Vec3& velocity, Vec3& acceleration) noexcept {
  const ctl::Trajectory* tr = s.get();
  const auto* stream = std::get_if<StreamTrajectory>(&s.traj);
  if (!tr || !stream) {
    // Moves and circles end at rest (a circle's ramp, or Elkady's abrupt
    // stop, which the hold then takes as a step: the loop plays what it was
    // given, and the next segment starts from rest).
    velocity.setZero();
    acceleration.setZero();
    return;
  }
  velocity = stream->end_velocity();
  acceleration = tr->sample(tr->duration()).a;
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

void ControlLoop::set_scheduling_info(bool realtime, bool memory_locked) noexcept {
  stats_.realtime = realtime ? 1 : 0;
  stats_.memory_locked = memory_locked ? 1 : 0;
}

void ControlLoop::add_sample(int s, std::int64_t ns) noexcept {
  if (ns < 0) ns = 0;
  const auto v = static_cast<std::int32_t>(std::min<std::int64_t>(ns, INT32_MAX));
  if (stats_.count[s] == 0 || v < stats_.min_ns[s]) stats_.min_ns[s] = v;
  if (v > stats_.max_ns[s]) stats_.max_ns[s] = v;
  stats_.count[s]++;
  stats_.sum_ns[s] += static_cast<double>(v);
  stats_.histogram[s][histogram_bin(ns)]++;
}

void ControlLoop::enter(Mode m) noexcept {
  if (m != Mode::stopping) underrun_pending_ = false;
  mode_ = m;
  mode_atomic_.store(m, std::memory_order_release);
}

void ControlLoop::latch(std::uint32_t bit, int axis, double value, double limit, std::int64_t k,
                        const char* cause) noexcept {
  if (faults_ == 0) {
    first_fault_ = bit;
    fault_axis_ = axis;
    fault_value_ = value;
    fault_limit_ = limit;
    fault_cycle_ = k;
    // The backend's own words for the faults it reports (e.g. which drive lost
    // its heartbeat), else the kinematic cause, which says what the value and
    // limit measure (fault_report: a stroke in m, an elbow angle in rad).
    const char* why = (bit & (kFaultDrive | kFaultBackendIo | kFaultEstop | kFaultLimitSwitch)) ? backend_->fault_text() : cause;
    std::strncpy(fault_text_, why, sizeof fault_text_ - 1);
    fault_text_[sizeof fault_text_ - 1] = '\0';
  }
  faults_ |= bit;
  saturated_cycles_ = {};
  underrun_pending_ = false;
  if (mode_ != Mode::fault) {
    if (playing_) finish_segment();
    flush_queue();
    disable_after_stop_ = false;
    // Homing ends: the actuator being homed stays unhomed.
    if (homing_axis_ >= 0) end_homing(false, k);
    jog_target_.setZero();
    transfer_pending_ = false;
    transfer_force_.setZero();
    enter(Mode::fault);
  }
}

void ControlLoop::clear_slot(Segment& s) noexcept {
  // The ring holds twice the queue: a push cannot fail while the server drains it.
  if (auto* p = std::get_if<const path::Plan*>(&s.traj)) (void)retired_plans_.push(*p);
  s.traj = std::monostate{};
}

void ControlLoop::flush_queue() noexcept {
  for (int i = 0; i < q_count_; ++i) clear_slot((*queue_)[(q_head_ + i) % kQueueCapacity]);
  q_head_ = 0;
  q_count_ = 0;
  playing_ = false;
  queue_end_v_.setZero();
  queue_end_a_.setZero();
}

void ControlLoop::finish_segment() noexcept {
  last_seg_id_ = (*queue_)[q_head_].id;
  last_seg_n_ = seg_n_;
  last_seg_rmse_ = seg_n_ > 0 ? std::sqrt(seg_sum_e2_ / seg_n_) : 0.0;
  last_seg_max_ = seg_max_e_;
  clear_slot((*queue_)[q_head_]);
  q_head_ = (q_head_ + 1) % kQueueCapacity;
  q_count_--;
  playing_ = false;
}

bool ControlLoop::start_next_segment(std::int64_t k) noexcept {
  if (q_count_ == 0) return false;
  playing_ = true;
  segment_start_cycle_ = k;
  seg_sum_e2_ = 0;
  seg_max_e_ = 0;
  seg_n_ = 0;
  return true;
}

void ControlLoop::start_stop(std::int64_t k) noexcept {
  if (ramp_active_) {
    // A ramp motion (homing, a jog, anything before homing): its speed goes
    // to zero at the stop's deceleration (trajectory()); a homing stopped
    // leaves its actuator unhomed.
    if (homing_axis_ >= 0) end_homing(false, k);
    jog_target_.setZero();
    flush_queue();
    enter(Mode::stopping);
    return;
  }
  // Decelerate along the reference's current direction of motion at the
  // configured rate, from where the reference is now.
  stop_p0_ = ref_.p;
  const double v = ref_.v.norm();
  stop_v0_ = v;
  stop_dir_ = v > 1e-12 ? Vec3(ref_.v / v) : Vec3::Zero();
  stop_T_ = v / cfg_.limits.stop_deceleration;
  stop_start_cycle_ = k;
  stop_t0_ = 0;
  if (playing_) finish_segment();
  flush_queue();
  enter(Mode::stopping);
}

void ControlLoop::start_underrun_stop(const Segment& s, std::int64_t k, double late) noexcept {
  // The stream's last chunk ended at speed and nothing follows it: decelerate
  // from where and how fast the chunk ended, `late` s ago (the profile is
  // continuous with the chunk: nothing jumps), then latch the fault at rest.
  const Vec3 v_end = std::get_if<StreamTrajectory>(&s.traj)->end_velocity();
  const double v = v_end.norm();
  stop_p0_ = s.end;
  stop_v0_ = v;
  stop_dir_ = Vec3(v_end / v);
  stop_T_ = v / cfg_.limits.stop_deceleration;
  stop_start_cycle_ = k;
  stop_t0_ = late;
  finish_segment();  // `s` is the playing segment: read above, cleared here
  flush_queue();
  enter(Mode::stopping);
  underrun_pending_ = true;
  underrun_cycle_ = k;
  underrun_speed_ = v;
}

void ControlLoop::reply(const Command& c, bool ok, std::int16_t reason, const char* msg,
                        const ctl::Machine* retired) noexcept {
  Ack a;
  a.id = c.id;
  a.source = c.source;
  a.code = c.code;
  a.accepted = ok;
  a.reason = reason;
  a.message = msg;
  a.mode = mode_;
  a.queue_depth = static_cast<std::int16_t>(q_count_);
  a.retired = retired;
  a.queue_end = queue_end_;
  a.queue_end_velocity = queue_end_v_;
  a.queue_end_acceleration = queue_end_a_;
  // The LCM thread drains 64 acks per millisecond at least; a full ring
  // would lose only the ack, never the command's effect.
  (void)acks_.push(a);
}

void ControlLoop::handle(const Command& c, std::int64_t k) noexcept {
  constexpr std::int16_t kIllegal = ack_t::REASON_ILLEGAL_IN_MODE;
  switch (c.kind) {
    case CommandKind::ping:
      reply(c, true, 0, "pong");
      return;
    case CommandKind::enable:
      if (mode_ == Mode::disabled) {
        hold_ = est_.p;  // resynchronise: hold where the platform is
        queue_end_ = hold_;
        ramp_.reset(cin_.d);  // (the actuator space's hold)
        ctl_state_.reset();  // the drives were given nothing while off
        enabling_since_ = k;
        enter(Mode::enabling);
        reply(c, true, 0, "enabling");
      } else if (mode_ == Mode::fault) {
        reply(c, false, ack_t::REASON_FAULT_ACTIVE, "a fault is latched: reset first");
      } else {
        reply(c, false, kIllegal, "enable is legal only when disabled");
      }
      return;
    case CommandKind::disable:
      if (mode_ == Mode::enabling || mode_ == Mode::holding) {
        flush_queue();
        enter(Mode::disabled);
        reply(c, true, 0, "disabled");
      } else if (mode_ == Mode::moving || mode_ == Mode::homing || mode_ == Mode::jogging) {
        start_stop(k);
        disable_after_stop_ = true;
        reply(c, true, 0, "stopping, then disabling");
      } else if (mode_ == Mode::stopping) {
        disable_after_stop_ = true;
        reply(c, true, 0, "disabling once stopped");
      } else if (mode_ == Mode::fault) {
        reply(c, false, kIllegal, "in fault the drives are already off");
      } else {
        reply(c, false, kIllegal, "already disabled");
      }
      return;
    case CommandKind::stop:
      if (mode_ == Mode::moving || mode_ == Mode::homing || mode_ == Mode::jogging) {
        start_stop(k);
        reply(c, true, 0, "stopping");
      } else if (mode_ == Mode::holding || mode_ == Mode::stopping) {
        flush_queue();
        reply(c, true, 0, "already at rest or stopping; queue cleared");
      } else {
        reply(c, false, kIllegal, "stop needs the drives enabled (holding, moving, homing, jogging or stopping)");
      }
      return;
    case CommandKind::reset:
      if (mode_ != Mode::fault) {
        reply(c, false, kIllegal, "no fault latched");
        return;
      }
      if (in_.estop) {
        reply(c, false, ack_t::REASON_FAULT_ACTIVE, "the e-stop chain is still open");
        return;
      }
      if (in_.drive_fault[0] || in_.drive_fault[1] || in_.drive_fault[2]) {
        reply(c, false, ack_t::REASON_FAULT_ACTIVE, "a drive still reports a fault");
        return;
      }
      if (!backend_ok_) {
        reply(c, false, ack_t::REASON_FAULT_ACTIVE, "the backend still reports an I/O error (bus, GPIO)");
        return;
      }
      faults_ = 0;
      first_fault_ = 0;
      fault_axis_ = -1;
      fault_value_ = fault_limit_ = 0;
      fault_cycle_ = -1;
      fault_text_[0] = '\0';
      saturated_cycles_ = {};
      consecutive_overruns_ = 0;
      overrun_fault_pending_ = false;
      hold_ = est_.p;
      queue_end_ = hold_;
      ramp_.reset(cin_.d);
      enter(Mode::disabled);
      reply(c, true, 0, "fault reset; disabled, setpoint at the measured position");
      return;
    case CommandKind::select_controller:
      if (mode_ == Mode::disabled || mode_ == Mode::holding) {
        // While holding in the task space the new law starts from the force
        // the old one gave: the difference is faded out (bumpless).
        if (mode_ == Mode::holding && all_homed() && !ramp_active_) transfer_pending_ = true;
        controller_ = *c.controller;
        reply(c, true, 0, mode_ == Mode::holding ? "controller selected; the force difference fades out" : "controller selected");
      } else {
        reply(c, false, kIllegal, "select the controller when disabled or holding");
      }
      return;
    case CommandKind::load_model:
      if (mode_ == Mode::disabled) {
        const ctl::Machine* old = machine_;
        machine_ = c.machine;
        controller_ = *c.controller;
        reply(c, true, 0, "model loaded", old);
      } else {
        // Hand the unused model back so that it is freed.
        reply(c, false, kIllegal, "load a model only when disabled", c.machine);
      }
      return;
    case CommandKind::home:
      handle_home(c, k);
      return;
    case CommandKind::jog:
      handle_jog(c, k);
      return;
    case CommandKind::set_params:
      handle_settings(c);
      return;
    case CommandKind::segment:
      handle_segment(c, k);
      return;
    case CommandKind::none:
      return;
  }
}

void ControlLoop::handle_segment(const Command& c, std::int64_t k) noexcept {
  if (!all_homed()) {
    reply(c, false, ack_t::REASON_NOT_HOMED,
          "not every actuator is homed: the platform's position is not known; home the machine first (cpm home)");
    return;
  }
  if (mode_ != Mode::holding && mode_ != Mode::moving) {
    reply(c, false, ack_t::REASON_ILLEGAL_IN_MODE, "trajectories are accepted only when holding or moving");
    return;
  }
  if (q_count_ >= kQueueCapacity) {
    reply(c, false, ack_t::REASON_QUEUE_FULL, "the trajectory queue is full");
    return;
  }
  if ((c.segment.start - queue_end_).norm() > 1e-6) {
    reply(c, false, ack_t::REASON_NOT_CONTINUOUS,
          "the segment does not start where the queue ends (the state changed meanwhile)");
    return;
  }
  const ctl::Trajectory* tr = c.segment.get();
  if (!c.segment.allow_step && !check_start(*tr, queue_end_v_, cfg_.limits, dt_).ok()) {
    reply(c, false, ack_t::REASON_NOT_CONTINUOUS,
          "the segment does not start with the velocity and acceleration the queue ends with (a step the "
          "acceleration limit does not allow in one period)");
    return;
  }
  Segment& slot = (*queue_)[(q_head_ + q_count_) % kQueueCapacity];
  slot = c.segment;
  slot.id = c.id;  // the command's id is the segment's
  q_count_++;
  queue_end_ = c.segment.end;
  segment_end_motion(slot, queue_end_v_, queue_end_a_);
  if (mode_ == Mode::holding) {
    enter(Mode::moving);
    start_next_segment(k);
  }
  reply(c, true, 0, "queued");
}

void ControlLoop::handle_home(const Command& c, std::int64_t k) noexcept {
  if (mode_ != Mode::holding) {
    reply(c, false, ack_t::REASON_ILLEGAL_IN_MODE,
          mode_ == Mode::homing ? "homing already runs" : "homing needs the drives enabled and the platform at rest (holding)");
    return;
  }
  // The configured order, filtered by the request.
  home_count_ = 0;
  for (int n = 0; n < cfg_.homing.order_count; ++n) {
    const int i = cfg_.homing.order[static_cast<std::size_t>(n)];
    if (c.home_axes == 0 || (c.home_axes & (1u << i))) home_queue_[static_cast<std::size_t>(home_count_++)] = i;
  }
  // Absolute actuators asked for but not in the order: homed already.
  if (home_count_ == 0) {
    reply(c, true, 0, "nothing to home: the actuators asked for have absolute encoders");
    return;
  }
  for (int n = 0; n < home_count_; ++n) homed_[static_cast<std::size_t>(home_queue_[static_cast<std::size_t>(n)])] = false;
  ramp_in_actuators();
  home_next_ = 0;
  enter(Mode::homing);
  begin_axis_homing(k);
  reply(c, true, 0, "homing");
}

void ControlLoop::begin_axis_homing(std::int64_t k) noexcept {
  const int i = home_queue_[static_cast<std::size_t>(home_next_++)];
  homing_axis_ = i;
  const AxisHomingConfig& h = cfg_.homing.axes[static_cast<std::size_t>(i)];
  // A drive that homes itself redefines its own counts: no offset of ours.
  if (h.method == HomingMethod::drive) {
    offset_[i] = 0.0;
    cin_.d[i] = raw_[i];
    ramp_.p[i] = raw_[i];
    ramp_.v[i] = 0.0;
  }
  axis_homing_.start(h, static_cast<double>(k) * dt_, in_.home_switch[static_cast<std::size_t>(i)]);
}

void ControlLoop::end_homing(bool completed, std::int64_t k) noexcept {
  (void)k;
  if (!completed) axis_homing_.abort();
  homing_axis_ = -1;
  home_count_ = home_next_ = 0;
  homing_request_ = {};
}

void ControlLoop::handle_jog(const Command& c, std::int64_t k) noexcept {
  if (mode_ != Mode::holding && mode_ != Mode::jogging) {
    reply(c, false, ack_t::REASON_ILLEGAL_IN_MODE, "jogging needs the drives enabled and no other motion (holding or jogging)");
    return;
  }
  const bool machine_frame = c.jog_frame == 1;
  if (machine_frame && !all_homed()) {
    reply(c, false, ack_t::REASON_NOT_HOMED,
          "a jog in the machine frame needs every actuator homed (the platform's position); jog the actuators, or home first");
    return;
  }
  const double speed = machine_frame ? c.jog_velocity.norm() : c.jog_velocity.cwiseAbs().maxCoeff();
  if (speed > cfg_.jog.max_velocity * (1.0 + 1e-9)) {
    reply(c, false, ack_t::REASON_LIMIT, "the jog is faster than jog.max_velocity");
    return;
  }
  if (mode_ == Mode::jogging && machine_frame != ramp_task_ && !ramp_.at_rest()) {
    reply(c, false, ack_t::REASON_ILLEGAL_IN_MODE, "the jog in the other frame is still moving: let it stop first");
    return;
  }
  // Where the jog starts from, in its frame.
  if (mode_ == Mode::holding || machine_frame != ramp_task_ || !ramp_active_) {
    // The ramp starts at rest; a target of the other frame means nothing in
    // this one (and must not drive it if this command is refused).
    jog_target_.setZero();
    if (machine_frame) {
      // From the hold point, or where the other frame's jog came to rest.
      ramp_.reset(mode_ == Mode::holding ? hold_ : ref_.p);
      ramp_task_ = true;
      ramp_active_ = true;
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
  const bool actuator_box = !machine_frame && all_homed();
  if (actuator_box) {
    by_workspace = actuator_jog_box(c.jog_velocity, lo, hi);
  } else {
    ramp_box(lo, hi);
  }
  for (int i = 0; i < 3; ++i) {
    const double v = c.jog_velocity[i];
    const bool up = v > 0.0 && ramp_.p[i] >= hi[i] - 1e-9, down = v < 0.0 && ramp_.p[i] <= lo[i] + 1e-9;
    if (up || down) {
      if (mode_ == Mode::holding && all_homed()) {
        ramp_active_ = false;  // nothing moved: the task space holds as before
      }
      const bool workspace = machine_frame || (by_workspace & (1u << (2 * i + (up ? 1 : 0)))) != 0;
      reply(c, false, ack_t::REASON_WORKSPACE,
            machine_frame ? "the jog leads out of the workspace (limits.workspace_min/max): the platform is at its edge"
            : workspace   ? "the actuator jog would take the platform out of the workspace (limits.workspace_min/max): "
                            "it is at the edge this actuator moves it across; jog in the machine frame along the edge"
                          : "the jog leads beyond the actuator's stroke: the actuator is at its end");
      return;
    }
  }
  if (actuator_box) {
    actuator_box_lo_ = lo;
    actuator_box_hi_ = hi;
    actuator_box_ready_ = true;
  }
  jog_frame_ = c.jog_frame;
  jog_target_ = c.jog_velocity;
  jog_deadline_ = k + static_cast<std::int64_t>(std::ceil(cfg_.jog.keepalive / dt_ - 1e-9));
  if (mode_ == Mode::holding) {
    flush_queue();
    enter(Mode::jogging);
  }
  reply(c, true, 0, "jogging");
}

void ControlLoop::handle_settings(const Command& c) noexcept {
  const bool at_rest = mode_ == Mode::disabled || mode_ == Mode::holding || mode_ == Mode::fault ||
                       mode_ == Mode::init || mode_ == Mode::enabling;
  if (!at_rest && !c.while_moving) {
    reply(c, false, ack_t::REASON_ILLEGAL_IN_MODE,
          "this parameter may change only when disabled or holding: what moves now was checked against its old value");
    return;
  }
  cfg_.limits = c.settings.limits;
  cfg_.jog = c.settings.jog;
  cfg_.controller.transfer_time = c.settings.transfer_time;
  reply(c, true, 0, "set");
}

void ControlLoop::ramp_in_actuators() noexcept {
  actuator_box_ready_ = false;  // the next actuator jog computes its own
  if (ramp_active_ && !ramp_task_) return;  // already there
  // From the actuator reference the task space last had: nothing jumps.
  ramp_.reset(d_ref_);
  ramp_task_ = false;
  ramp_active_ = true;
  if (all_homed()) return;
  // Leaving the task space: the actuator law starts from the force the
  // task law gave.
  transfer_pending_ = true;
}

void ControlLoop::leave_ramp() noexcept {
  // In the task space, hold where the ramp came to rest.
  if (!all_homed()) return;  // the actuator space holds on the ramp itself
  hold_ = ref_.p;
  queue_end_ = hold_;
  queue_end_v_.setZero();
  queue_end_a_.setZero();
  ramp_active_ = false;
}

void ControlLoop::ramp_box(Vec3& lo, Vec3& hi) const noexcept {
  if (ramp_task_) {
    lo = cfg_.limits.workspace_min;
    hi = cfg_.limits.workspace_max;
    return;
  }
  if (all_homed() && actuator_box_ready_) {
    lo = actuator_box_lo_;
    hi = actuator_box_hi_;
    return;
  }
  const kin::Strokes& s = machine_->model().strokes;
  for (int i = 0; i < 3; ++i) {
    lo[i] = homed_[i] ? s.min[i] : -std::numeric_limits<double>::infinity();
    hi[i] = homed_[i] ? s.max[i] : std::numeric_limits<double>::infinity();
  }
}

unsigned ControlLoop::actuator_jog_box(const Vec3& v_target, Vec3& lo, Vec3& hi) const noexcept {
  // Each end of each actuator's interval around d0, the reference now:
  // end 2i + 0 toward -d_i, 2i + 1 toward +d_i. An end the jog drives to
  // reaches the workspace's face (the inverse kinematics of the platform
  // point on the face, the other coordinates where they are: exact for a
  // one-actuator jog, whatever the model's effects) or the stroke's end;
  // an end it does not drive to gets the distance the reference still
  // needs to stop there, nothing if it does not move that way.
  const kin::KinematicModel& km = machine_->kinematics();
  const kin::Strokes& st = machine_->model().strokes;
  const Vec3& wmin = cfg_.limits.workspace_min;
  const Vec3& wmax = cfg_.limits.workspace_max;
  const Vec3 d0 = ramp_.p;
  lo = hi = d0;
  Vec3 x0;
  if (!kin::forward(km, d0, cin_.kin, x0).ok()) return 0x3fu;  // no platform point: nothing moves
  std::array<double, 6> reach{};
  std::array<Vec3, 6> moved{};  // the platform's displacement at each end (m)
  unsigned by_workspace = 0;
  for (std::size_t e = 0; e < 6; ++e) {
    const int i = static_cast<int>(e / 2);
    const double sign = (e % 2) ? 1.0 : -1.0;
    kin::KinematicInputs in = cin_.kin;
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

void ControlLoop::handle_commands(std::int64_t k) noexcept {
  // A stop rung in from the server's stop listener: before any command.
  if (const std::uint64_t r = stop_requests_.load(std::memory_order_acquire); r != stops_taken_) {
    stops_taken_ = r;
    if (mode_ == Mode::moving || mode_ == Mode::homing || mode_ == Mode::jogging) start_stop(k);
  }
  // A bounded number per cycle keeps the cycle's time bounded.
  for (int n = 0; n < kCommandsPerCycle; ++n) {
    const Command* c = commands_.front();
    if (!c) return;
    handle(*c, k);
    commands_.release();
  }
}

ctl::TrajectorySample ControlLoop::reference(std::int64_t k) noexcept {
  ctl::TrajectorySample r;
  switch (mode_) {
    case Mode::moving: {
      while (playing_) {
        const Segment& s = (*queue_)[q_head_];
        const ctl::Trajectory* tr = s.get();
        const double t = static_cast<double>(k - segment_start_cycle_) * dt_;
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
        const bool starved = q_count_ == 1 && std::holds_alternative<StreamTrajectory>(s.traj) &&
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
      const double elapsed = static_cast<double>(k - stop_start_cycle_) * dt_ + stop_t0_;
      const double t = std::min(elapsed, stop_T_);
      const double a = cfg_.limits.stop_deceleration;
      r.p = stop_p0_ + stop_dir_ * (stop_v0_ * t - 0.5 * a * t * t);
      r.v = stop_dir_ * (stop_v0_ - a * t);
      r.a = t < stop_T_ ? Vec3(-a * stop_dir_) : Vec3::Zero();
      if (elapsed >= stop_T_) {
        hold_ = r.p;
        queue_end_ = hold_;
        r.v.setZero();
        if (underrun_pending_) {
          // At rest: now the drives may go off (brakes on) without a jolt.
          underrun_pending_ = false;
          latch(kFaultStreamUnderrun, -1, underrun_speed_, kStreamRestSpeed, underrun_cycle_);
          return r;
        }
        enter(disable_after_stop_ ? Mode::disabled : Mode::holding);
        disable_after_stop_ = false;
      }
      return r;
    }
    case Mode::holding:
      r.p = hold_;
      return r;
    default:
      // Drives off: the setpoint follows the measurement, so enabling starts from it.
      r.p = estimate_ok_ ? est_.p : hold_;
      hold_ = r.p;
      queue_end_ = hold_;
      return r;
  }
}

ctl::TrajectorySample ControlLoop::reference_ahead(std::int64_t k, double ahead) const noexcept {
  // The profiles of reference(), sampled `ahead` s after cycle k, without
  // their side effects (a segment finishes, a stop ends, when reference()
  // reaches them). A segment that follows another starts at the first cycle
  // at or after its predecessor's end, as reference() starts it.
  if (mode_ == Mode::moving && playing_) {
    double t = static_cast<double>(k - segment_start_cycle_) * dt_ + ahead;
    for (int i = 0; i < q_count_; ++i) {
      const Segment& s = (*queue_)[(q_head_ + i) % kQueueCapacity];
      const ctl::Trajectory* tr = s.get();
      const double played = std::ceil((tr->duration() - 1e-9) / dt_ - 1e-9) * dt_;
      if (t < played) return tr->sample(t);
      t -= played;
    }
    ctl::TrajectorySample r;  // past the queue's end: the hold there
    r.p = (*queue_)[(q_head_ + q_count_ - 1) % kQueueCapacity].end;
    return r;
  }
  if (mode_ == Mode::stopping) {
    const double elapsed = static_cast<double>(k - stop_start_cycle_) * dt_ + stop_t0_ + ahead;
    const double t = std::min(elapsed, stop_T_);
    const double a = cfg_.limits.stop_deceleration;
    ctl::TrajectorySample r;
    r.p = stop_p0_ + stop_dir_ * (stop_v0_ * t - 0.5 * a * t * t);
    r.v = stop_dir_ * (stop_v0_ - a * t);
    r.a = t < stop_T_ ? Vec3(-a * stop_dir_) : Vec3::Zero();
    return r;
  }
  return ref_;  // holding, enabling: the hold point, which does not move
}

void ControlLoop::record_schedule(bool overrun, std::int64_t skipped) noexcept {
  stats_.skipped += skipped;
  if (overrun) {
    stats_.overruns++;
    if (++consecutive_overruns_ >= cfg_.loop.max_consecutive_overruns) overrun_fault_pending_ = true;
  } else {
    consecutive_overruns_ = 0;
  }
}

void ControlLoop::cycle(std::int64_t k, std::int64_t latency_ns) noexcept {
  // The phases of loop.hpp, in order; each timed into its statistics series
  // (the commands are timed with the estimate, as they always were; homing
  // and jog with the trajectory, whose reference they steer).
  PhaseTimes t{};
  record_latency(latency_ns);
  t[0] = now_ns();
  if (mode_ == Mode::init) enter(Mode::disabled);
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

void ControlLoop::record_latency(std::int64_t latency_ns) noexcept {
  add_sample(kSeriesLatency, latency_ns);
  latency_us_[static_cast<std::size_t>(std::clamp<std::int64_t>(latency_ns / 1000, 0, kFineLatencyBins - 1))]++;
}

bool ControlLoop::drives_on() const noexcept {
  return mode_ == Mode::enabling || mode_ == Mode::holding || mode_ == Mode::moving || mode_ == Mode::stopping ||
         mode_ == Mode::homing || mode_ == Mode::jogging;
}

void ControlLoop::read_inputs(std::int64_t k) noexcept {
  read_result_ = backend_->read(k, in_);
  backend_ok_ = read_result_ == BackendResult::ok && backend_write_ok_;
  raw_ = Vec3(in_.position[0], in_.position[1], in_.position[2]);
  // A drive that lost its position (it rebooted) must be homed again; the
  // loop falls back to the actuator space, from the reference it has.
  for (int i = 0; i < 3; ++i)
    if (in_.position_lost[i] && homed_[i] && cfg_.homing.axes[i].method != HomingMethod::absolute) {
      ramp_in_actuators();
      homed_[i] = false;
    }
}

void ControlLoop::estimate(std::int64_t k) noexcept {
  cin_.d = raw_ + offset_;
  cin_.d_dot = Vec3(in_.velocity[0], in_.velocity[1], in_.velocity[2]);
  // The direction each actuator last moved in, for the model's backlash.
  for (int i = 0; i < 3; ++i)
    if (std::abs(cin_.d_dot[i]) > 1e-6) cin_.kin.dir[i] = cin_.d_dot[i] > 0 ? 1 : -1;
  cin_.kin.t = static_cast<double>(k) * dt_;
  estimate_status_ = read_result_ == BackendResult::ok ? machine_->task_state(cin_.d, cin_.d_dot, cin_.kin, est_)
                                                       : Status::failure(Fault::not_finite);
  estimate_ok_ = estimate_status_.ok();
}

void ControlLoop::apply_commands(std::int64_t k) noexcept {
  if (shutdown_.load(std::memory_order_acquire) && mode_ != Mode::fault && mode_ != Mode::disabled) {
    flush_queue();
    enter(Mode::disabled);
  }
  handle_commands(k);
}

void ControlLoop::homing(std::int64_t k) noexcept {
  if (mode_ != Mode::homing || homing_axis_ < 0) {
    homing_request_ = {};
    return;
  }
  const int i = homing_axis_;
  AxisHoming::Inputs h;
  h.t = static_cast<double>(k) * dt_;
  h.raw = raw_[i];
  h.reference = ramp_.p[i] - offset_[i];
  h.reference_at_rest = ramp_.v[i] == 0.0;
  h.home_switch = in_.home_switch[static_cast<std::size_t>(i)];
  h.index = in_.index_pulse[static_cast<std::size_t>(i)];
  h.drive = in_.drive_homing[static_cast<std::size_t>(i)];
  const AxisHoming::Outcome o = axis_homing_.step(h, homing_request_);
  if (axis_homing_.event_seen() && offset_[i] != axis_homing_.offset()) {
    // The homing event: the actuator's zero is known. The reference and the
    // reading move together, so nothing moves on the machine.
    const double delta = axis_homing_.offset() - offset_[i];
    offset_[i] = axis_homing_.offset();
    cin_.d[i] += delta;
    ramp_.p[i] += delta;
  }
  if (o == AxisHoming::Outcome::failed) {
    const AxisHoming::Failure& f = axis_homing_.failure();
    latch(kFaultHoming, i, f.value, f.limit, k, f.cause);
    return;
  }
  if (o != AxisHoming::Outcome::homed) return;
  homed_[static_cast<std::size_t>(i)] = true;
  homing_request_ = {};
  if (home_next_ < home_count_) {
    begin_axis_homing(k);
    return;
  }
  end_homing(true, k);
  enter(Mode::holding);
}

void ControlLoop::jog(std::int64_t k) noexcept {
  // The deadman: a jog holds for jog.keepalive after its command.
  if (mode_ == Mode::jogging && k >= jog_deadline_) jog_target_.setZero();
}

void ControlLoop::trajectory(std::int64_t k) noexcept {
  if (!ramp_active_) {
    ref_ = reference(k);
    return;
  }
  Vec3 lo, hi;
  ramp_box(lo, hi);
  switch (mode_) {
    case Mode::homing: {
      const int i = homing_axis_;
      const double acc = cfg_.homing.axes[static_cast<std::size_t>(i)].acceleration;
      if (homing_request_.kind == AxisHoming::Request::Kind::drive) {
        // The drive moves itself: the reference follows it.
        ramp_.step(Vec3::Zero(), acc, lo, hi, dt_);
        ramp_.p[i] = cin_.d[i];
        ramp_.v[i] = 0.0;
      } else if (homing_request_.kind == AxisHoming::Request::Kind::position) {
        Vec3 target = ramp_.p;
        target[i] = homing_request_.position + offset_[i];
        ramp_.step_to(target, homing_request_.speed, acc, dt_);
      } else {
        Vec3 v = Vec3::Zero();
        v[i] = homing_request_.velocity;
        ramp_.step(v, acc, lo, hi, dt_);
      }
      break;
    }
    case Mode::jogging:
      ramp_.step(jog_target_, cfg_.jog.acceleration, lo, hi, dt_);
      if (jog_target_.isZero(0.0) && ramp_.at_rest()) enter(Mode::holding);
      break;
    case Mode::stopping: {
      ramp_.step(Vec3::Zero(), std::max(cfg_.jog.acceleration, cfg_.limits.stop_deceleration), lo, hi, dt_);
      if (ramp_.at_rest()) {
        enter(disable_after_stop_ ? Mode::disabled : Mode::holding);
        disable_after_stop_ = false;
      }
      break;
    }
    case Mode::holding:
    case Mode::enabling:
    case Mode::moving:
      break;
    default:
      // Drives off: the reference follows the measurement.
      if (all_homed()) {
        ramp_active_ = false;
        ref_ = reference(k);
        return;
      }
      ramp_task_ = false;
      ramp_.reset(cin_.d);
      break;
  }
  if (ramp_task_) {
    ref_.p = ramp_.p;
    ref_.v = ramp_.v;
    ref_.a = ramp_.a;
  } else {
    reference_of_actuators(ramp_.p, ramp_.v, ramp_.a);
  }
  // A ramp motion in the task space (a jog, or the first hold after homing)
  // ends at rest: the hold point takes over.
  if (mode_ == Mode::holding && all_homed() && ramp_.at_rest()) leave_ramp();
}

void ControlLoop::reference_of_actuators(const Vec3& d, const Vec3& d_dot, const Vec3& d_dd) noexcept {
  ctl::TaskState ts;
  if (machine_->task_state(d, d_dot, cin_.kin, ts).ok()) {
    ref_.p = ts.p;
    ref_.v = ts.p_dot;
    ref_.a = ts.J * d_dd;
  }
  // else (an unhomed actuator far off): the last reference stays on show.
}

void ControlLoop::inverse_kinematics() noexcept {
  if (ramp_active_ && !ramp_task_) {
    // The ramp is the actuator reference itself.
    d_ref_ = ramp_.p;
    ik_status_ = Status{};
    return;
  }
  ik_status_ = kin::inverse(machine_->kinematics(), ref_.p, cin_.kin, d_ref_);
}

void ControlLoop::control(std::int64_t k) noexcept {
  powered_ = drives_on();
  control_status_ = Status{};
  const bool actuator_law = !all_homed();
  if (powered_) {
    // The law changes (homing done, or a position lost): fade the difference.
    if (actuator_law != actuator_law_) transfer_pending_ = true;
    actuator_law_ = actuator_law;
    if (actuator_law) {
      control_actuators();
    } else {
      // With an actuation delay in the model the command acts from t + tau:
      // the controller aims at the reference then.
      const double ahead = controller_.lookahead();
      cin_.ref = ahead > 0.0 && !ramp_active_ ? reference_ahead(k, ahead) : ref_;
      control_status_ = controller_.step(cin_, ctl_state_, cout_);
    }
    fade_transfer(k);
    return;
  }
  actuator_law_ = actuator_law;
  transfer_pending_ = false;
  transfer_force_.setZero();
  transfer_now_.setZero();
  saturated_cycles_ = {};
  cout_.force.setZero();
  cout_.force_unlimited.setZero();
  cout_.saturated = {false, false, false};
  cout_.d_ref = d_ref_;
  cout_.d_dot_ref.setZero();
}

void ControlLoop::control_actuators() noexcept {
  // Each actuator on its own PD law toward the ramp, plus the force that
  // holds the platform's weight (at the estimate when it has one, else at
  // the middle of the workspace: the weight hardly changes with the pose).
  const ctl::Gains& g = cfg_.homing.actuator_gains;
  Vec3 hold = Vec3::Zero();
  const Vec3 at = estimate_ok_ ? est_.p : Vec3(0.5 * (cfg_.limits.workspace_min + cfg_.limits.workspace_max));
  if (!machine_->holding_command(at, cin_.kin, hold).ok()) hold.setZero();
  Vec3 f = g.kp.cwiseProduct(d_ref_ - cin_.d) + g.kd.cwiseProduct(ramp_.v - cin_.d_dot) + hold;
  if (mode_ == Mode::homing && homing_axis_ >= 0 && homing_request_.kind == AxisHoming::Request::Kind::drive)
    f[homing_axis_] = 0.0;  // the drive drives itself
  const double lim = machine_->force_limit();
  cout_.force_unlimited = f;
  for (int i = 0; i < 3; ++i) {
    cout_.saturated[static_cast<std::size_t>(i)] = std::abs(f[i]) > lim;
    cout_.force[i] = std::clamp(f[i], -lim, lim);
  }
  cout_.d_ref = d_ref_;
  cout_.d_dot_ref = ramp_.v;
  ctl_state_.sent.push(cin_.kin.t, cout_.force);
}

void ControlLoop::fade_transfer(std::int64_t k) noexcept {
  // Bumpless: the new law starts from the force the old one gave (the force
  // written last cycle); the difference fades out linearly.
  if (transfer_pending_) {
    transfer_pending_ = false;
    transfer_force_ = Vec3(out_.force[0], out_.force[1], out_.force[2]) - cout_.force_unlimited;
    transfer_start_ = k;
  }
  if (transfer_force_.isZero(0.0)) {
    transfer_now_.setZero();
    return;
  }
  const double T = cfg_.controller.transfer_time;
  const double w = std::max(0.0, 1.0 - static_cast<double>(k - transfer_start_) * dt_ / T);
  transfer_now_ = w * transfer_force_;
  if (w == 0.0) transfer_force_.setZero();
  const Vec3 f = cout_.force_unlimited + transfer_now_;
  const double lim = machine_->force_limit();
  for (int i = 0; i < 3; ++i) {
    cout_.saturated[static_cast<std::size_t>(i)] = std::abs(f[i]) > lim;
    cout_.force[i] = std::clamp(f[i], -lim, lim);
  }
  // What the drives are given is what the prediction across a delay uses.
  ctl_state_.sent.amend_last(cout_.force);
}

void ControlLoop::safety(std::int64_t k) noexcept {
  latch_input_faults(k);
  if (!powered_ || mode_ == Mode::fault) return;
  // The error is measured before any latch below ends the segment it
  // belongs to; in the actuator space, of the actuators (the platform's
  // position is not known).
  const double error = all_homed() ? (ref_.p - est_.p).norm() : (d_ref_ - cin_.d).norm();
  latch_motion_faults(k, error);
  latch_saturation(k);
  finish_enabling(k);
  if (playing_) {
    seg_sum_e2_ += error * error;
    seg_max_e_ = std::max(seg_max_e_, error);
    seg_n_++;
  }
}

void ControlLoop::latch_input_faults(std::int64_t k) noexcept {
  if (read_result_ != BackendResult::ok) latch(kFaultBackendIo, -1, static_cast<double>(read_result_), 0, k);
  for (int i = 0; i < 3; ++i)
    if (in_.drive_fault[i]) latch(kFaultDrive, i, in_.statusword[i], 0, k);
  if (in_.estop) latch(kFaultEstop, -1, 1, 0, k);
  for (int i = 0; i < 3; ++i)
    if (in_.limit_switch[i]) latch(kFaultLimitSwitch, i, 1, 0, k);
  if (overrun_fault_pending_) {
    latch(kFaultOverrun, -1, consecutive_overruns_, cfg_.loop.max_consecutive_overruns, k);
    overrun_fault_pending_ = false;
  }
  // Before homing an actuator's reading may be anything: no pose to estimate.
  if (read_result_ == BackendResult::ok && !estimate_status_.ok() && all_homed())
    latch(kFaultEstimate, estimate_status_.index, estimate_status_.value, estimate_status_.limit, k,
          cpm::fault_name(estimate_status_.fault));
}

void ControlLoop::latch_motion_faults(std::int64_t k, double error) noexcept {
  if (!ik_status_.ok())
    latch(kFaultController, ik_status_.index, ik_status_.value, ik_status_.limit, k, cpm::fault_name(ik_status_.fault));
  else if (!control_status_.ok())
    latch(kFaultController, control_status_.index, control_status_.value, control_status_.limit, k,
          cpm::fault_name(control_status_.fault));
  if (error > cfg_.limits.following_error) latch(kFaultFollowingError, -1, error, cfg_.limits.following_error, k);
  if (!all_homed()) {
    // The actuator space: the strokes of the homed actuators, the speed of all.
    const kin::Strokes& st = machine_->model().strokes;
    for (int i = 0; i < 3 && mode_ != Mode::fault; ++i) {
      if (!homed_[static_cast<std::size_t>(i)]) continue;
      if (cin_.d[i] < st.min[i]) latch(kFaultSoftLimit, i, cin_.d[i], st.min[i], k, "stroke_low");
      else if (cin_.d[i] > st.max[i]) latch(kFaultSoftLimit, i, cin_.d[i], st.max[i], k, "stroke_high");
    }
    const double speed = cin_.d_dot.norm();
    if (speed > cfg_.limits.overspeed) latch(kFaultOverspeed, -1, speed, cfg_.limits.overspeed, k);
    return;
  }
  int axis = -1;
  double v = 0, lim = 0;
  // The reference never passes the soft limits (validation, the jog's box);
  // the platform follows it within its tracking error, so it may pass one it
  // stops at by that much.
  const Vec3 slack = Vec3::Constant(kSoftLimitSlack);
  if (!inside(est_.p, cfg_.limits.workspace_min - slack, cfg_.limits.workspace_max + slack, axis, v, lim)) {
    // Reported against the limit as configured.
    lim = v < cfg_.limits.workspace_min[axis] ? cfg_.limits.workspace_min[axis] : cfg_.limits.workspace_max[axis];
    latch(kFaultSoftLimit, axis, v, lim, k);
  }
  // The machine's own workspace (strokes, limb reach, elbow singularity):
  // the reference one cycle ahead is checked first, so that a path running
  // towards a stroke end or a singularity stops before the platform (which
  // follows the reference within micrometres) gets there.
  if (mode_ != Mode::fault) {
    const Vec3 ahead = ref_.p + ref_.v * dt_;
    const Status wr = kin::check_pose(machine_->kinematics(), machine_->model().strokes, ahead, cin_.kin);
    const Status wm = wr.ok() ? kin::check_pose(machine_->kinematics(), machine_->model().strokes, est_.p, cin_.kin) : wr;
    if (!wm.ok()) latch(kFaultSoftLimit, wm.index, wm.value, wm.limit, k, cpm::fault_name(wm.fault));
  }
  if (est_.p_dot.norm() > cfg_.limits.overspeed) latch(kFaultOverspeed, -1, est_.p_dot.norm(), cfg_.limits.overspeed, k);
}

void ControlLoop::latch_saturation(std::int64_t k) noexcept {
  // Force saturation held too long: the axis cannot follow (blocked,
  // overloaded, a gain too high); the following error may not show it yet.
  for (int i = 0; i < 3 && mode_ != Mode::fault; ++i) {
    saturated_cycles_[i] = cout_.saturated[i] ? saturated_cycles_[i] + 1 : 0;
    const double held = static_cast<double>(saturated_cycles_[i]) * dt_;
    if (held > cfg_.limits.saturation_time + 1e-12) latch(kFaultSaturation, i, held, cfg_.limits.saturation_time, k);
  }
}

void ControlLoop::finish_enabling(std::int64_t k) noexcept {
  if (mode_ != Mode::enabling) return;
  if (in_.drive_enabled[0] && in_.drive_enabled[1] && in_.drive_enabled[2]) {
    enter(Mode::holding);
  } else if (static_cast<double>(k - enabling_since_) * dt_ > cfg_.limits.enable_timeout) {
    latch(kFaultEnableTimeout, -1, static_cast<double>(k - enabling_since_) * dt_, cfg_.limits.enable_timeout, k);
  }
}

void ControlLoop::write_outputs(std::int64_t k) noexcept {
  const bool on = drives_on();
  for (int i = 0; i < 3; ++i) out_.force[i] = on ? cout_.force[i] : 0.0;
  out_.enable = on;
  // The actuator a drive homes itself: its own homing mode, started.
  for (int i = 0; i < 3; ++i) {
    const bool drive_homes = on && mode_ == Mode::homing && homing_axis_ == i &&
                             homing_request_.kind == AxisHoming::Request::Kind::drive;
    out_.axis_drive[static_cast<std::size_t>(i)] = drive_homes ? AxisDrive::homing : AxisDrive::torque;
    out_.start_homing[static_cast<std::size_t>(i)] = drive_homes;
  }
  const BackendResult rw = backend_->write(k, out_);
  backend_write_ok_ = rw == BackendResult::ok;
  if (rw != BackendResult::ok) latch(kFaultBackendIo, -1, static_cast<double>(rw), 0, k);
}

void ControlLoop::publish(std::int64_t k) noexcept {
  fill_state(k);
  if (cfg_.lcm.state_decimation <= 1 || k % cfg_.lcm.state_decimation == 0) {
    if (!snapshots_.push(state_)) dropped_++;
  }
  const auto every = std::max<std::int64_t>(1, std::lround(cfg_.loop.rate_hz / 10.0));
  if (k % every == 0) publish_drives(k);
}

void ControlLoop::publish_drives(std::int64_t k) noexcept {
  backend_->diagnostics(diagnostics_);
  const BackendDiagnostics& d = diagnostics_;
  cpm_msgs::drives_t& m = drives_msg_;
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
    m.enabled[i] = in_.drive_enabled[i];
    m.fault[i] = in_.drive_fault[i];
    m.homed[i] = homed_[i];
    m.heartbeat_age_ms[i] =
        v.heartbeat_age_ns < 0 ? -1 : static_cast<std::int32_t>(std::min<std::int64_t>(v.heartbeat_age_ns / 1000000, INT32_MAX));
    m.master_faults[i] = static_cast<std::int32_t>(v.master_faults);
    m.emcy_count[i] = static_cast<std::int32_t>(std::min<std::uint32_t>(v.emcy_count, INT32_MAX));
    m.last_emcy_code[i] = v.last_emcy_code;
    m.last_emcy_register[i] = v.last_emcy_register;
    m.position[i] = cin_.d[static_cast<Eigen::Index>(i)];
    m.force[i] = out_.force[i];
    m.limit_low[i] = d.limit_low[i];
    m.limit_high[i] = d.limit_high[i];
    m.home_switch[i] = in_.home_switch[i];
  }
  m.bus_state = d.bus_state;
  m.error_frames = static_cast<std::int64_t>(d.error_frames);
  m.tx_error_counter = d.tx_error_counter;
  m.rx_error_counter = d.rx_error_counter;
  m.rx_dropped = static_cast<std::int64_t>(d.rx_dropped);
  m.tx_failures = static_cast<std::int64_t>(d.tx_failures);
  m.bus_load = d.bus_load;
  m.estop = in_.estop;
  (void)drives_out_.push(m);  // a full ring drops this view; the next comes in 0.1 s
}

void ControlLoop::finish_cycle(std::int64_t k, const PhaseTimes& t) noexcept {
  for (int s = kSeriesRead; s <= kSeriesPublish; ++s) add_sample(s, t[s] - t[s - 1]);
  add_sample(kSeriesCycle, t[kSeriesPublish] - t[0]);
  stats_.cycles++;
  // Statistics once a second (copied whole; the ring holds a few).
  const auto per_second = static_cast<std::int64_t>(std::lround(cfg_.loop.rate_hz));
  if (per_second > 0 && (k + 1) % per_second == 0) (void)stats_out_.push(stats_);
  cycles_done_.store(stats_.cycles, std::memory_order_release);
}

void ControlLoop::fill_state(std::int64_t k) noexcept {
  state_t& s = state_;
  s.utime = 0;  // stamped by the publisher with the wall clock
  s.cycle = k;
  s.t = static_cast<double>(k) * dt_;
  s.mode = static_cast<std::int8_t>(mode_);
  s.controller = static_cast<std::int8_t>(controller_.law());
  put(s.position, est_.p);
  put(s.velocity, est_.p_dot);
  put(s.position_ref, ref_.p);
  put(s.velocity_ref, ref_.v);
  put(s.acceleration_ref, ref_.a);
  const Vec3 e = ref_.p - est_.p;
  put(s.position_error, e);
  s.position_error_norm = e.norm();
  put(s.d, cin_.d);
  put(s.d_dot, cin_.d_dot);
  put(s.d_ref, d_ref_);
  put(s.d_dot_ref, cout_.d_dot_ref);
  for (int i = 0; i < 3; ++i) {
    s.force[i] = out_.force[i];
    s.saturated[i] = out_.enable && cout_.saturated[i];
  }
  s.faults = static_cast<std::int32_t>(faults_);
  s.first_fault = static_cast<std::int32_t>(first_fault_);
  s.fault_axis = static_cast<std::int8_t>(fault_axis_);
  s.fault_value = fault_value_;
  s.fault_limit = fault_limit_;
  s.fault_cycle = fault_cycle_;
  static_assert(sizeof s.fault_text == sizeof fault_text_);
  std::memcpy(s.fault_text, fault_text_, sizeof fault_text_);
  if (playing_) {
    const Segment& seg = (*queue_)[q_head_];
    s.segment_id = seg.id;
    s.segment_elapsed = static_cast<double>(k - segment_start_cycle_) * dt_;
    s.segment_duration = seg.get()->duration();
    s.program_line = std::holds_alternative<const path::Plan*>(seg.traj) ? program_line_ : 0;
  } else {
    s.program_line = 0;
    s.segment_id = -1;
    s.segment_elapsed = 0;
    s.segment_duration = 0;
  }
  s.queue_depth = static_cast<std::int16_t>(playing_ ? q_count_ - 1 : q_count_);
  put(s.queue_end, queue_end_);
  put(s.queue_end_velocity, queue_end_v_);
  put(s.queue_end_acceleration, queue_end_a_);
  for (std::size_t i = 0; i < 3; ++i) s.homed[i] = homed_[i];
  s.homing_axis = static_cast<std::int8_t>(homing_axis_);
  s.homing_phase = static_cast<std::int8_t>(homing_axis_ >= 0 ? axis_homing_.phase() : HomingPhase::idle);
  s.control_space = all_homed() ? state_t::SPACE_TASK : state_t::SPACE_ACTUATOR;
  s.jog_frame = jog_frame_;
  put(s.jog_velocity, mode_ == Mode::jogging ? jog_target_ : Vec3::Zero());
  s.jog_keepalive_left = mode_ == Mode::jogging ? std::max<double>(0.0, static_cast<double>(jog_deadline_ - k) * dt_) : 0.0;
  put(s.transfer_force, transfer_now_);
  s.last_segment_id = last_seg_id_;
  s.last_segment_rmse = last_seg_rmse_;
  s.last_segment_max = last_seg_max_;
  s.last_segment_cycles = last_seg_n_;
  s.cycles = stats_.cycles + 1;
  s.overruns = stats_.overruns;
  s.skipped = stats_.skipped;
  s.max_latency_ns = stats_.max_ns[kSeriesLatency];
  s.max_cycle_ns = stats_.max_ns[kSeriesCycle];
  s.dropped_snapshots = dropped_;
}

}  // namespace cpm::daemon
