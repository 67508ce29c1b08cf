// SPDX-License-Identifier: Apache-2.0
// The fault matrix (docs/fault-matrix.md), rows the canopen backend detects:
// cpmd's loop, the backend, the hal master and three virtual CiA 402 drives
// on the fake bus (fake clock, fake GPIO). Each test asserts the detection
// latency in cycles, the reaction on the wire and the GPIO (every drive
// "disable voltage" and zero torque, enable output off, z brake engaged),
// the report (bit, axis, text), the latch, and the reset (refused while the
// cause holds; then disabled, setpoint on the measured position, nothing
// jumps when enabled again).
#include <linux/can/error.h>

#include "canopen/rig.hpp"
#include "reliability/fault_rig.hpp"

namespace cpm::daemon::test {
namespace {

using hal::cia402::State;

// The reaction, checked on the drives themselves too: none holds torque.
void expect_safe(Rig& r) {
  r.expect_safe_outputs();
  for (int i = 0; i < 3; ++i) {
    EXPECT_NE(r.vm->drive(i).state(), State::operation_enabled) << "drive " << i + 1;
    EXPECT_EQ(r.vm->drive(i).applied_torque(), 0) << "drive " << i + 1;
  }
}

void expect_report(const Rig& r, std::uint32_t bit, int axis, const std::string& words) {
  EXPECT_EQ(r.mode(), Mode::fault);
  EXPECT_EQ(static_cast<std::uint32_t>(r.state().first_fault), bit) << fault_bit_name(r.state().first_fault);
  EXPECT_EQ(r.state().fault_axis, axis);
  EXPECT_TRUE(has(r.fault_text(), words)) << "fault text '" << r.fault_text() << "'";
}

// Latched `hold` cycles with the cause gone, then reset: disabled, setpoint
// on the measured position, and enabled again it holds without a jump.
void expect_latched_then_reset(Rig& r, int hold = 100) {
  r.run(hold);
  ASSERT_EQ(r.mode(), Mode::fault);
  expect_safe(r);
  const Ack a = r.simple(CommandKind::reset);
  ASSERT_TRUE(a.accepted) << a.message;
  EXPECT_EQ(r.mode(), Mode::disabled);
  EXPECT_EQ(r.state().faults, 0);
  EXPECT_LT((v3(r.state().position_ref) - r.position()).norm(), 1e-12);
  const Vec3 p0 = r.vm->plant().position();
  r.to_holding();
  double jump = 0;
  for (int n = 0; n < 100; ++n) {
    r.step();
    jump = std::max(jump, (v3(r.state().position_ref) - p0).norm());
  }
  EXPECT_LT(jump, 1e-6) << "the setpoint jumped after the reset (m)";  // 1 encoder count is 0.1 um
  EXPECT_LT((r.vm->plant().position() - p0).norm(), 5e-6) << "the platform moved after the reset (m)";
  EXPECT_EQ(r.mode(), Mode::holding);
  EXPECT_EQ(r.state().faults, 0) << r.fault_text();
}

struct Matrix : ::testing::Test {
  Rig r;
  void SetUp() override {
    r.to_holding();
    // Moving, so that a late reaction would show.
    ASSERT_TRUE(r.command(r.move_to(r.queue_end() + Vec3(-0.1, 0, 0), 0.05)).accepted);
    r.run(100);
    ASSERT_EQ(r.mode(), Mode::moving);
  }
};

// Row: a drive's heartbeat lost. Latency: heartbeat.timeout_ms after the
// last heartbeat, which came at most drive_ms before it stopped.
TEST_F(Matrix, HeartbeatLost) {
  const auto& m = r.cfg.canopen.master;
  r.vm->drive(1).stop_heartbeat(true);
  const int n = r.run_until([&] { return r.mode() == Mode::fault; }, 1000);
  ASSERT_GE(n, 0);
  const int bound = (m.heartbeat_timeout_ms + 1) * static_cast<int>(r.cfg.loop.rate_hz) / 1000 + 1;
  const int floor = (m.heartbeat_timeout_ms - m.drive_heartbeat_ms) * static_cast<int>(r.cfg.loop.rate_hz) / 1000;
  std::printf("heartbeat lost: %d cycles (bound %d)\n", n, bound);
  EXPECT_LE(n, bound);
  EXPECT_GE(n, floor);
  expect_report(r, kFaultDrive, 1, "heartbeat lost");
  r.run(3);
  expect_safe(r);
  EXPECT_FALSE(r.simple(CommandKind::reset).accepted) << "reset while the heartbeat is still missing";
  r.vm->drive(1).stop_heartbeat(false);
  r.run(m.drive_heartbeat_ms + 5);
  expect_latched_then_reset(r);
}

// Row: EMCY. Latency 1 cycle (it arrives with the next read).
TEST_F(Matrix, Emcy) {
  r.vm->drive(2).send_emcy(0x3210, 0x04);  // DC link over-voltage
  const int n = r.run_until([&] { return r.mode() == Mode::fault; }, 10);
  ASSERT_GE(n, 0);
  EXPECT_LE(n, 1);
  expect_report(r, kFaultDrive, 2, "0x3210");
  r.run(2);
  expect_safe(r);
  expect_latched_then_reset(r);
}

// Row: a drive's CiA 402 fault bit. Latency 1 cycle (the next TPDO).
TEST_F(Matrix, DriveFaultBit) {
  r.vm->drive(0).inject_fault(0x7121, 0x01, /*persistent=*/true);
  const int n = r.run_until([&] { return r.mode() == Mode::fault; }, 10);
  ASSERT_GE(n, 0);
  EXPECT_LE(n, 1);
  expect_report(r, kFaultDrive, 0, "drive 1 (x");
  r.run(5);
  expect_safe(r);
  const Ack a = r.simple(CommandKind::reset);
  EXPECT_FALSE(a.accepted);
  EXPECT_TRUE(has(a.message, "drive")) << a.message;
  r.vm->drive(0).clear_fault();
  r.run(5);
  expect_latched_then_reset(r);
}

// Row: TPDOs missing (a drive silent on the bus). Latency pdo_timeout_cycles.
TEST_F(Matrix, TpdosMissing) {
  r.net.drop(hal::canopen::kTpdo1Base + 2, 0x7FF, -1);
  const int n = r.run_until([&] { return r.mode() == Mode::fault; }, 50);
  ASSERT_GE(n, 0);
  EXPECT_LE(n, r.cfg.canopen.master.pdo_timeout_cycles + 1);
  expect_report(r, kFaultDrive, 1, "no TPDO");
  r.net.clear_faults();
  r.run(5);
  expect_latched_then_reset(r);
}

// Row: CAN bus-off. Latency 1 cycle (the error frame, or the failed send).
TEST_F(Matrix, BusOff) {
  r.net.set_bus_off(true);
  const int n = r.run_until([&] { return r.mode() == Mode::fault; }, 10);
  ASSERT_GE(n, 0);
  EXPECT_LE(n, 1);
  expect_report(r, kFaultBackendIo, -1, "bus-off");
  // The GPIO still works: enable off and the brake on, whatever the bus.
  r.run(3);
  r.expect_safe_outputs();
  r.net.set_bus_off(false);
  // The drives lost their master for the bus-off: their own consumer quick stops them.
  r.run(300);
  expect_latched_then_reset(r);
}

// Row: CAN error passive. Latency 1 cycle.
TEST_F(Matrix, ErrorPassive) {
  r.net.inject_error_frame(hal::make_error_frame(CAN_ERR_CRTL, CAN_ERR_CRTL_TX_PASSIVE, 0, 0, 128));
  const int n = r.run_until([&] { return r.mode() == Mode::fault; }, 10);
  ASSERT_GE(n, 0);
  EXPECT_LE(n, 1);
  expect_report(r, kFaultBackendIo, -1, "passive");
  r.run(3);
  expect_safe(r);
  // Back to error active (the controller's counters fell), then reset.
  r.net.inject_error_frame(hal::make_error_frame(CAN_ERR_CRTL, CAN_ERR_CRTL_ACTIVE, 0, 0, 0));
  r.run(2);
  expect_latched_then_reset(r);
}

// Row: e-stop (GPIO). Latency 0 cycles: the read that sees the chain open
// disables every drive and engages the brake in the same cycle's write.
TEST_F(Matrix, Estop) {
  r.io.inputs.estop = true;
  r.loop->cycle(r.k++, 0);
  expect_report(r, kFaultEstop, -1, "e-stop");
  r.expect_safe_outputs();
  r.clock.wait(r.period_ns());
  expect_safe(r);
  EXPECT_FALSE(r.simple(CommandKind::reset).accepted);
  r.io.inputs.estop = false;
  expect_latched_then_reset(r);
}

// Row: limit switch. Latency 0 cycles.
TEST_F(Matrix, LimitSwitch) {
  r.io.inputs.limit_low[0] = true;
  r.loop->cycle(r.k++, 0);
  expect_report(r, kFaultLimitSwitch, 0, "limit_low_x");
  r.expect_safe_outputs();
  r.clock.wait(r.period_ns());
  r.io.inputs.limit_low[0] = false;
  expect_latched_then_reset(r);
}

// Row: backend I/O error (GPIO read fails: the e-stop is taken as open).
// Latency 0 cycles.
TEST_F(Matrix, GpioReadFails) {
  r.io.fail_reads = true;
  r.loop->cycle(r.k++, 0);
  expect_report(r, kFaultBackendIo, -1, "GPIO read failed");
  EXPECT_EQ(static_cast<std::uint32_t>(r.state().faults) & kFaultEstop, kFaultEstop);
  r.clock.wait(r.period_ns());
  for (int i = 0; i < 3; ++i) EXPECT_EQ(r.backend->commands().drive[i].target, hal::cia402::Target::disabled);
  r.io.fail_reads = false;
  r.run(2);
  expect_latched_then_reset(r);
}

// Row: SDO timeout at start-up. start() throws naming the drive and the
// object; cpmd exits non-zero before the loop runs (nothing was enabled).
TEST(MatrixStart, SdoTimeoutAtStartUp) {
  Rig r(canopen_config(), /*start=*/false);
  r.vm->drive(2).answer_late(300'000'000);
  try {
    r.backend->start(1e-3);
    FAIL() << "start() accepted a drive that answers SDO too late";
  } catch (const Error& e) {
    const std::string m = e.what();
    EXPECT_TRUE(has(m, "node 3")) << m;
    EXPECT_TRUE(has(m, "SDO timeout")) << m;
    EXPECT_TRUE(has(m, "0x")) << m;  // the object
  }
  EXPECT_FALSE(r.io.outputs.drive_enable);
  EXPECT_FALSE(r.io.outputs.brake_release_z);
  for (int i = 0; i < 3; ++i) EXPECT_NE(r.vm->drive(i).state(), State::operation_enabled);
  EXPECT_EQ(r.vm->steps(), 0u);
}

// Restart safety, the drives' half: the master goes silent (cpmd killed)
// while moving; within the consumer time (0x1016) each drive runs its abort
// connection option (0x6007 = quick stop) and holds no torque; the plant
// comes to rest. A new master then starts them disabled.
TEST(MatrixRestart, MasterSilentDrivesQuickStopThenANewMasterStartsDisabled) {
  Rig r;
  r.to_holding();
  ASSERT_TRUE(r.command(r.move_to(Vec3(0.50, 0.425, 0.300), 0.1)).accepted);
  r.run(300);
  ASSERT_EQ(r.mode(), Mode::moving);
  const int consumer_ms = r.cfg.canopen.master.drive_consumer_timeout_ms;
  // SIGKILL: nothing more from this master, ever. 1 ms steps of the fake clock.
  int stopped_after_ms = -1;
  for (int ms = 1; ms <= 1000 && stopped_after_ms < 0; ++ms) {
    r.clock.wait(1'000'000);
    bool all = true;
    for (int i = 0; i < 3; ++i) all = all && r.vm->drive(i).state() != State::operation_enabled;
    if (all) stopped_after_ms = ms;
  }
  std::printf("master silent: drives left operation enabled after %d ms (consumer time %d ms)\n", stopped_after_ms,
              consumer_ms);
  ASSERT_GE(stopped_after_ms, 0) << "the drives never stopped on their own";
  EXPECT_LE(stopped_after_ms, consumer_ms + r.cfg.canopen.master.master_heartbeat_ms + 2);
  EXPECT_GE(stopped_after_ms, consumer_ms - r.cfg.canopen.master.master_heartbeat_ms);
  r.clock.wait(500'000'000);
  for (int i = 0; i < 3; ++i) {
    EXPECT_EQ(r.vm->drive(i).applied_torque(), 0) << "drive " << i + 1;
    EXPECT_GE(r.vm->drive(i).master_heartbeat_timeouts, 1u);
  }
  const std::uint64_t steps = r.vm->steps();
  r.clock.wait(200'000'000);
  EXPECT_EQ(r.vm->steps(), steps) << "the plant still moves with no master";

  // The restarted cpmd: a new backend and loop on the same drives.
  r.backend.reset();
  hal::FakeCanPort& port2 = r.net.add_port("cpmd-2");
  auto backend2 = std::make_unique<CanopenBackend>(r.cfg.canopen, port2, r.clock, r.io);
  backend2->start(1.0 / r.cfg.loop.rate_hz);
  ControlLoop loop2(r.cfg, *backend2, r.model, ctl::Controller(r.model, r.cfg.controller.law, r.cfg.controller.gains));
  for (int n = 0; n < 500; ++n) {
    loop2.cycle(n, 0);
    while (loop2.snapshots().front()) loop2.snapshots().release();
    r.clock.wait(r.period_ns());
    ASSERT_EQ(loop2.mode(), Mode::disabled) << "cycle " << n;
    ASSERT_FALSE(r.io.outputs.drive_enable);
    ASSERT_FALSE(r.io.outputs.brake_release_z);
  }
  for (int i = 0; i < 3; ++i) EXPECT_NE(r.vm->drive(i).state(), State::operation_enabled);
  EXPECT_EQ(r.vm->steps(), steps) << "the plant moved after the restart";
  const Vec3 p = v3(loop2.last_state().position);
  EXPECT_LT((v3(loop2.last_state().position_ref) - p).norm(), 1e-12) << "setpoint not on the measured position";
  backend2->stop();
}

}  // namespace
}  // namespace cpm::daemon::test
