// SPDX-License-Identifier: Apache-2.0
// The fault matrix (docs/fault-matrix.md), rows the loop detects itself, on
// the simulator backend: one test per row, each asserting the detection
// latency in cycles, the reaction (zero force, drives off, brakes holding),
// the report (bit, axis, value, limit), the latch and the reset (setpoint on
// the measured position, nothing jumps).
#include <cmath>

#include "cpm/kinematics/plane_model.hpp"
#include "cpm/kinematics/workspace.hpp"
#include "reliability/fault_rig.hpp"

namespace cpm::daemon::test {
namespace {

// Row: e-stop chain open. Latency 0 cycles (the cycle that reads it).
TEST(FaultMatrix, EstopSim) {
  SimRig r;
  r.to_holding();
  ASSERT_TRUE(r.command(r.move_to(r.queue_end() + Vec3(-0.05, 0, 0))).accepted);
  r.run(100);
  const std::int64_t k_cause = r.k;
  r.sim->set_estop(true);
  r.step();
  ASSERT_EQ(r.mode(), Mode::fault);
  EXPECT_EQ(r.state().fault_cycle, k_cause);
  expect_report(r.state(), kFaultEstop, -1);
  r.run(10);
  expect_safe_from(r, k_cause);
  // Refused while the chain is open, with the reason.
  const Ack a = r.simple(CommandKind::reset);
  EXPECT_FALSE(a.accepted);
  EXPECT_TRUE(has(a.message, "e-stop")) << a.message;
  r.sim->set_estop(false);
  expect_latched_then_reset(r, kFaultEstop);
}

// Row: drive fault bit (CiA 402 fault). Latency 0 cycles.
TEST(FaultMatrix, DriveFaultBitSim) {
  SimRig r;
  r.to_holding();
  const std::int64_t k_cause = r.k;
  r.sim->inject_drive_fault(1);
  r.step();
  ASSERT_EQ(r.mode(), Mode::fault);
  EXPECT_EQ(r.state().fault_cycle, k_cause);
  expect_report(r.state(), kFaultDrive, 1);
  EXPECT_EQ(r.state().fault_value, 0x0218);  // the statusword that said so
  r.run(5);
  expect_safe_from(r, k_cause);
  EXPECT_FALSE(r.simple(CommandKind::reset).accepted) << "reset accepted while the drive reports a fault";
  r.sim->inject_drive_fault(-1);
  expect_latched_then_reset(r, kFaultDrive);
}

// Row: backend I/O error on read. Latency 0 cycles.
TEST(FaultMatrix, BackendReadErrorSim) {
  SimRig r;
  r.to_holding();
  const std::int64_t k_cause = r.k;
  r.sim->inject_io_error(true);
  r.step();
  ASSERT_EQ(r.mode(), Mode::fault);
  EXPECT_EQ(r.state().fault_cycle, k_cause);
  expect_report(r.state(), kFaultBackendIo, -1);
  r.sim->inject_io_error(false);
  r.run(5);
  expect_safe_from(r, k_cause);
  expect_latched_then_reset(r, kFaultBackendIo);
}

// Row: backend I/O error on write. Latched in the cycle whose write failed;
// the next write already disables.
TEST(FaultMatrix, BackendWriteErrorSim) {
  SimRig r;
  r.to_holding();
  const std::int64_t k_cause = r.k;
  r.backend->fail_writes = true;
  r.step();
  ASSERT_EQ(r.mode(), Mode::fault);
  EXPECT_EQ(r.state().fault_cycle, k_cause);
  expect_report(r.state(), kFaultBackendIo, -1);
  r.backend->fail_writes = false;
  r.run(5);
  expect_safe_from(r, k_cause + 1);
  expect_latched_then_reset(r, kFaultBackendIo);
}

// Row: an encoder reading that is not a number (or a pose the forward
// kinematics cannot solve). Latency 0 cycles.
TEST(FaultMatrix, EstimateFailsSim) {
  SimRig r;
  r.to_holding();
  const std::int64_t k_cause = r.k;
  r.backend->nan_position_axis = 2;
  r.step();
  ASSERT_EQ(r.mode(), Mode::fault);
  EXPECT_EQ(r.state().fault_cycle, k_cause);
  EXPECT_EQ(static_cast<std::uint32_t>(r.state().first_fault), kFaultEstimate);
  r.backend->nan_position_axis = -1;
  r.run(5);
  expect_safe_from(r, k_cause);
  expect_latched_then_reset(r, kFaultEstimate);
}

// Row: following error beyond limits.following_error. A drive whose force
// never reaches the axis (lost power stage) while a move runs. Latency: 0
// cycles after the measured error first exceeds the limit.
TEST(FaultMatrix, FollowingErrorSim) {
  SimRig r;
  r.to_holding();
  r.backend->dead_axis = 0;
  ASSERT_TRUE(r.command(r.move_to(r.queue_end() + Vec3(-0.1, 0, 0), 0.1)).accepted);
  ASSERT_GE(r.run_until([&] { return r.mode() == Mode::fault; }, 2000), 0);
  const double lim = r.cfg.limits.following_error;
  const std::int64_t k_over = r.first_cycle([&](const auto& s) { return s.position_error_norm > lim; });
  ASSERT_GE(k_over, 0);
  EXPECT_EQ(r.state().fault_cycle, k_over) << "latency (cycles) " << r.state().fault_cycle - k_over;
  EXPECT_LE(r.at(k_over - 1).position_error_norm, lim);
  expect_report(r.state(), kFaultFollowingError, -1);
  EXPECT_GT(r.state().fault_value, lim);
  EXPECT_EQ(r.state().fault_limit, lim);
  r.backend->dead_axis = -1;
  r.run(5);
  expect_safe_from(r, k_over);
  expect_latched_then_reset(r, kFaultFollowingError);
}

// Row: force saturation held longer than limits.saturation_time. The axis
// cannot follow (dead drive) and the following-error limit is wide, so only
// the saturation timer catches it. Latency: floor(T / period) + 1 cycles of
// saturation, the last of them the fault's.
TEST(FaultMatrix, ForceSaturationHeldTooLongSim) {
  DaemonConfig c = test_config();
  c.limits.following_error = 0.1;
  c.limits.saturation_time = 0.05;
  SimRig r(c);
  r.to_holding();
  r.backend->dead_axis = 0;
  ASSERT_TRUE(r.command(r.move_to(r.queue_end() + Vec3(-0.2, 0, 0), 0.1)).accepted);
  ASSERT_GE(r.run_until([&] { return r.mode() == Mode::fault; }, 3000), 0);
  const std::int64_t k_sat = r.first_cycle([](const auto& s) { return s.saturated[0]; });
  ASSERT_GE(k_sat, 0);
  const auto n_expected = static_cast<std::int64_t>(std::floor(c.limits.saturation_time * c.loop.rate_hz + 1e-9)) + 1;
  for (std::int64_t k = k_sat; k < r.state().fault_cycle; ++k) ASSERT_TRUE(r.at(k).saturated[0]) << "cycle " << k;
  EXPECT_EQ(r.state().fault_cycle - k_sat + 1, n_expected);
  expect_report(r.state(), kFaultSaturation, 0);
  EXPECT_GT(r.state().fault_value, c.limits.saturation_time);
  EXPECT_EQ(r.state().fault_limit, c.limits.saturation_time);
  EXPECT_LT(r.state().position_error_norm, c.limits.following_error);
  EXPECT_STREQ(fault_bit_name(kFaultSaturation), "force_saturation");
  r.backend->dead_axis = -1;
  r.run(5);
  expect_safe_from(r, r.state().fault_cycle);
  expect_latched_then_reset(r, kFaultSaturation);
}

// The saturation timer counts consecutive cycles only: a brief saturation
// (the start of a fast move) is no fault.
TEST(FaultMatrix, BriefSaturationIsNoFault) {
  DaemonConfig c = test_config();
  c.limits.saturation_time = 0.05;
  SimRig r(c);
  r.to_holding();
  // 4 m/s^2 with a jerk step: a few cycles at the force limit at the start.
  ASSERT_TRUE(r.command(r.move_to(r.queue_end() + Vec3(-0.1, 0, 0), 0.3, 4.0)).accepted);
  ASSERT_GE(r.run_until([&] { return r.mode() == Mode::holding; }, 3000), 0);
  EXPECT_EQ(r.state().faults, 0) << fault_bit_name(r.state().first_fault) << " " << r.state().fault_value;
}

// Row: workspace (soft limits). The measured position leaves
// limits.workspace_min/max by more than the platform's tracking error where
// its reference stops at one (ControlLoop::kSoftLimitSlack); latency 0 cycles.
TEST(FaultMatrix, SoftLimitSim) {
  DaemonConfig c = test_config();
  c.limits.workspace_max.x() = 0.610;
  SimRig r(c);
  r.to_holding();
  // In-process the command skips the LCM thread's check of the path, as a
  // model error or a drifting encoder would.
  ASSERT_TRUE(r.command(r.move_to(Vec3(0.62, 0.425, 0.300), 0.05)).accepted);
  ASSERT_GE(r.run_until([&] { return r.mode() == Mode::fault; }, 2000), 0);
  const std::int64_t k_out = r.first_cycle(
      [&](const auto& s) { return s.position[0] > c.limits.workspace_max.x() + ControlLoop::kSoftLimitSlack; });
  ASSERT_GE(k_out, 0);
  EXPECT_EQ(r.state().fault_cycle, k_out);
  expect_report(r.state(), kFaultSoftLimit, 0);
  EXPECT_EQ(r.state().fault_limit, c.limits.workspace_max.x());
  r.run(5);
  expect_safe_from(r, k_out);
  // Still outside: reset is allowed (the operator moves back in), the first
  // powered cycle outside latches again.
  EXPECT_TRUE(r.simple(CommandKind::reset).accepted);
  EXPECT_TRUE(r.simple(CommandKind::enable).accepted);
  r.run(3);
  EXPECT_EQ(r.mode(), Mode::fault);
  EXPECT_EQ(static_cast<std::uint32_t>(r.state().first_fault), kFaultSoftLimit);
}

// Row: singularity / reach / stroke end. With the soft limits opened wide,
// a path running out of the machine's workspace (actuator stroke, limb
// reach, elbow near straight or folded: kin::check_pose) latches soft_limit
// in the cycle before the reference leaves it (the reference is checked one
// cycle ahead): latency -1 cycles, before the platform itself gets there.
TEST(FaultMatrix, WorkspaceOrSingularityApproachSim) {
  DaemonConfig c = test_config();
  c.limits.workspace_min = Vec3(0, 0, 0);
  c.limits.workspace_max = Vec3(2, 2, 2);
  c.limits.following_error = 0.1;
  SimRig r(c);
  r.to_holding();
  ASSERT_TRUE(r.command(r.move_to(Vec3(1.5, 0.425, 0.300), 0.1)).accepted);
  ASSERT_GE(r.run_until([&] { return r.mode() == Mode::fault; }, 20000), 0);
  const std::int64_t kf = r.state().fault_cycle;
  expect_report(r.state(), kFaultSoftLimit, r.state().fault_axis);
  const kin::KinematicInputs ki;
  const auto& strokes = r.model.model().strokes;
  // The reference one cycle ahead: inside at kf - 1, outside at kf.
  auto ahead = [&](std::int64_t k) -> Vec3 { return v3(r.at(k).position_ref) + v3(r.at(k).velocity_ref) * 1e-3; };
  const Status before = kin::check_pose(r.model.kinematics(), strokes, ahead(kf - 1), ki);
  const Status now = kin::check_pose(r.model.kinematics(), strokes, ahead(kf), ki);
  EXPECT_TRUE(before.ok()) << describe(before);
  EXPECT_FALSE(now.ok());
  EXPECT_TRUE(kin::check_pose(r.model.kinematics(), strokes, v3(r.at(kf).position), ki).ok())
      << "the platform got there first";
  std::printf("workspace: soft_limit at x_ref = %.4f m (%s)\n", r.at(kf).position_ref[0], describe(now).c_str());
  r.run(5);
  expect_safe_from(r, kf);
}

// Overspeed (measured platform speed above limits.overspeed): latency 0 cycles.
TEST(FaultMatrix, OverspeedSim) {
  DaemonConfig c = test_config();
  c.limits.velocity = 0.05;
  c.limits.overspeed = 0.08;
  SimRig r(c);
  r.to_holding();
  ASSERT_TRUE(r.command(r.move_to(r.queue_end() + Vec3(-0.2, 0, 0), 0.1)).accepted);
  ASSERT_GE(r.run_until([&] { return r.mode() == Mode::fault; }, 2000), 0);
  const std::int64_t k_fast = r.first_cycle([&](const auto& s) { return v3(s.velocity).norm() > c.limits.overspeed; });
  EXPECT_EQ(r.state().fault_cycle, k_fast);
  expect_report(r.state(), kFaultOverspeed, -1);
  r.run(5);
  expect_safe_from(r, k_fast);
  expect_latched_then_reset(r, kFaultOverspeed);
}

// Row: loop overruns. loop.max_consecutive_overruns in a row latch in the
// next cycle; fewer, or interrupted, do not.
TEST(FaultMatrix, OverrunsSim) {
  SimRig r;  // max_consecutive_overruns = 3
  r.to_holding();
  const int n = r.cfg.loop.max_consecutive_overruns;
  for (int i = 0; i < n - 1; ++i) {
    r.loop->record_schedule(true, 1);
    r.step();
  }
  r.loop->record_schedule(false, 0);  // one good cycle resets the count
  r.step();
  for (int i = 0; i < n - 1; ++i) {
    r.loop->record_schedule(true, 1);
    r.step();
  }
  EXPECT_EQ(r.mode(), Mode::holding);
  r.loop->record_schedule(true, 1);
  const std::int64_t k_next = r.k;
  r.step();
  ASSERT_EQ(r.mode(), Mode::fault);
  EXPECT_EQ(r.state().fault_cycle, k_next);
  expect_report(r.state(), kFaultOverrun, -1);
  EXPECT_EQ(r.state().fault_value, n);
  EXPECT_EQ(r.state().skipped, 2 * (n - 1) + 1);
  r.run(5);
  expect_safe_from(r, k_next);
  expect_latched_then_reset(r, kFaultOverrun);
}

// Enable timeout: the drives do not report operation enabled within
// limits.enable_timeout. Latency floor(T / period) + 1 cycles after enable.
TEST(FaultMatrix, EnableTimeoutSim) {
  DaemonConfig c = test_config();
  c.limits.enable_timeout = 0.1;
  SimRig r(c, /*enable_delay=*/1.0);
  const std::int64_t k_enable = r.k;
  ASSERT_TRUE(r.simple(CommandKind::enable).accepted);
  ASSERT_GE(r.run_until([&] { return r.mode() == Mode::fault; }, 1000), 0);
  EXPECT_EQ(r.state().fault_cycle - k_enable, 101);
  expect_report(r.state(), kFaultEnableTimeout, -1);
  r.run(5);
  expect_safe_from(r, r.state().fault_cycle);
  EXPECT_TRUE(r.simple(CommandKind::reset).accepted);
  EXPECT_EQ(r.mode(), Mode::disabled);
}

// --- Row: LCM silence where a stream was expected (stream underrun).

// A chunk of a stream along -x at `speed`, from `from`, `n` points 10 ms
// apart; its first / last setpoint at rest when asked (else at speed).
Command stream_chunk(const Vec3& from, double speed, int n, bool starts_at_rest, bool ends_at_rest) {
  double t[100], p[100][3], v[100][3];
  for (int i = 0; i < n; ++i) {
    t[i] = 0.01 * i;
    const bool rest = (i == 0 && starts_at_rest) || (i == n - 1 && ends_at_rest);
    p[i][0] = from.x() - speed * t[i];
    p[i][1] = from.y();
    p[i][2] = from.z();
    v[i][0] = rest ? 0.0 : -speed;
    v[i][1] = v[i][2] = 0;
  }
  Command c;
  c.kind = CommandKind::segment;
  c.segment.start = from;
  c.segment.end = Vec3(p[n - 1][0], p[n - 1][1], p[n - 1][2]);
  c.segment.traj.emplace<StreamTrajectory>(n, t, p, v);
  // From rest to speed in one 10 ms step (20 m/s^2): more than the start
  // check allows; the rig grants it, as a bench would (these rows test the
  // underrun, not the start).
  c.segment.allow_step = true;
  return c;
}

// Two chunks of a stream at speed, then nothing: the next chunk is late.
// Detected in the first cycle past the last setpoint; the loop stops along
// the path at limits.stop_deceleration (the reference continuous in position
// and velocity), and latches stream_underrun at rest.
TEST(FaultMatrix, StreamUnderrunStopsAlongThePathThenLatches) {
  SimRig r;
  r.to_holding();
  const double speed = 0.05;
  const Command c1 = stream_chunk(r.queue_end(), speed, 20, true, false);
  const std::int64_t k_start = r.k;  // chunk 1 starts in its command's cycle
  ASSERT_TRUE(r.command(c1).accepted);
  const Command c2 = stream_chunk(c1.segment.end, speed, 20, false, false);
  ASSERT_TRUE(r.command(c2).accepted);
  const double dur = 0.19 * 2;
  ASSERT_GE(r.run_until([&] { return r.mode() == Mode::stopping; }, 1000), 0);
  const std::int64_t k_detect = r.k - 1;
  // The first cycle at or past the stream's last setpoint.
  EXPECT_EQ(k_detect - k_start, static_cast<std::int64_t>(std::ceil(dur * 1e3 - 1e-6)));
  ASSERT_GE(r.run_until([&] { return r.mode() == Mode::fault; }, 1000), 0);
  expect_report(r.state(), kFaultStreamUnderrun, -1);
  EXPECT_EQ(r.state().fault_cycle, k_detect);
  EXPECT_NEAR(r.state().fault_value, speed, 1e-9);  // the speed it ran dry at
  EXPECT_STREQ(fault_bit_name(kFaultStreamUnderrun), "stream_underrun");
  const std::int64_t k_rest = r.k - 1;
  EXPECT_NEAR(static_cast<double>(k_rest - k_detect) * 1e-3, speed / r.cfg.limits.stop_deceleration, 2e-3);
  double max_step = 0, max_dv = 0;
  for (std::int64_t k = k_detect - 20; k <= k_rest; ++k) {
    max_step = std::max(max_step, (v3(r.at(k).position_ref) - v3(r.at(k - 1).position_ref)).norm());
    max_dv = std::max(max_dv, (v3(r.at(k).velocity_ref) - v3(r.at(k - 1).velocity_ref)).norm());
  }
  EXPECT_LE(max_step, speed * 1e-3 * 1.01) << "the reference jumped (m per cycle)";
  EXPECT_LE(max_dv, r.cfg.limits.stop_deceleration * 1e-3 * 1.01 + 1e-9)
      << "the reference velocity jumped (m/s per cycle)";
  // Drives off only at rest.
  EXPECT_LT(v3(r.at(k_rest - 1).velocity_ref).norm(), r.cfg.limits.stop_deceleration * 1e-3 + 1e-9);
  EXPECT_LT(v3(r.at(k_rest).velocity).norm(), 2e-3);
  r.run(5);
  expect_safe_from(r, k_rest);
  expect_latched_then_reset(r, kFaultStreamUnderrun);
}

TEST(FaultMatrix, StreamEndingAtRestIsNoUnderrun) {
  SimRig r;
  r.to_holding();
  ASSERT_TRUE(r.command(stream_chunk(r.queue_end(), 0.01, 30, true, true)).accepted);
  ASSERT_GE(r.run_until([&] { return r.mode() == Mode::holding; }, 1000), 0);
  r.run(50);
  EXPECT_EQ(r.mode(), Mode::holding);
  EXPECT_EQ(r.state().faults, 0);
}

TEST(FaultMatrix, StreamChunksInTimeAreNoUnderrun) {
  SimRig r;
  r.to_holding();
  // Ten chunks of 100 ms at speed, each sent 60 ms after the previous one
  // (the commander keeps ahead, as cpm stream does), the last ending at rest.
  for (int i = 0; i < 10; ++i) {
    ASSERT_TRUE(r.command(stream_chunk(r.queue_end(), 0.05, 11, i == 0, i == 9)).accepted) << i;
    r.run(60);
    EXPECT_EQ(r.state().faults, 0) << "chunk " << i;
  }
  ASSERT_GE(r.run_until([&] { return r.mode() == Mode::holding; }, 2000), 0);
  EXPECT_EQ(r.state().faults, 0);
}

}  // namespace
}  // namespace cpm::daemon::test
