// SPDX-License-Identifier: Apache-2.0
// The control loop of cpmd: the state machine and one control cycle.
//
// cycle() is the real-time part, shaped like LinuxCNC's emcmotController
// (src/emc/motion/control.c): a short list of calls, one function per phase,
// over preallocated data (docs/daemon.md); every phase is allocation-free,
// lock-free, noexcept, and makes no system call but the backend's I/O (and
// clock_gettime, a vDSO read, for the phase timers). Each phase is described
// here once; its statistics series (loop_stats_t, --stats-json) in brackets.
//   read_inputs        the backend's feedback: actuator positions and
//                      velocities (plus the zero homing found), drive status
//                      words, e-stop, limit and home switches ["read"]
//   estimate           calibrated forward kinematics: p, p_dot, J ["estimate"]
//   apply_commands     a shutdown request, then at most kCommandsPerCycle
//                      commands from the command queue (timed with estimate)
//   homing             the actuator being homed: one step of its sequence
//                      (homing.hpp), which asks the reference for a speed or a
//                      place, or hands the axis to the drive's own homing
//   jog                the deadman: a jog command holds for jog.keepalive;
//                      then the jog's target speed drops to zero
//   trajectory         the reference at the cycle's nominal time k / rate:
//                      from the ramp (ramp.hpp: actuator space before homing,
//                      homing moves, jogs, their stops), or the playing
//                      segment, the stop profile or the hold point
//                      ["trajectory"; homing and jog are timed with it]
//   inverse_kinematics d_ref = IK(p_ref) of the calibrated model; in actuator
//                      space (and for an actuator jog) the ramp is d_ref
//                      ["inverse_kinematics"]
//   control            the selected law (task space) or each actuator's PD
//                      law on its own (actuator space), the force limit, and
//                      a switch's force difference faded out; with an
//                      actuation delay, aimed at the reference at t + tau
//                      ["controller"]
//   safety             conditions become latched faults: backend, drives,
//                      e-stop, limit switches, overruns, estimate
//                      (latch_input_faults); controller, following error,
//                      soft limits, workspace, overspeed
//                      (latch_motion_faults); force saturation held too long
//                      (latch_saturation); enabling ends or times out
//                      (finish_enabling); the segment's tracking error
//                      ["safety"]
//   write_outputs      forces, enable and each drive's mode to the backend
//                      ["write"]
//   publish            state snapshot into the SPSC ring for the LCM thread,
//                      the drives' view ten times a second ["publish"]
// then finish_cycle records the phase times ("cycle": all of them) and hands
// the statistics on once a second.
// The schedule (clock_nanosleep on an absolute time) lives in rt.hpp; tests
// call cycle() directly, deterministic and without threads.
// The state the phases share lives in small owners with their own
// transitions (loop_state.hpp: the mode, the model and law in use, the
// fault latch, the stop profile, the segment queue, homing, jog, transfer,
// ...); the commands' legality and
// transitions in loop_commands.cpp, the phases in loop.cpp.
//
// Spaces (as LinuxCNC's joint and teleop modes): until every actuator is
// homed the platform's position is unknown, so each actuator is held and
// moved on its own (the actuator space: a PD law per actuator, references
// from the ramp, no soft limits but the homed actuators' strokes); once all
// are homed the calibrated kinematics and the selected law take over (the
// task space), with the force difference faded out.
//
// States and commands (docs/daemon.md has the full table):
//   init -> disabled            when the loop starts
//   disabled --enable--> enabling --drives enabled--> holding
//   holding --segment--> moving --queue empty--> holding      (every actuator homed)
//   holding --home--> homing --all asked homed--> holding
//   holding --jog--> jogging --deadman or zero speed, at rest--> holding
//   moving/homing/jogging --stop--> stopping --at rest--> holding
//   moving/homing/jogging/stopping --disable--> stopping --at rest--> disabled
//   enabling/holding --disable--> disabled
//   any --fault--> fault (latched, drives off) --reset--> disabled
// On every entry to enabling and on reset the hold point is resynchronised
// to the measured position, so nothing jumps.
#pragma once

#include <array>
#include <atomic>
#include <cstdint>
#include <optional>
#include <variant>

#include <cpm_msgs/drives_t.hpp>
#include <cpm_msgs/loop_stats_t.hpp>
#include <cpm_msgs/state_t.hpp>

#include "cpm/daemon/backend.hpp"
#include "cpm/daemon/config.hpp"
#include "cpm/daemon/homing.hpp"
#include "cpm/daemon/loop_state.hpp"
#include "cpm/daemon/modes.hpp"
#include "cpm/daemon/ramp.hpp"
#include "cpm/daemon/spsc.hpp"
#include "cpm/daemon/stream_trajectory.hpp"

namespace cpm::daemon {

// How a segment's start meets the motion it follows: the step in velocity
// from the queue's end (m/s), which must be within what the acceleration
// limit builds in one period (limits.acceleration * dt), and the
// acceleration the start asks for (m/s^2), within limits.acceleration. (The
// position is checked on its own: the start is the queue's end.) The server
// (with the queue's end it expects) and the loop (with the one it has) both
// check it.
struct StartCheck {
  double velocity_step = 0.0, velocity_allowed = 0.0;
  double acceleration = 0.0, acceleration_allowed = 0.0;
  [[nodiscard]] bool ok() const noexcept {
    return velocity_step <= velocity_allowed && acceleration <= acceleration_allowed;
  }
};
StartCheck check_start(const ctl::Trajectory& tr, const Vec3& end_velocity, const LimitsConfig& limits,
                       double dt) noexcept;

// Command codes (= control_command_t.CMD_* and ack_t sources).
enum class CommandKind : std::uint8_t {
  none = 0, enable = 1, disable = 2, stop = 3, reset = 4, select_controller = 5, load_model = 6,
  ping = 7, home = 10, jog = 11, set_params = 12, segment = 16,
};

// What CMD_SET_PARAM changes in the loop: the limits and the jog, whole (the
// server checked the new values and their ranges).
struct Settings {
  LimitsConfig limits;
  JogConfig jog;
  double transfer_time = 0.5;
};

// Command::jog_frame of a jog in the machine frame (= control_command_t.JOG_MACHINE);
// 0 jogs the actuators.
inline constexpr std::int8_t kJogMachineFrame = 1;

// A command the non-real-time side has decoded and validated, for the loop.
struct Command {
  CommandKind kind = CommandKind::none;
  std::int64_t id = 0;
  std::int8_t source = 1;        // ack_t.source
  std::int8_t code = 0;          // the original CMD_* or KIND_*
  std::optional<ctl::Controller> controller;  // select_controller, load_model
  const ctl::Machine* machine = nullptr;      // load_model
  Segment segment;                            // segment
  std::uint8_t home_axes = 0;                 // home: bit i = actuator i + 1; 0 = all, in order
  std::int8_t jog_frame = 0;                  // jog: control_command_t.JOG_* (kJogMachineFrame)
  Vec3 jog_velocity = Vec3::Zero();           // jog: m/s
  Settings settings;                          // set_params
  bool while_moving = false;                  // set_params: the parameter may change while moving
  const char* param = "";                     // set_params: its name (static storage), for the refusal
};

// The loop's answer to a command. `message` is a string literal.
struct Ack {
  std::int64_t id = 0;
  std::int8_t source = 1, code = 0;
  bool accepted = false;
  Refusal refusal = Refusal::none;  // why not (the server maps it to ack_t.REASON_*)
  const char* message = "";
  Mode mode = Mode::init;
  std::int16_t queue_depth = 0;
  const ctl::Machine* retired = nullptr;  // a model the loop no longer uses (load_model)
  Vec3 queue_end = Vec3::Zero();           // where the next segment must start
  Vec3 queue_end_velocity = Vec3::Zero();  // and how fast (m/s)
  Vec3 queue_end_acceleration = Vec3::Zero();
  // The cycle that answered: the state of this cycle and later already holds
  // the command's effect on the queue (commands come before the state's publish).
  std::int64_t cycle = 0;
};


class ControlLoop {
 public:
  static constexpr int kQueueCapacity = SegmentQueue::kCapacity;  // trajectory segments
  // A stream chunk ending slower than this (m/s) ends the stream; faster,
  // it owes a next chunk (stream_underrun when none has come).
  static constexpr double kStreamRestSpeed = 1e-6;
  // Commands taken from the command queue per cycle, at most: a flood of
  // commands cannot lengthen a cycle (the rest wait in the queue, and the
  // server answers REASON_BUSY when it is full).
  static constexpr int kCommandsPerCycle = 4;
  // How far the measured platform may pass a soft limit its reference stops
  // at (m): its tracking error when it brakes there (32 um measured for a
  // 50 mm/s jog braking at 0.5 m/s^2 on the simulator; the following error
  // bounds the rest).
  static constexpr double kSoftLimitSlack = 50e-6;

  // Keeps references to `backend` and `machine`; the controller refers to
  // `machine`. Throws Error when the model's actuation delay needs more
  // commands than the controller's history keeps at the loop rate.
  ControlLoop(const DaemonConfig& config, Backend& backend, const ctl::Machine& machine,
              const ctl::Controller& controller);

  // --- real-time side -------------------------------------------------
  // One control cycle at nominal time cycle / rate. `latency_ns` is how late
  // the thread woke (recorded in the statistics).
  void cycle(std::int64_t cycle, std::int64_t latency_ns) noexcept;
  // The scheduler's verdict on the cycle just run: whether it overran (ended
  // after the next slot began) and how many slots it skipped.
  void record_schedule(bool overrun, std::int64_t skipped) noexcept;
  // Shut down: disable the drives on the next cycle (from any thread).
  void request_shutdown() noexcept { requests_.shutdown(); }
  // A stop heard on the bus (any thread, lock-free): the next cycle brakes
  // a motion (moving, homing, jogging) before it takes any command. The
  // stop's ack comes through the command queue as before; this is the path
  // no other command's work can delay (docs/security.md).
  void request_stop() noexcept { requests_.stop(); }

  // --- queues to and from the other threads ----------------------------
  SpscRing<Command, 16>& commands() noexcept { return ch_.commands; }
  SpscRing<Ack, 64>& acks() noexcept { return ch_.acks; }
  SpscRing<cpm_msgs::state_t, 4096>& snapshots() noexcept { return ch_.snapshots; }
  SpscRing<cpm_msgs::loop_stats_t, 4>& stats() noexcept { return ch_.stats; }
  SpscRing<cpm_msgs::drives_t, 8>& drives() noexcept { return ch_.drives; }
  // Plans the loop no longer holds (played, flushed by a stop or a fault),
  // for the server to free. Larger than the queue: it never fills.
  RetiredPlans& retired_plans() noexcept { return ch_.retired_plans; }
  // Cycles completed (the watchdog is fed only while this advances).
  [[nodiscard]] std::int64_t cycles_done() const noexcept { return stats_.cycles_done(); }
  // Latest mode (any thread).
  [[nodiscard]] Mode mode() const noexcept { return mode_.published(); }
  void set_scheduling_info(bool realtime, bool memory_locked) noexcept { stats_.scheduling(realtime, memory_locked); }

  // Last state as the loop wrote it (test thread only, when no loop thread runs).
  [[nodiscard]] const cpm_msgs::state_t& last_state() const noexcept { return pub_.state; }
  [[nodiscard]] const cpm_msgs::loop_stats_t& current_stats() const noexcept { return stats_.sums(); }
  [[nodiscard]] const FineLatencyHistogram& fine_latency_histogram() const noexcept { return stats_.fine_latency(); }
  [[nodiscard]] double period() const noexcept { return dt_; }

 private:
  // The phases of cycle(), in order (the list at the top of this file).
  void read_inputs(std::int64_t k) noexcept;
  void estimate(std::int64_t k) noexcept;
  void apply_commands(std::int64_t k) noexcept;
  void homing(std::int64_t k) noexcept;
  void jog(std::int64_t k) noexcept;
  void trajectory(std::int64_t k) noexcept;
  void inverse_kinematics() noexcept;
  void control(std::int64_t k) noexcept;
  void control_actuators() noexcept;
  void fade_transfer(std::int64_t k) noexcept;
  void safety(std::int64_t k) noexcept;
  void latch_input_faults(std::int64_t k) noexcept;
  void latch_motion_faults(std::int64_t k, double error) noexcept;
  void latch_saturation(std::int64_t k) noexcept;
  void finish_enabling(std::int64_t k) noexcept;
  void write_outputs(std::int64_t k) noexcept;
  void publish(std::int64_t k) noexcept;
  void finish_cycle(std::int64_t k, const PhaseTimes& t) noexcept;
  // The clamped force and its saturation flags of `f` (N) into this cycle's output.
  void limit_force(const Vec3& f) noexcept;

  // Commands (loop_commands.cpp): handle() dispatches, one function each.
  void handle_commands(std::int64_t k) noexcept;
  void handle(const Command& c, std::int64_t k) noexcept;
  void handle_enable(const Command& c, std::int64_t k) noexcept;
  void handle_disable(const Command& c, std::int64_t k) noexcept;
  void handle_stop(const Command& c, std::int64_t k) noexcept;
  void handle_reset(const Command& c) noexcept;
  void handle_select(const Command& c) noexcept;
  void handle_load(const Command& c) noexcept;
  void handle_home(const Command& c, std::int64_t k) noexcept;
  void handle_jog(const Command& c, std::int64_t k) noexcept;
  void handle_segment(const Command& c, std::int64_t k) noexcept;
  void handle_settings(const Command& c) noexcept;
  // The answer; `retired`: a model the loop no longer uses (load_model).
  void reply(const Command& c, Refusal refusal, const char* msg, const ctl::Machine* retired = nullptr) noexcept;
  void accept(const Command& c, const char* msg, const ctl::Machine* retired = nullptr) noexcept {
    reply(c, Refusal::none, msg, retired);
  }
  void refuse(const Command& c, Refusal why, const char* msg, const ctl::Machine* retired = nullptr) noexcept {
    reply(c, why, msg, retired);
  }
  // Resynchronise on enable and reset: hold where the platform is measured.
  void hold_where_measured() noexcept;
  void begin_axis_homing(std::int64_t k) noexcept;
  // The ramp drives the reference in actuator coordinates from where the
  // reference is now (entering the actuator space, or an actuator jog).
  void ramp_in_actuators() noexcept;
  // A ramp motion in the task space ended at rest: hold there.
  void leave_ramp() noexcept;
  // The box the ramp stays in: the soft limits (machine frame), the box of
  // the actuator jog taken last (once homed), the strokes of homed
  // actuators, nothing for the others.
  void ramp_box(Vec3& lo, Vec3& hi) const noexcept;
  // The box (actuator coordinates, m) of an actuator jog at `v_target` once
  // homed: the strokes, and the workspace (limits.workspace_min/max,
  // machine frame) through the calibrated kinematics, around where the
  // reference is now. Returns a bit per end (2i: toward -d_i, 2i+1: +d_i)
  // that the workspace, not the stroke, bounds. Bounded work: 6 inverse and
  // 7 forward kinematics, no allocation; at a jog command, not each cycle.
  unsigned actuator_jog_box(const Vec3& v_target, Vec3& lo, Vec3& hi) const noexcept;
  // The task-space reference of an actuator reference (calibrated forward
  // kinematics), for an actuator jog once homed and for the display before.
  void reference_of_actuators(const Vec3& d, const Vec3& d_dot, const Vec3& d_dd) noexcept;
  void publish_drives(std::int64_t k) noexcept;

  // `cause`: a string literal for fault_text when the backend has no words
  // for the fault (the kinematic fault's name).
  void latch(std::uint32_t bit, int axis, double value, double limit, std::int64_t k,
             const char* cause = "") noexcept;
  void enter(Mode m) noexcept;
  void flush_queue() noexcept;
  void start_stop(std::int64_t k) noexcept;
  void start_underrun_stop(const Segment& s, std::int64_t k, double late) noexcept;
  bool start_next_segment(std::int64_t k) noexcept;
  void finish_segment() noexcept;
  ctl::TrajectorySample reference(std::int64_t k) noexcept;
  ctl::TrajectorySample reference_ahead(std::int64_t k, double ahead) const noexcept;
  void fill_state(std::int64_t k) noexcept;

  DaemonConfig cfg_;
  Backend* backend_;
  double dt_;
  ActiveModel model_;  // the model and law in use (swapped whole by load_model, select_controller)

  // Queues to and from the other threads.
  struct Channels {
    SpscRing<Command, 16> commands;
    SpscRing<Ack, 64> acks;
    SpscRing<cpm_msgs::state_t, 4096> snapshots;
    SpscRing<cpm_msgs::loop_stats_t, 4> stats;
    SpscRing<cpm_msgs::drives_t, 8> drives;
    RetiredPlans retired_plans;
  } ch_;
  LoopRequests requests_;

  // State machine (the owners' transitions: loop_state.hpp).
  ModeState mode_;
  FaultLatch fault_;
  OverrunCount overruns_;
  std::int64_t commands_cycle_ = 0;  // the cycle whose commands are being answered (Ack::cycle)
  std::array<std::int64_t, 3> saturated_cycles_{};  // consecutive cycles at the force limit
  Underrun underrun_;

  // The reference's sources.
  SegmentQueue queue_{ch_.retired_plans};
  SegmentTracking tracking_;
  std::int32_t program_line_ = 0;  // of the playing plan (state_t.program_line)
  Vec3 hold_ = Vec3::Zero();       // hold point = end of the queue when idle
  StopProfile stop_;
  HomingSequence homing_;
  // The ramp (ramp.hpp): the reference in actuator space, and of any jog.
  struct RampReference : Ramp {
    bool active = false;  // the reference comes from the ramp
    bool task = false;    // its coordinates: machine frame (true) or actuators
  } ramp_;
  Jog jog_;
  Transfer transfer_;

  // What one phase hands the later ones within a cycle.
  struct CycleData {
    BackendInput in;
    BackendOutput out;
    ctl::ControlInput cin;
    ctl::ControlOutput cout;
    ctl::TaskState est;
    ctl::TrajectorySample ref;
    Vec3 d_ref = Vec3::Zero();
    Vec3 raw = Vec3::Zero();  // the backend's actuator positions, before the homing offset (m)
    bool estimate_ok = false;
    BackendResult read_result = BackendResult::ok;
    bool backend_ok = true, backend_write_ok = true;  // last read / write: reset waits for both
    Status estimate_status, ik_status, control_status;
    bool powered = false;  // the drives were on when the controller ran
  } io_;
  // What goes out: the state snapshot, the drives' view (every rate/10 cycles).
  struct Publication {
    cpm_msgs::state_t state{};
    BackendDiagnostics diagnostics{};
    cpm_msgs::drives_t drives{};
    std::int64_t dropped = 0;  // snapshots the full ring lost
  } pub_;
  CycleStatistics stats_;
};

}  // namespace cpm::daemon
