// SPDX-License-Identifier: Apache-2.0
// Every state x every command of the state machine (docs/daemon.md), legal
// and illegal, and the transitions the loop makes by itself (drives enabled,
// queue empty, at rest, faults), all on the simulator backend cycle by cycle.
#include <map>

#include <cpm_msgs/ack_t.hpp>

#include "loop_fixture.hpp"

namespace cpm::daemon::test {
namespace {

struct Expect {
  bool accepted;
  Mode after;
};

// Bring a fresh harness into `m`.
std::unique_ptr<LoopHarness> in_mode(Mode m) {
  // A long enable delay keeps the machine in `enabling` for the test.
  auto h = std::make_unique<LoopHarness>(test_config(), m == Mode::enabling ? 0.2 : 0.005);
  switch (m) {
    case Mode::disabled: break;
    case Mode::enabling: EXPECT_TRUE(h->simple(CommandKind::enable).accepted); break;
    case Mode::holding: h->to_holding(); break;
    case Mode::moving: h->to_moving(); break;
    case Mode::stopping: h->to_stopping(); break;
    case Mode::fault: h->to_fault(); break;
    default: break;
  }
  EXPECT_EQ(h->mode(), m);
  return h;
}

Command make(LoopHarness& h, CommandKind k, std::unique_ptr<ctl::Machine>& keep) {
  Command c;
  c.kind = k;
  if (k == CommandKind::select_controller)
    c.controller.emplace(h.machine, ctl::ControlLaw::pd_gravity, ctl::table3_gains(ctl::ControlLaw::pd_gravity));
  if (k == CommandKind::load_model) {
    keep = std::make_unique<ctl::Machine>(ctl::MachineModel::elkady());
    c.machine = keep.get();
    c.controller.emplace(*keep, ctl::ControlLaw::computed_torque, ctl::table3_gains(ctl::ControlLaw::computed_torque));
  }
  if (k == CommandKind::segment) c = h.move_to(h.queue_end() + Vec3(0, 0.02, 0));
  return c;
}

TEST(StateMachine, EveryCommandInEveryState) {
  const std::map<Mode, std::map<CommandKind, Expect>> table = {
      {Mode::disabled,
       {{CommandKind::enable, {true, Mode::enabling}}, {CommandKind::disable, {false, Mode::disabled}},
        {CommandKind::stop, {false, Mode::disabled}}, {CommandKind::reset, {false, Mode::disabled}},
        {CommandKind::select_controller, {true, Mode::disabled}}, {CommandKind::load_model, {true, Mode::disabled}},
        {CommandKind::segment, {false, Mode::disabled}}}},
      {Mode::enabling,
       {{CommandKind::enable, {false, Mode::enabling}}, {CommandKind::disable, {true, Mode::disabled}},
        {CommandKind::stop, {false, Mode::enabling}}, {CommandKind::reset, {false, Mode::enabling}},
        {CommandKind::select_controller, {false, Mode::enabling}}, {CommandKind::load_model, {false, Mode::enabling}},
        {CommandKind::segment, {false, Mode::enabling}}}},
      {Mode::holding,
       {{CommandKind::enable, {false, Mode::holding}}, {CommandKind::disable, {true, Mode::disabled}},
        {CommandKind::stop, {true, Mode::holding}}, {CommandKind::reset, {false, Mode::holding}},
        {CommandKind::select_controller, {true, Mode::holding}}, {CommandKind::load_model, {false, Mode::holding}},
        {CommandKind::segment, {true, Mode::moving}}}},
      {Mode::moving,
       {{CommandKind::enable, {false, Mode::moving}}, {CommandKind::disable, {true, Mode::stopping}},
        {CommandKind::stop, {true, Mode::stopping}}, {CommandKind::reset, {false, Mode::moving}},
        {CommandKind::select_controller, {false, Mode::moving}}, {CommandKind::load_model, {false, Mode::moving}},
        {CommandKind::segment, {true, Mode::moving}}}},
      {Mode::stopping,
       {{CommandKind::enable, {false, Mode::stopping}}, {CommandKind::disable, {true, Mode::stopping}},
        {CommandKind::stop, {true, Mode::stopping}}, {CommandKind::reset, {false, Mode::stopping}},
        {CommandKind::select_controller, {false, Mode::stopping}}, {CommandKind::load_model, {false, Mode::stopping}},
        {CommandKind::segment, {false, Mode::stopping}}}},
      {Mode::fault,
       {{CommandKind::enable, {false, Mode::fault}}, {CommandKind::disable, {false, Mode::fault}},
        {CommandKind::stop, {false, Mode::fault}}, {CommandKind::reset, {true, Mode::disabled}},
        {CommandKind::select_controller, {false, Mode::fault}}, {CommandKind::load_model, {false, Mode::fault}},
        {CommandKind::segment, {false, Mode::fault}}}},
  };
  for (const auto& [mode, row] : table)
    for (const auto& [kind, expect] : row) {
      SCOPED_TRACE(std::string(mode_name(mode)) + " + command " + std::to_string(static_cast<int>(kind)));
      auto h = in_mode(mode);
      std::unique_ptr<ctl::Machine> keep;
      const auto before = h->state();
      const Ack a = h->command(make(*h, kind, keep));
      EXPECT_EQ(a.accepted, expect.accepted) << a.message;
      EXPECT_EQ(h->mode(), expect.after);
      EXPECT_STRNE(a.message, "");
      if (!a.accepted) {
        EXPECT_NE(a.refusal, Refusal::none);
        // A refused command changes nothing: same faults, same queue.
        EXPECT_EQ(h->state().faults, before.faults);
        EXPECT_EQ(h->state().queue_depth, before.queue_depth);
      }
      if (kind == CommandKind::load_model) {
        // The loop hands back the model it no longer uses: the old one when it
        // took the new one, the new one when it refused.
        EXPECT_EQ(a.retired, a.accepted ? &h->machine : keep.get());
      }
      if (kind == CommandKind::select_controller && a.accepted) {
        EXPECT_EQ(h->state().controller, static_cast<int>(ctl::ControlLaw::pd_gravity));
      }
    }
}

TEST(StateMachine, StartsInInitThenDisabled) {
  LoopHarness h;
  EXPECT_EQ(h.mode(), Mode::disabled);
  EXPECT_EQ(h.state().faults, 0);
}

TEST(StateMachine, EnablingBecomesHoldingWhenDrivesReportEnabled) {
  LoopHarness h(test_config(), 0.010);
  ASSERT_TRUE(h.simple(CommandKind::enable).accepted);
  h.run(5);
  EXPECT_EQ(h.mode(), Mode::enabling);  // drives not yet enabled
  h.run(10);
  EXPECT_EQ(h.mode(), Mode::holding);
}

TEST(StateMachine, EnableTimeoutIsAFault) {
  DaemonConfig c = test_config();
  c.limits.enable_timeout = 0.05;
  LoopHarness h(c, 1.0);  // the drives take 1 s; the loop waits 50 ms
  ASSERT_TRUE(h.simple(CommandKind::enable).accepted);
  h.run(49);
  EXPECT_EQ(h.mode(), Mode::enabling);
  h.run(5);
  EXPECT_EQ(h.mode(), Mode::fault);
  EXPECT_EQ(h.state().first_fault, kFaultEnableTimeout);
}

TEST(StateMachine, QueuePlaysBackToBackThenHolds) {
  LoopHarness h;
  h.to_holding();
  const Vec3 p0 = h.queue_end();
  const Vec3 a = p0 + Vec3(-0.02, 0, 0), b = a + Vec3(0, 0.02, 0.01);
  Command c1 = h.move_to(a);
  ASSERT_TRUE(h.command(c1).accepted);
  Command c2 = h.move_to(b);  // starts at the queue's end = a
  EXPECT_TRUE(c2.segment.start.isApprox(a));
  const std::int64_t id2 = h.next_id;
  ASSERT_TRUE(h.command(c2).accepted);
  EXPECT_EQ(h.state().queue_depth, 1);
  for (int i = 0; i < 5000 && h.mode() == Mode::moving; ++i) h.run(1);
  EXPECT_EQ(h.mode(), Mode::holding);
  h.run(300);  // settle
  EXPECT_LT((h.position() - b).norm(), 1e-6);
  EXPECT_EQ(h.state().last_segment_id, id2);
}

TEST(StateMachine, SegmentNotStartingAtQueueEndIsRefused) {
  LoopHarness h;
  h.to_holding();
  Command c = h.move_to(h.queue_end() + Vec3(0.01, 0, 0));
  c.segment.start += Vec3(0.001, 0, 0);  // planned from a stale point
  const Ack a = h.command(c);
  EXPECT_FALSE(a.accepted);
  EXPECT_EQ(a.refusal, Refusal::not_continuous);
  EXPECT_EQ(h.mode(), Mode::holding);
}

TEST(StateMachine, StopDeceleratesToRestThenHolds) {
  LoopHarness h;
  h.to_stopping();
  const double v0 = Vec3(h.state().velocity_ref[0], h.state().velocity_ref[1], h.state().velocity_ref[2]).norm();
  EXPECT_GT(v0, 0.05);
  // v0 / 2 m/s^2 of deceleration, plus one cycle.
  const int n = static_cast<int>(std::ceil(v0 / h.cfg.limits.stop_deceleration * 1000)) + 2;
  h.run(n);
  EXPECT_EQ(h.mode(), Mode::holding);
  EXPECT_EQ(h.state().queue_depth, 0);
  h.run(300);
  const Vec3 v(h.state().velocity[0], h.state().velocity[1], h.state().velocity[2]);
  EXPECT_LT(v.norm(), 1e-5);
}

TEST(StateMachine, DisableWhileMovingStopsThenDisables) {
  LoopHarness h;
  h.to_moving();
  h.run(100);
  ASSERT_TRUE(h.simple(CommandKind::disable).accepted);
  EXPECT_EQ(h.mode(), Mode::stopping);
  h.run(200);
  EXPECT_EQ(h.mode(), Mode::disabled);
}

TEST(StateMachine, FaultsLatchAndResetResyncsToMeasuredPosition) {
  LoopHarness h;
  h.to_moving();
  h.run(100);
  h.sim->set_estop(true);
  h.run(1);
  EXPECT_EQ(h.mode(), Mode::fault);
  EXPECT_EQ(h.state().first_fault, kFaultEstop);
  EXPECT_EQ(h.state().force[0], 0.0);
  // While the cause is present, reset is refused.
  Ack a = h.simple(CommandKind::reset);
  EXPECT_FALSE(a.accepted);
  EXPECT_EQ(h.mode(), Mode::fault);
  h.sim->set_estop(false);
  h.run(10);
  EXPECT_EQ(h.mode(), Mode::fault);  // latched: the cause going away is not enough
  a = h.simple(CommandKind::reset);
  EXPECT_TRUE(a.accepted) << a.message;
  EXPECT_EQ(h.mode(), Mode::disabled);
  EXPECT_EQ(h.state().faults, 0);
  // The setpoint is where the platform is (it stopped mid-move under the brakes).
  EXPECT_LT((h.queue_end() - h.position()).norm(), 1e-12);
  ASSERT_TRUE(h.simple(CommandKind::enable).accepted);
  h.run(20);
  EXPECT_EQ(h.mode(), Mode::holding);
  EXPECT_LT(h.state().position_error_norm, 1e-6);  // nothing jumped
}

TEST(StateMachine, DriveFaultAndBackendIoLatch) {
  {
    LoopHarness h;
    h.to_holding();
    h.sim->inject_drive_fault(1);
    h.run(1);
    EXPECT_EQ(h.mode(), Mode::fault);
    EXPECT_EQ(h.state().first_fault, kFaultDrive);
    EXPECT_EQ(h.state().fault_axis, 1);
    EXPECT_FALSE(h.simple(CommandKind::reset).accepted);  // drive still faulted
    h.sim->inject_drive_fault(-1);
    h.run(1);
    EXPECT_TRUE(h.simple(CommandKind::reset).accepted);
  }
  {
    LoopHarness h;
    h.to_holding();
    h.sim->inject_io_error(true);
    h.run(1);
    EXPECT_EQ(h.mode(), Mode::fault);
    EXPECT_EQ(h.state().first_fault, kFaultBackendIo);
  }
}

TEST(StateMachine, ConsecutiveOverrunsAreAFault) {
  LoopHarness h;  // max_consecutive_overruns = 3
  h.to_holding();
  h.loop->record_schedule(true, 1);
  h.loop->record_schedule(true, 1);
  h.loop->record_schedule(false, 0);  // the count restarts
  h.loop->record_schedule(true, 1);
  h.loop->record_schedule(true, 1);
  h.run(1);
  EXPECT_EQ(h.mode(), Mode::holding);
  h.loop->record_schedule(true, 1);
  h.run(1);
  EXPECT_EQ(h.mode(), Mode::fault);
  EXPECT_EQ(h.state().first_fault, kFaultOverrun);
  EXPECT_EQ(h.state().overruns, 5);
}

// The wake-up latency is kept twice: in loop_stats_t's bins (1 us to 200 us,
// then 50 us) and in 1 us bins to 2 ms (for the comparison with cyclictest).
// Both must hold every sample, in the right bin.
TEST(LoopStatistics, WakeUpLatencyInBothHistograms) {
  LoopHarness h;
  const auto& fine0 = h.loop->fine_latency_histogram();
  const std::int64_t before = h.loop->current_stats().count[kSeriesLatency];
  std::int64_t fine_before = 0;
  for (auto n : fine0) fine_before += n;
  ASSERT_EQ(fine_before, before);
  // ns: within the fine range, on both sides of the coarse limit, exactly on
  // bin edges, just below 2 ms, and far above it (one bin for all).
  const std::int64_t planted[] = {0, 999, 1000, 66'400, 199'999, 200'000, 249'999, 250'000, 251'700,
                                  1'999'999, 2'000'000, 40'000'000};
  auto fine_count = [&](int us) { return h.loop->fine_latency_histogram()[static_cast<std::size_t>(us)]; };
  auto coarse_count = [&](std::int64_t ns) { return h.loop->current_stats().histogram[kSeriesLatency][histogram_bin(ns)]; };
  for (std::int64_t ns : planted) {
    const int fine_bin = static_cast<int>(std::min<std::int64_t>(ns / 1000, kFineLatencyBins - 1));
    const auto f0 = fine_count(fine_bin);
    const auto c0 = coarse_count(ns);
    h.loop->cycle(h.k++, ns);
    h.drain_snapshots();
    EXPECT_EQ(fine_count(fine_bin), f0 + 1) << ns << " ns";
    EXPECT_EQ(coarse_count(ns), c0 + 1) << ns << " ns";
  }
  // Every coarse bin holds exactly the fine bins it spans.
  const auto& st = h.loop->current_stats();
  const auto& fine = h.loop->fine_latency_histogram();
  for (int b = 0; b < kBins; ++b) {
    const std::int64_t lo = histogram_bin_floor(b) / 1000;
    const std::int64_t hi = b + 1 < kBins ? histogram_bin_floor(b + 1) / 1000 : kFineLatencyBins;
    std::int64_t sum = 0;
    for (std::int64_t us = lo; us < hi; ++us) sum += fine[static_cast<std::size_t>(us)];
    EXPECT_EQ(sum, st.histogram[kSeriesLatency][b]) << "coarse bin " << b << " [" << lo << ", " << hi << ") us";
  }
  EXPECT_EQ(fine[199], 1);   // 199.999 us
  EXPECT_EQ(fine[251], 1);   // 251.7 us: coarse bin [250, 300)
  EXPECT_EQ(fine[kFineLatencyBins - 1], 2);  // 2 ms and 40 ms
  EXPECT_EQ(st.count[kSeriesLatency], before + static_cast<std::int64_t>(std::size(planted)));
}

TEST(StateMachine, FollowingErrorIsAFault) {
  // The true machine carries 3 kg the model does not know: holding against
  // gravity with the wrong model leaves a steady error the limit catches.
  DaemonConfig c = test_config();
  c.limits.following_error = 0.0005;
  LoopHarness h(c);
  ctl::MachineModel heavy = ctl::MachineModel::elkady();
  ctl::add_effect(heavy, "payload_mass", -1, {3.0});
  SimBackendOptions so;
  auto b = std::make_unique<SimBackend>(std::make_unique<ctl::Machine>(heavy), so);
  h.sim = b.get();
  h.backend = std::move(b);
  h.backend->start(1e-3);
  h.loop = std::make_unique<ControlLoop>(c, *h.backend, h.machine,
                                         ctl::Controller(h.machine, ctl::ControlLaw::pd,
                                                         ctl::table3_gains(ctl::ControlLaw::pd)));
  h.run(2);
  ASSERT_TRUE(h.simple(CommandKind::enable).accepted);
  h.run(500);
  EXPECT_EQ(h.mode(), Mode::fault);
  EXPECT_EQ(h.state().first_fault, kFaultFollowingError);
  EXPECT_GT(h.state().fault_value, 0.0005);
}

}  // namespace
}  // namespace cpm::daemon::test
