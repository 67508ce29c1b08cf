// SPDX-License-Identifier: Apache-2.0
// Harnesses for the fault matrix (docs/fault-matrix.md): the control loop on
// the simulator backend behind a fault-injecting decorator, stepped cycle by
// cycle with every published state kept, and the checks every row shares:
// detection latency in cycles, the reaction (forces zero, drives off), the
// report, the latch, and a reset that resynchronises the setpoint.
#pragma once

#include <gtest/gtest.h>

#include <cmath>
#include <memory>
#include <string>
#include <vector>

#include "cpm/daemon/loop.hpp"
#include "cpm/daemon/sim_backend.hpp"
#include "daemon/loop_fixture.hpp"

namespace cpm::daemon::test {

inline bool has(const std::string& s, const std::string& part) { return s.find(part) != std::string::npos; }

inline std::string text_of(const cpm_msgs::state_t& s) {
  const auto* t = reinterpret_cast<const char*>(s.fault_text);
  return std::string(t, strnlen(t, sizeof s.fault_text));
}
inline Vec3 v3(const double* v) { return Vec3(v[0], v[1], v[2]); }

// Faults a backend cannot be asked for: a NaN encoder reading, a drive that
// delivers no force (power stage lost, coupling broken), a failing write.
class InjectingBackend final : public Backend {
 public:
  explicit InjectingBackend(Backend& inner) : inner_(inner) {}
  [[nodiscard]] const char* name() const noexcept override { return "injecting"; }
  void start(double period) override { inner_.start(period); }
  void stop() noexcept override { inner_.stop(); }
  BackendResult read(std::int64_t cycle, BackendInput& in) noexcept override {
    const BackendResult r = inner_.read(cycle, in);
    if (nan_position_axis >= 0) in.position[nan_position_axis] = std::nan("");
    return r;
  }
  BackendResult write(std::int64_t cycle, const BackendOutput& out) noexcept override {
    BackendOutput o = out;
    if (dead_axis >= 0) o.force[dead_axis] = 0.0;
    last_out = out;
    ++writes;
    const BackendResult r = inner_.write(cycle, o);
    return fail_writes ? BackendResult::io_error : r;
  }
  [[nodiscard]] const char* fault_text() const noexcept override { return inner_.fault_text(); }

  int nan_position_axis = -1;  // this actuator's encoder reads NaN
  int dead_axis = -1;          // this actuator's force never reaches the plant
  bool fail_writes = false;
  BackendOutput last_out{};    // what the loop wrote last (before injection)
  std::int64_t writes = 0;

 private:
  Backend& inner_;
};

// The loop on the simulator backend behind InjectingBackend; every state kept.
struct SimRig {
  DaemonConfig cfg;
  ctl::Machine truth{ctl::MachineModel::elkady()};
  ctl::Machine model;
  std::unique_ptr<SimBackend> sim;
  std::unique_ptr<InjectingBackend> backend;
  std::unique_ptr<ControlLoop> loop;
  std::vector<cpm_msgs::state_t> states;
  std::int64_t k = 0;
  std::int64_t next_id = 1;

  explicit SimRig(const DaemonConfig& c = test_config(), double enable_delay = 0.005,
                  ctl::MachineModel belief = ctl::MachineModel::elkady())
      : cfg(c), model(belief) {
    SimBackendOptions so;
    so.enable_delay = enable_delay;
    sim = std::make_unique<SimBackend>(std::make_unique<ctl::Machine>(ctl::MachineModel::elkady()), so);
    backend = std::make_unique<InjectingBackend>(*sim);
    backend->start(1.0 / cfg.loop.rate_hz);
    loop = std::make_unique<ControlLoop>(cfg, *backend, model,
                                         ctl::Controller(model, cfg.controller.law, cfg.controller.gains));
    states.reserve(20000);
    run(2);
  }
  void step() {
    loop->cycle(k++, 0);
    while (const auto* s = loop->snapshots().front()) {
      states.push_back(*s);
      loop->snapshots().release();
    }
  }
  void run(int n) {
    for (int i = 0; i < n; ++i) step();
  }
  template <class P>
  int run_until(P pred, int limit) {
    for (int n = 0; n < limit; ++n) {
      if (pred()) return n;
      step();
    }
    return pred() ? limit : -1;
  }
  Mode mode() const { return loop->mode(); }
  const cpm_msgs::state_t& state() const { return loop->last_state(); }
  Vec3 position() const { return v3(state().position); }
  Vec3 queue_end() const { return v3(state().queue_end); }
  Ack command(Command c) {
    c.id = next_id++;
    EXPECT_TRUE(loop->commands().push(c));
    step();
    Ack a;
    EXPECT_TRUE(loop->acks().pop(a)) << "no ack";
    while (loop->acks().pop(a)) {
    }
    return a;
  }
  Ack simple(CommandKind kind) {
    Command c;
    c.kind = kind;
    return command(c);
  }
  Command move_to(const Vec3& to, double v = 0.1, double a = 1.0) {
    Command c;
    c.kind = CommandKind::segment;
    c.segment.start = queue_end();
    c.segment.end = to;
    ctl::MotionLimits lim;
    lim.velocity = v;
    lim.acceleration = a;
    c.segment.traj.emplace<ctl::PointToPoint>(c.segment.start, to, lim);
    return c;
  }
  void to_holding() {
    ASSERT_TRUE(simple(CommandKind::enable).accepted);
    ASSERT_GE(run_until([&] { return mode() == Mode::holding; }, 100), 0);
  }
  // The state of cycle `cycle` (it must have been published).
  const cpm_msgs::state_t& at(std::int64_t cycle) const {
    for (auto it = states.rbegin(); it != states.rend(); ++it)
      if (it->cycle == cycle) return *it;
    ADD_FAILURE() << "no state of cycle " << cycle;
    return states.back();
  }
  // First published cycle >= from where `pred(state)` holds; -1 if none.
  template <class P>
  std::int64_t first_cycle(P pred, std::int64_t from = 0) const {
    for (const auto& s : states)
      if (s.cycle >= from && pred(s)) return s.cycle;
    return -1;
  }
};

// The reaction every latched fault has, from the fault's own cycle on: the
// loop writes zero force with the drives disabled (brakes on), and the
// simulated platform stays where it stopped.
inline void expect_safe_from(const SimRig& r, std::int64_t fault_cycle) {
  ASSERT_GE(fault_cycle, 0);
  for (const auto& s : r.states) {
    if (s.cycle < fault_cycle) continue;
    EXPECT_EQ(s.mode, static_cast<std::int8_t>(Mode::fault)) << "cycle " << s.cycle;
    for (int i = 0; i < 3; ++i) EXPECT_EQ(s.force[i], 0.0) << "force " << i + 1 << " at cycle " << s.cycle;
  }
  EXPECT_FALSE(r.backend->last_out.enable) << "the drives are still enabled";
  for (int i = 0; i < 3; ++i) EXPECT_EQ(r.backend->last_out.force[i], 0.0);
  EXPECT_EQ(r.sim->plant().velocity().norm(), 0.0) << "the brakes do not hold the platform";
}

// The report: the first fault's bit, axis and the words of its text.
inline void expect_report(const cpm_msgs::state_t& s, std::uint32_t bit, int axis, const std::string& words = "") {
  EXPECT_EQ(static_cast<std::uint32_t>(s.first_fault), bit) << "first fault " << fault_bit_name(s.first_fault);
  EXPECT_TRUE(static_cast<std::uint32_t>(s.faults) & bit);
  EXPECT_EQ(s.fault_axis, axis);
  if (!words.empty()) {
    EXPECT_TRUE(has(text_of(s), words)) << "fault text '" << text_of(s) << "'";
  }
}

// Latch, then reset: the fault stays `hold` cycles after its cause is gone
// (the caller cleared it), reset takes the loop to disabled with the setpoint
// on the measured position, and enabling again holds there without a jump.
inline void expect_latched_then_reset(SimRig& r, std::uint32_t bit, int hold = 100) {
  r.run(hold);
  ASSERT_EQ(r.mode(), Mode::fault) << "the fault did not latch";
  EXPECT_TRUE(static_cast<std::uint32_t>(r.state().faults) & bit);
  EXPECT_FALSE(r.simple(CommandKind::enable).accepted) << "enable accepted with a fault latched";
  const Ack a = r.simple(CommandKind::reset);
  ASSERT_TRUE(a.accepted) << a.message;
  EXPECT_EQ(r.mode(), Mode::disabled);
  EXPECT_EQ(r.state().faults, 0);
  EXPECT_EQ(r.state().fault_cycle, -1);
  EXPECT_LT((v3(r.state().position_ref) - r.position()).norm(), 1e-12) << "setpoint not resynchronised";
  const Vec3 p0 = r.sim->plant().position();
  const std::size_t from = r.states.size();
  r.to_holding();
  r.run(100);
  double jump = 0;
  for (std::size_t i = from; i < r.states.size(); ++i)
    jump = std::max(jump, (v3(r.states[i].position_ref) - p0).norm());
  EXPECT_LT(jump, 1e-9) << "the setpoint jumped after the reset (m)";
  EXPECT_LT((r.sim->plant().position() - p0).norm(), 2e-6) << "the platform moved after the reset (m)";
  EXPECT_EQ(r.mode(), Mode::holding);
}

}  // namespace cpm::daemon::test
