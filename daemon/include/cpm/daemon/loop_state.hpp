// SPDX-License-Identifier: Apache-2.0
// The control loop's state in small owners, each with its own transitions
// (as LinuxCNC keeps homing.c and command.c apart from control.c): the mode,
// the model and law in use, the fault latch, the stop profile, the segment
// queue and its tracking, the homing sequence, the jog, the bumpless
// transfer, the overrun count, the stream underrun, the stop and shutdown
// requests. ControlLoop (loop.hpp) holds one
// of each and decides when each transition happens; each is tested on its
// own (tests/daemon/test_loop_state.cpp). All real-time: no allocation after
// construction, no lock, noexcept.
#pragma once

#include <array>
#include <atomic>
#include <cstdint>
#include <memory>
#include <variant>

#include <cpm_msgs/loop_stats_t.hpp>

#include "cpm/control/controller.hpp"
#include "cpm/control/trajectory.hpp"
#include "cpm/daemon/config.hpp"
#include "cpm/daemon/homing.hpp"
#include "cpm/daemon/modes.hpp"
#include "cpm/daemon/spsc.hpp"
#include "cpm/daemon/stream_trajectory.hpp"

namespace cpm::path {
class Plan;
}  // namespace cpm::path

namespace cpm::daemon {

// Why the loop refused a command: the loop's own words, which the server
// maps to ack_t.REASON_* (server.cpp, ack_reason); the loop knows nothing of
// its transport.
enum class Refusal : std::uint8_t {
  none = 0,
  illegal_in_mode,   // not in this mode
  fault_active,      // a fault is latched, or its cause is still there
  not_homed,         // the platform's position is not known
  queue_full,        // the trajectory queue holds kQueueCapacity segments
  not_continuous,    // the segment does not start where and how the queue ends
  limit,             // faster than a limit allows
  workspace,         // it would leave the workspace or a stroke
};

// Timing statistics: histograms as in loop_stats_t.
inline constexpr int kSeriesLatency = 0, kSeriesRead = 1, kSeriesEstimate = 2, kSeriesTrajectory = 3,
                     kSeriesInverseKinematics = 4, kSeriesController = 5, kSeriesSafety = 6, kSeriesWrite = 7,
                     kSeriesPublish = 8, kSeriesCycle = 9, kSeries = 10, kBins = 237;
int histogram_bin(std::int64_t ns) noexcept;
// Lower edge of bin k (ns).
std::int64_t histogram_bin_floor(int k) noexcept;
// The wake-up latency at cyclictest's resolution (cyclictest -h 2000): bin k
// < 2000 holds [k, k+1) us, the last bin everything from 2 ms. loop_stats_t's
// 50 us bins above 200 us are too coarse to hold a p99 against cyclictest's
// to within 20 %, so cpmd --stats-json writes this one for that series.
inline constexpr int kFineLatencyBins = 2001;
using FineLatencyHistogram = std::array<std::int32_t, kFineLatencyBins>;

// The clock reading at the start of a cycle, then at the end of each phase
// (index: the phase's series, kSeriesRead to kSeriesPublish).
using PhaseTimes = std::array<std::int64_t, kSeriesPublish + 1>;

// The cycle's timing statistics (loop_stats_t): per series the count, sum,
// extremes and histogram; the wake-up latency also in 1 us bins; the
// schedule's overruns and skipped slots; and the cycles completed, which
// any thread may read (the watchdog is fed only while they advance).
class CycleStatistics {
 public:
  explicit CycleStatistics(double rate_hz) noexcept;
  // How late the thread woke for this cycle (ns).
  void latency(std::int64_t ns) noexcept;
  // The scheduler's verdict on the cycle just run.
  void schedule(bool overrun, std::int64_t skipped) noexcept;
  void scheduling(bool realtime, bool memory_locked) noexcept;
  // A cycle ran with these phase times: each phase and the whole.
  void cycle(const PhaseTimes& t) noexcept;
  // ... and everything it hands on is handed on: cycles_done() advances.
  void completed() noexcept { cycles_done_.store(sums_.cycles, std::memory_order_release); }
  [[nodiscard]] const cpm_msgs::loop_stats_t& sums() const noexcept { return sums_; }
  [[nodiscard]] const FineLatencyHistogram& fine_latency() const noexcept { return latency_us_; }
  [[nodiscard]] std::int64_t cycles_done() const noexcept { return cycles_done_.load(std::memory_order_acquire); }

 private:
  void add(int series, std::int64_t ns) noexcept;
  cpm_msgs::loop_stats_t sums_{};
  FineLatencyHistogram latency_us_{};  // series 0 again, in 1 us bins
  std::atomic<std::int64_t> cycles_done_{0};
};

// The state machine's mode: the loop's own copy, the one other threads read,
// and what two transitions remember: the cycle enabling began (the enable
// timeout counts from it) and whether the stop under way ends disabled.
class ModeState {
 public:
  [[nodiscard]] Mode now() const noexcept { return now_; }
  // Any thread.
  [[nodiscard]] Mode published() const noexcept { return published_.load(std::memory_order_acquire); }
  // Leaving stopping spends a disable asked for during the stop (a fault or
  // a shutdown ends the stop as well).
  void enter(Mode m) noexcept {
    if (m != Mode::stopping) disable_after_stop_ = false;
    now_ = m;
    published_.store(m, std::memory_order_release);
  }
  // Enabling began at cycle k.
  void enabling_from(std::int64_t k) noexcept { enabling_since_ = k; }
  // How long enabling has waited for the drives at cycle k (s).
  [[nodiscard]] double enabling_time(std::int64_t k, double dt) const noexcept {
    return static_cast<double>(k - enabling_since_) * dt;
  }
  // A disable while stopping (or a motion about to stop): the stop ends disabled.
  void disable_after_stop() noexcept { disable_after_stop_ = true; }
  // The mode a stop at rest enters: disabled when a disable asked for it, else holding.
  [[nodiscard]] Mode after_stop() const noexcept { return disable_after_stop_ ? Mode::disabled : Mode::holding; }
  // The drives are (to be) powered: enabling, holding, moving, homing,
  // jogging or stopping.
  [[nodiscard]] bool drives_on() const noexcept {
    return now_ == Mode::enabling || now_ == Mode::holding || now_ == Mode::moving || now_ == Mode::stopping ||
           now_ == Mode::homing || now_ == Mode::jogging;
  }

 private:
  Mode now_ = Mode::init;
  std::atomic<Mode> published_{Mode::init};
  std::int64_t enabling_since_ = 0;
  bool disable_after_stop_ = false;
};

// The model and the law the loop runs, and the forces the drives were given
// since they were enabled (the law's prediction across the actuation delay
// reads them). The server builds a new model or law off the real-time
// thread; the loop swaps it in whole, so a law never refers to a model the
// loop no longer holds.
class ActiveModel {
 public:
  ActiveModel(const ctl::Machine& machine, const ctl::Controller& controller) noexcept
      : machine_(&machine), controller_(controller) {}
  [[nodiscard]] const ctl::Machine& machine() const noexcept { return *machine_; }
  [[nodiscard]] const ctl::Controller& controller() const noexcept { return controller_; }
  // The law's step at `in`; its force is kept as given.
  Status step(const ctl::ControlInput& in, ctl::ControlOutput& out) noexcept { return controller_.step(in, state_, out); }
  // The forces given, for what another law gave (the actuator space's PD
  // law, a fade): the prediction must see what the drives were given.
  [[nodiscard]] ctl::CommandHistory& sent() noexcept { return state_.sent; }
  [[nodiscard]] const ctl::CommandHistory& sent() const noexcept { return state_.sent; }
  // The drives are enabled: while off they were given nothing.
  void restart() noexcept { state_.reset(); }
  // Another law on the same model.
  void select(const ctl::Controller& c) noexcept { controller_ = c; }
  // Another model and its law; returns the model no longer used (for the
  // server to free).
  [[nodiscard]] const ctl::Machine* load(const ctl::Machine& machine, const ctl::Controller& c) noexcept {
    const ctl::Machine* old = machine_;
    machine_ = &machine;
    controller_ = c;
    return old;
  }

 private:
  const ctl::Machine* machine_;
  ctl::Controller controller_;
  ctl::ControllerState state_;
};

// A queued trajectory segment: one of the trajectory kinds, by value, or a
// planned program (path_command_t) by pointer: the server owns the plan and
// frees it only after the loop hands it back (retired_plans()).
struct Segment {
  std::int64_t id = -1;
  std::variant<std::monostate, ctl::CircleTrajectory, ctl::PointToPoint, StreamTrajectory, const path::Plan*> traj;
  Vec3 start = Vec3::Zero(), end = Vec3::Zero();
  // Accept a start whose velocity or acceleration steps from the queue's end
  // (granted by the server: the simulator, or limits.allow_velocity_step).
  bool allow_step = false;
  [[nodiscard]] const ctl::Trajectory* get() const noexcept;
};

// The velocity and acceleration a queued segment ends with: a stream chunk
// the velocity it was given (the stream goes on), every other kind at rest.
void segment_end_motion(const Segment& s, Vec3& velocity, Vec3& acceleration) noexcept;

// The latched fault: every bit since the last reset, and the particulars of
// the first (which axis, the value against its limit, the cycle, words).
class FaultLatch {
 public:
  // Latch `bit`; the first fault since clear() keeps its particulars.
  // `text` (copied, truncated to 95 characters) is read only for the first.
  void set(std::uint32_t bit, int axis, double value, double limit, std::int64_t cycle, const char* text) noexcept;
  void clear() noexcept { *this = FaultLatch{}; }
  [[nodiscard]] bool active() const noexcept { return bits_ != 0; }
  [[nodiscard]] std::uint32_t bits() const noexcept { return bits_; }
  [[nodiscard]] std::uint32_t first() const noexcept { return first_; }
  [[nodiscard]] int axis() const noexcept { return axis_; }
  [[nodiscard]] double value() const noexcept { return value_; }
  [[nodiscard]] double limit() const noexcept { return limit_; }
  [[nodiscard]] std::int64_t cycle() const noexcept { return cycle_; }
  [[nodiscard]] const char* text() const noexcept { return text_; }
  static constexpr std::size_t kTextBytes = 96;  // = state_t.fault_text

 private:
  std::uint32_t bits_ = 0, first_ = 0;
  int axis_ = -1;
  double value_ = 0.0, limit_ = 0.0;
  std::int64_t cycle_ = -1;
  char text_[kTextBytes] = {};
};

// A stop along a line: from p0 at speed v0 the reference decelerates at a
// constant rate to rest, p(t) = p0 + u (v0 t - a t^2 / 2) for t <= T = v0 / a.
class StopProfile {
 public:
  // Brake from `p0` moving at `v0` (m/s) at `deceleration` (m/s^2), from
  // cycle k, with `elapsed` s of the profile already behind at k.
  void start(const Vec3& p0, const Vec3& v0, double deceleration, std::int64_t k, double elapsed) noexcept;
  // The profile at cycle k plus `ahead` s (period dt); `at_rest` when the
  // time is past T (the sample's velocity is then zero in size, not yet set
  // to exactly zero: the caller decides what rest means).
  [[nodiscard]] ctl::TrajectorySample sample(std::int64_t k, double dt, double ahead, bool& at_rest) const noexcept;
  [[nodiscard]] double duration() const noexcept { return duration_; }

 private:
  Vec3 p0_ = Vec3::Zero(), dir_ = Vec3::Zero();
  double v0_ = 0.0, duration_ = 0.0, a_ = 0.0;
  double t0_ = 0.0;  // s of the profile already elapsed at start_cycle_
  std::int64_t start_cycle_ = 0;
};

// Plans the loop no longer holds, for the server to free (twice the queue:
// a push cannot fail while the server drains it).
inline constexpr int kSegmentQueueCapacity = 32;
using RetiredPlans = SpscRing<const path::Plan*, 2 * kSegmentQueueCapacity>;

// The trajectory queue: a ring of segments, the front one playing (or next),
// and the motion the queue ends with (where and how the next segment must
// start). Its plans go to `retired` when dropped.
class SegmentQueue {
 public:
  static constexpr int kCapacity = kSegmentQueueCapacity;
  explicit SegmentQueue(RetiredPlans& retired);  // allocates the ring (before the loop runs)

  // Append `s` with `id`; the queue's end becomes its end. (The caller
  // checked count() < kCapacity.)
  void push(const Segment& s, std::int64_t id) noexcept;
  // The front segment starts playing at cycle k; false when empty.
  bool start(std::int64_t k) noexcept;
  // The playing segment is done: dropped, its plan retired.
  void pop() noexcept;
  // Everything dropped; the queue ends at rest (at end()).
  void flush() noexcept;
  // The queue (empty) ends at `p`: the hold point moved.
  void end_at(const Vec3& p) noexcept { end_ = p; }
  // ... and at rest there.
  void end_at_rest(const Vec3& p) noexcept;

  [[nodiscard]] int count() const noexcept { return count_; }
  [[nodiscard]] bool playing() const noexcept { return playing_; }
  [[nodiscard]] std::int64_t start_cycle() const noexcept { return start_cycle_; }
  // The i-th segment from the front (0: the playing or next one).
  [[nodiscard]] const Segment& at(int i) const noexcept { return (*ring_)[(head_ + i) % kCapacity]; }
  [[nodiscard]] const Vec3& end() const noexcept { return end_; }
  [[nodiscard]] const Vec3& end_velocity() const noexcept { return end_v_; }
  [[nodiscard]] const Vec3& end_acceleration() const noexcept { return end_a_; }

 private:
  void clear_slot(Segment& s) noexcept;  // empty it; a plan goes to retired_
  RetiredPlans* retired_;
  std::unique_ptr<std::array<Segment, kCapacity>> ring_;
  int head_ = 0, count_ = 0;
  bool playing_ = false;
  std::int64_t start_cycle_ = 0;
  Vec3 end_ = Vec3::Zero(), end_v_ = Vec3::Zero(), end_a_ = Vec3::Zero();
};

// The tracking error over the playing segment, and the last one's summary.
class SegmentTracking {
 public:
  void begin() noexcept { sum_e2_ = 0.0, max_ = 0.0, n_ = 0; }
  void add(double error) noexcept;
  // The segment `id` ended: its RMS and maximum become the last one's.
  void finish(std::int64_t id) noexcept;
  [[nodiscard]] std::int64_t last_id() const noexcept { return last_id_; }
  [[nodiscard]] double last_rmse() const noexcept { return last_rmse_; }
  [[nodiscard]] double last_max() const noexcept { return last_max_; }
  [[nodiscard]] std::int32_t last_cycles() const noexcept { return last_n_; }

 private:
  double sum_e2_ = 0.0, max_ = 0.0;
  std::int32_t n_ = 0;
  std::int64_t last_id_ = -1;
  double last_rmse_ = 0.0, last_max_ = 0.0;
  std::int32_t last_n_ = 0;
};

// Which actuators are homed, the zero each one's homing found, and the
// sequence that homes them one after another (AxisHoming each).
class HomingSequence {
 public:
  // Absolute encoders know their zero from the start.
  explicit HomingSequence(const HomingConfig& cfg) noexcept;
  // The configured order filtered by `mask` (bit i = actuator i + 1; 0 =
  // all): those become unhomed and queued. Returns how many (0: every one
  // asked for is absolute, homed already).
  int plan(const HomingConfig& cfg, std::uint8_t mask) noexcept;
  // The next queued actuator starts homing now: returns it.
  int begin_next() noexcept;
  [[nodiscard]] bool more() const noexcept { return next_ < count_; }
  // The sequence ends (`completed`: the last actuator homed, else the one
  // homing now stays unhomed).
  void end(bool completed) noexcept;
  [[nodiscard]] bool all_homed() const noexcept { return homed[0] && homed[1] && homed[2]; }
  [[nodiscard]] int axis() const noexcept { return axis_; }  // homing now, -1 none
  // The drive homes this actuator itself this cycle.
  [[nodiscard]] bool drive_homes(int i) const noexcept {
    return axis_ == i && request.kind == AxisHoming::Request::Kind::drive;
  }

  std::array<bool, 3> homed{};
  Vec3 offset = Vec3::Zero();  // added to the backend's positions (m); an absolute actuator's is 0
  AxisHoming axis_homing;
  AxisHoming::Request request{};  // what the actuator homing now asks of the reference

 private:
  std::array<int, 3> queue_{};  // the actuators to home, in order
  int count_ = 0, next_ = 0;
  int axis_ = -1;
};

// The jog: its frame and target speed, the deadman's deadline, and the box
// of the actuator jog taken last once homed (ControlLoop::actuator_jog_box).
struct Jog {
  std::int8_t frame = 0;         // control_command_t.JOG_*
  Vec3 target = Vec3::Zero();    // commanded velocity (m/s), zero after the deadman
  std::int64_t deadline = 0;     // the cycle the last jog command stops holding
  Vec3 box_lo = Vec3::Zero(), box_hi = Vec3::Zero();
  bool box_ready = false;

  void take(std::int8_t f, const Vec3& v, std::int64_t until) noexcept {
    frame = f;
    target = v;
    deadline = until;
  }
  void keep_box(const Vec3& lo, const Vec3& hi) noexcept {
    box_lo = lo;
    box_hi = hi;
    box_ready = true;
  }
  // The deadman: past the deadline the target speed drops to zero.
  void deadman(std::int64_t k) noexcept {
    if (k >= deadline) target.setZero();
  }
};

// Bumpless transfer: when the law changes while the drives hold the
// platform, the difference between the force written last and the new
// law's is added and faded out linearly over the transfer time.
class Transfer {
 public:
  void request() noexcept { pending_ = true; }
  // The law running this cycle (actuator space or not): a change asks for
  // a transfer.
  void law(bool actuator) noexcept {
    if (actuator != actuator_law_) pending_ = true;
    actuator_law_ = actuator;
  }
  // Drives off (law: the one that would run): nothing to fade.
  void off(bool actuator) noexcept;
  // A fault: the fade ends (what was added last stays on show).
  void cancel() noexcept {
    pending_ = false;
    force_.setZero();
  }
  // At cycle k: a pending transfer starts from `written` (the force written
  // last cycle) against `law_force` (the new law's); returns whether a
  // difference is being faded in (then now() is what to add).
  bool fade(std::int64_t k, const Vec3& written, const Vec3& law_force, double dt, double transfer_time) noexcept;
  [[nodiscard]] const Vec3& now() const noexcept { return now_; }

 private:
  bool pending_ = false;
  bool actuator_law_ = false;  // the actuator law ran last cycle
  Vec3 force_ = Vec3::Zero();  // the difference at the switch
  Vec3 now_ = Vec3::Zero();    // what is added this cycle
  std::int64_t start_ = 0;
};

// Overruns one after another: `max` in a row becomes a fault, latched by the
// next cycle's safety phase.
class OverrunCount {
 public:
  void record(bool overrun, int max) noexcept {
    if (!overrun) {
      consecutive_ = 0;
      return;
    }
    if (++consecutive_ >= max) pending_ = true;
  }
  // The fault is due: returns true once per run of overruns that reached max.
  [[nodiscard]] bool take() noexcept {
    const bool p = pending_;
    pending_ = false;
    return p;
  }
  void clear() noexcept { consecutive_ = 0, pending_ = false; }
  [[nodiscard]] int consecutive() const noexcept { return consecutive_; }

 private:
  int consecutive_ = 0;
  bool pending_ = false;
};

// A stream ran dry: the fault is latched once the stop it started is at rest.
struct Underrun {
  bool pending = false;
  std::int64_t cycle = -1;
  double speed = 0.0;  // m/s, how fast the last chunk ended
  void arm(std::int64_t k, double v) noexcept { pending = true, cycle = k, speed = v; }
};

// Requests from other threads (lock-free): shutdown, and stops heard on the
// bus, which the loop takes before any command.
class LoopRequests {
 public:
  void shutdown() noexcept { shutdown_.store(true, std::memory_order_release); }
  void stop() noexcept { stops_.fetch_add(1, std::memory_order_release); }
  [[nodiscard]] bool shutdown_requested() const noexcept { return shutdown_.load(std::memory_order_acquire); }
  // Loop thread: a stop came since the last call.
  [[nodiscard]] bool take_stop() noexcept {
    const std::uint64_t r = stops_.load(std::memory_order_acquire);
    if (r == taken_) return false;
    taken_ = r;
    return true;
  }

 private:
  std::atomic<bool> shutdown_{false};
  std::atomic<std::uint64_t> stops_{0};
  std::uint64_t taken_ = 0;  // stops_ as last acted on (loop thread)
};

}  // namespace cpm::daemon
