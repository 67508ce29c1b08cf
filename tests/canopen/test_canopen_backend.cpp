// SPDX-License-Identifier: Apache-2.0
// The canopen backend inside cpmd's loop, against three virtual drives that
// share one plant, on the fake bus: bring-up, enable, motion through the
// plant against the in-process simulator, every fault and its safe state.
#include <linux/can/error.h>

#include <cmath>

#include "canopen/circle.hpp"
#include "cpm/sim/closed_loop.hpp"
#include "support/allocation_counter.hpp"

namespace cpm::daemon::test {
namespace {

using hal::cia402::State;

bool contains(const std::string& s, const std::string& part) { return s.find(part) != std::string::npos; }

TEST(CanopenBackend, BringUpReadsThePlantsEncodersAndKeepsEverythingOff) {
  Rig r;
  EXPECT_EQ(r.mode(), Mode::disabled);
  // The first cycles already see the true actuator positions (one SYNC at start-up).
  const sim::EncoderReading e = const_cast<sim::Plant&>(r.vm->plant()).read();
  for (int i = 0; i < 3; ++i) EXPECT_NEAR(r.state().d[i], e.d[i], 1e-7 + 1e-12) << "actuator " << i + 1;  // 1 count
  EXPECT_LT((r.position() - Vec3(0.600, 0.425, 0.300)).norm(), 1e-6);
  // The mapping the master wrote is in the drives (read back at start-up, and here once more).
  for (int i = 0; i < 3; ++i) {
    auto& d = r.vm->drive(i);
    EXPECT_EQ(d.nmt_state(), hal::canopen::NmtState::operational);
    EXPECT_EQ(d.state(), State::switch_on_disabled);
    EXPECT_EQ(d.mode_display(), hal::cia402::kModeCyclicSyncTorque);
    EXPECT_EQ(d.od_value(0x1A00, 1), 0x60410010u);
    EXPECT_EQ(d.od_value(0x1A00, 2), 0x60640020u);
    EXPECT_EQ(d.od_value(0x1600, 2), 0x60710010u);
    EXPECT_EQ(d.od_value(0x6007, 0), 3u);  // abort connection: quick stop
  }
  r.expect_safe_outputs();
  EXPECT_EQ(r.vm->steps(), 0u) << "the plant moved with the drives off";
  EXPECT_NEAR(r.backend->bus_load().load, 0.69, 0.005);
}

TEST(CanopenBackend, EnableCircleAndDisableMatchTheInProcessSimulatorInLockstep) {
  // Lockstep drives apply a torque at once, as the in-process loop does:
  // the bus then changes nothing but the drives' units. (Real drives apply
  // it a SYNC later: DriveTiming, below.)
  Rig r(config_500hz_with_velocity(), true, sim::DriveTiming::lockstep);
  r.to_holding();
  EXPECT_TRUE(r.io.outputs.drive_enable);
  EXPECT_TRUE(r.io.outputs.brake_release_z);
  for (int i = 0; i < 3; ++i) EXPECT_EQ(r.vm->drive(i).state(), State::operation_enabled);

  // Elkady's circle from P1, through the bus, the drives and the plant.
  const ctl::CircleTrajectory circle{ctl::CircleSpec{}};
  Command c;
  c.kind = CommandKind::segment;
  c.segment.start = r.queue_end();
  c.segment.end = circle.sample(circle.duration()).p;
  c.segment.traj = circle;
  c.segment.allow_step = true;  // Elkady's start at speed: a bench with simulated drives
  ASSERT_TRUE(r.command(c).accepted);
  const int n = r.run_until([&] { return r.mode() == Mode::holding; }, static_cast<int>(circle.duration() * 500) + 50);
  ASSERT_GE(n, 0) << "the circle did not finish; " << r.fault_text();
  ASSERT_EQ(r.state().faults, 0) << r.fault_text();
  const double rmse = r.state().last_segment_rmse;

  // The same plant, controller and period in-process.
  sim::Plant plant(r.truth, sim::PlantOptions{});
  ASSERT_TRUE(plant.reset(Vec3(0.600, 0.425, 0.300)));
  const ctl::Controller ctrl(r.model, r.cfg.controller.law, r.cfg.controller.gains);
  sim::LoopOptions lo;
  lo.rate_hz = 500;
  lo.keep_log = false;
  const auto ref = sim::run_closed_loop(ctrl, plant, circle, lo);
  ASSERT_TRUE(ref.ok());
  const double on_sim = circle_on_sim_backend(r.cfg, circle).rmse;
  std::printf("canopen: circle RMSE %.3f um through the bus, %.3f um on the simulator backend, %.3f um in "
              "sim::run_closed_loop (500 Hz)\n", rmse * 1e6, on_sim * 1e6, ref.metrics.position_rmse * 1e6);
  // The same loop on the in-process plant: only the drives' units differ
  // (0.1 um counts, 0.04 N torque steps).
  EXPECT_NEAR(rmse, on_sim, 0.002 * on_sim);
  // The bare closed loop counts its samples slightly differently (first and last).
  EXPECT_NEAR(rmse, ref.metrics.position_rmse, 0.02 * ref.metrics.position_rmse);

  ASSERT_TRUE(r.simple(CommandKind::disable).accepted);
  r.run(3);
  EXPECT_EQ(r.mode(), Mode::disabled);
  r.expect_safe_outputs();
  for (int i = 0; i < 3; ++i) EXPECT_EQ(r.vm->drive(i).state(), State::switch_on_disabled);
  const std::uint64_t steps = r.vm->steps();
  r.run(20);
  EXPECT_EQ(r.vm->steps(), steps) << "the plant moved after the disable";
}

TEST(CanopenBackend, PointToPointAt1kHzWithTheShippedMapping) {
  Rig r;  // velocity differentiated from SYNC-sampled positions
  r.to_holding();
  const Vec3 target(0.45, 0.40, 0.35);
  ASSERT_TRUE(r.command(r.move_to(target, 0.1)).accepted);
  ASSERT_GE(r.run_until([&] { return r.mode() == Mode::holding; }, 6000), 0) << r.fault_text();
  r.run(300);
  EXPECT_EQ(r.state().faults, 0) << r.fault_text();
  EXPECT_LT((r.position() - target).norm(), 10e-6);
  EXPECT_LT((r.vm->plant().position() - target).norm(), 10e-6) << "the true platform is not where the daemon thinks";
  EXPECT_LT(r.state().last_segment_max, 1e-3);
}

// Fault scenarios start here: holding, every drive enabled.
struct Faulted : ::testing::Test {
  Rig r;
  void SetUp() override { r.to_holding(); }
  void expect_fault(std::uint32_t bit, int axis, const std::string& words) {
    EXPECT_EQ(r.mode(), Mode::fault);
    EXPECT_EQ(static_cast<std::uint32_t>(r.state().first_fault), bit) << r.fault_text();
    EXPECT_EQ(r.state().fault_axis, axis);
    EXPECT_TRUE(contains(r.fault_text(), words)) << "fault text: '" << r.fault_text() << "'";
    r.expect_safe_outputs();
  }
};

TEST_F(Faulted, HeartbeatLost) {
  r.vm->drive(1).stop_heartbeat(true);
  const int n = r.run_until([&] { return r.mode() == Mode::fault; }, 400);
  ASSERT_GE(n, 0);
  // Latency: the heartbeat timeout (150 ms) from the last heartbeat (<= 50 ms before).
  EXPECT_LE(n, 150 + 2);
  EXPECT_GE(n, 100);
  expect_fault(kFaultDrive, 1, "drive 2 (y, node 2): heartbeat lost");
  r.run(5);
  for (int i = 0; i < 3; ++i) EXPECT_NE(r.vm->drive(i).state(), State::operation_enabled) << "drive " << i + 1;
  // The cause holds: reset refused; once the heartbeat is back, reset works.
  EXPECT_FALSE(r.simple(CommandKind::reset).accepted);
  r.vm->drive(1).stop_heartbeat(false);
  r.run(60);
  EXPECT_TRUE(r.simple(CommandKind::reset).accepted);
  r.to_holding();
}

TEST_F(Faulted, EmcyFromADrive) {
  r.vm->drive(2).send_emcy(0x2310, 0x03);
  r.run(2);
  expect_fault(kFaultDrive, 2, "0x2310");
  EXPECT_TRUE(contains(r.fault_text(), "drive 3 (z)")) << r.fault_text();
  // A warning EMCY leaves no lasting cause: reset, enable again.
  EXPECT_TRUE(r.simple(CommandKind::reset).accepted);
  r.to_holding();
}

// A drive may clear a transient error at once: the error EMCY and its
// "error reset" EMCY (code 0) reach the master in the same cycle. CANopenNode
// does this (found by the SIL test against it): the error must still fault.
TEST_F(Faulted, EmcyClearedWithinTheCycleStillFaults) {
  r.vm->drive(2).send_emcy(0x2310, 0x03);
  r.vm->drive(2).send_emcy(0x0000, 0x00);
  r.run(2);
  expect_fault(kFaultDrive, 2, "0x2310");
  EXPECT_TRUE(r.simple(CommandKind::reset).accepted);
  r.to_holding();
}

TEST_F(Faulted, DriveFaultBitIsResetOnlyOnceItsCauseIsGone) {
  r.vm->drive(0).inject_fault(0x7121, 0x01, /*persistent=*/true);  // motor blocked
  r.run(3);
  expect_fault(kFaultDrive, 0, "drive 1 (x");
  r.run(10);
  EXPECT_EQ(r.vm->drive(0).state(), State::fault);
  const Ack a = r.simple(CommandKind::reset);
  EXPECT_FALSE(a.accepted);
  EXPECT_TRUE(contains(a.message, "drive")) << a.message;
  r.vm->drive(0).clear_fault();
  r.run(5);  // while disabled the backend resets the drive's fault: back to switch on disabled
  EXPECT_EQ(r.vm->drive(0).state(), State::switch_on_disabled);
  EXPECT_TRUE(r.simple(CommandKind::reset).accepted);
  r.to_holding();
}

TEST_F(Faulted, EstopDisablesEveryDriveAndEngagesTheBrakeInTheSameCycle) {
  r.io.inputs.estop = true;
  r.loop->cycle(r.k++, 0);  // exactly one cycle: the one that reads the open chain
  expect_fault(kFaultEstop, -1, "e-stop");
  // What went on the wire in that cycle: "disable voltage", zero torque, for all three.
  const hal::Feedback& fb = r.backend->feedback();
  (void)fb;
  r.clock.wait(r.period_ns());
  for (int i = 0; i < 3; ++i) {
    EXPECT_EQ(r.vm->drive(i).od_value(0x6040, 0) & 0x0F, 0u) << "controlword of drive " << i + 1;
    EXPECT_EQ(r.vm->drive(i).applied_torque(), 0);
    EXPECT_EQ(r.vm->drive(i).state(), State::switch_on_disabled);
  }
  EXPECT_FALSE(r.simple(CommandKind::reset).accepted);  // the chain is still open
  r.io.inputs.estop = false;
  r.run(1);
  EXPECT_TRUE(r.simple(CommandKind::reset).accepted);
}

TEST_F(Faulted, LimitSwitch) {
  r.io.inputs.limit_high[0] = true;
  r.run(1);
  expect_fault(kFaultLimitSwitch, 0, "limit_high_x");
  // Still on the switch: the operator may reset and enable to move off it.
  EXPECT_TRUE(r.simple(CommandKind::reset).accepted);
  r.to_holding();
  r.io.inputs.limit_high[0] = false;
  r.io.inputs.limit_low[2] = true;
  r.run(1);
  expect_fault(kFaultLimitSwitch, 2, "limit_low_z");
}

TEST_F(Faulted, TpdosMissing) {
  r.net.drop(hal::canopen::kTpdo1Base + 3, 0x7FF, -1);  // drive 3's TPDO1 never arrives
  const int n = r.run_until([&] { return r.mode() == Mode::fault; }, 20);
  ASSERT_GE(n, 0);
  EXPECT_LE(n, r.cfg.canopen.master.pdo_timeout_cycles + 1);
  expect_fault(kFaultDrive, 2, "no TPDO");
}

TEST_F(Faulted, BusOff) {
  r.net.set_bus_off(true);
  r.run(1);
  expect_fault(kFaultBackendIo, -1, "bus-off");
}

TEST_F(Faulted, ErrorPassive) {
  r.net.inject_error_frame(hal::make_error_frame(CAN_ERR_CRTL, CAN_ERR_CRTL_RX_PASSIVE, 0, 0, 130));
  r.run(1);
  expect_fault(kFaultBackendIo, -1, "passive");
}

TEST_F(Faulted, DrivesDisappear) {
  r.vm->disappear(true, r.clock.now_ns());
  const int n = r.run_until([&] { return r.mode() == Mode::fault; }, 20);
  ASSERT_GE(n, 0);
  EXPECT_LE(n, r.cfg.canopen.master.pdo_timeout_cycles + 1);  // the TPDOs stop before the heartbeat times out
  EXPECT_EQ(r.state().first_fault, static_cast<std::int32_t>(kFaultDrive));
  EXPECT_TRUE(contains(r.fault_text(), "no TPDO")) << r.fault_text();
  r.expect_safe_outputs();
  r.run(200);
  EXPECT_TRUE(contains(std::string(r.backend->fault_text()), "heartbeat lost")) << r.backend->fault_text();
}

TEST_F(Faulted, MasterSilentTheDrivesStopOnTheirOwn) {
  // cpmd killed while moving: nothing more from the master. The drives'
  // heartbeat consumer (0x1016, 150 ms) runs 0x6007 = quick stop.
  ASSERT_TRUE(r.command(r.move_to(Vec3(0.50, 0.425, 0.300), 0.1)).accepted);
  r.run(200);
  ASSERT_EQ(r.mode(), Mode::moving);
  for (int i = 0; i < 3; ++i) ASSERT_EQ(r.vm->drive(i).state(), State::operation_enabled);
  r.clock.wait(100'000'000);  // 100 ms: still within the consumer time
  for (int i = 0; i < 3; ++i) EXPECT_EQ(r.vm->drive(i).state(), State::operation_enabled);
  r.clock.wait(100'000'000);  // 200 ms silent in all
  for (int i = 0; i < 3; ++i) {
    EXPECT_NE(r.vm->drive(i).state(), State::operation_enabled) << "drive " << i + 1;
    EXPECT_EQ(r.vm->drive(i).applied_torque(), 0) << "drive " << i + 1;
    EXPECT_GE(r.vm->drive(i).master_heartbeat_timeouts, 1u);
  }
}

TEST(CanopenBackendStart, SdoTimeoutIsRefusedNamingTheDrive) {
  Rig r(canopen_config(), /*start=*/false);
  r.vm->drive(1).answer_late(500'000'000);  // 500 ms, against sdo_timeout_ms 100
  try {
    r.backend->start(1e-3);
    FAIL() << "start() accepted a drive that does not answer SDO in time";
  } catch (const Error& e) {
    const std::string m = e.what();
    EXPECT_TRUE(contains(m, "node 2")) << m;
    EXPECT_TRUE(contains(m, "SDO")) << m;
    EXPECT_TRUE(contains(m, "vcan0") || contains(m, "can0")) << m;
  }
  EXPECT_FALSE(r.io.outputs.drive_enable);
  EXPECT_FALSE(r.io.outputs.brake_release_z);
}

TEST(CanopenBackendStart, MissingDriveIsRefused) {
  Rig r(canopen_config(), /*start=*/false);
  r.vm->drive(2).go_silent(true);
  try {
    r.backend->start(1e-3);
    FAIL() << "start() accepted a silent drive";
  } catch (const Error& e) {
    EXPECT_TRUE(contains(e.what(), "node 3")) << e.what();
  }
}

TEST(CanopenBackendStart, RateMustMatchTheConfiguration) {
  Rig r(canopen_config(), /*start=*/false);
  EXPECT_THROW(r.backend->start(2e-3), Error);
}

TEST(CanopenBackend, NoAllocationPerCycle) {
  Rig r;
  r.to_holding();
  ASSERT_TRUE(r.command(r.move_to(Vec3(0.55, 0.425, 0.300), 0.1)).accepted);
  std::size_t total = 0;
  for (int n = 0; n < 300; ++n) {
    {
      const cpm::test::CountAllocations count;
      r.loop->cycle(r.k++, 0);
      total += count.count();
    }
    while (r.loop->snapshots().front()) r.loop->snapshots().release();
    r.clock.wait(r.period_ns());  // the virtual drives may allocate: not the daemon's cycle
  }
  // Faults and their text too.
  r.vm->drive(1).send_emcy(0x2310, 1);
  r.io.inputs.estop = true;
  for (int n = 0; n < 20; ++n) {
    {
      const cpm::test::CountAllocations count;
      r.loop->cycle(r.k++, 0);
      total += count.count();
    }
    while (r.loop->snapshots().front()) r.loop->snapshots().release();
    r.clock.wait(r.period_ns());
  }
  EXPECT_EQ(r.mode(), Mode::fault);
  EXPECT_EQ(total, 0u);
}

// ---- configuration: refused with file:line:column and the key path.
void expect_refused(const std::vector<std::pair<std::string, std::string>>& edits, const std::string& words) {
  try {
    (void)canopen_config(edits);
    ADD_FAILURE() << "accepted; expected: " << words;
  } catch (const Error& e) {
    EXPECT_TRUE(contains(e.what(), words)) << e.what();
    EXPECT_TRUE(std::regex_search(std::string(e.what()), std::regex("canopen\\.yaml:\\d+:\\d+: "))) << e.what();
  }
}

TEST(CanopenConfig, RefusedWithKeyPaths) {
  expect_refused({{"velocity_from_drive: false", "velocity_from_drive: true"}}, "highest rate for this mapping 819 Hz");
  expect_refused({{"bitrate: 1000000", "bitrate: 900000"}}, "canopen.bitrate: must be a CiA 301 bitrate");
  expect_refused({{"name: y, node_id: 2", "name: y, node_id: 1"}}, "canopen.drives[1].node_id: node id 1 is used twice");
  expect_refused({{"name: z, node_id: 3, counts_per_m: 1.0e7", "name: z, node_id: 3, counts_per_m: -5"}},
                 "canopen.drives[2].counts_per_m");
  expect_refused({{"rated_force: 40, max_torque_permille: 3000, direction: 1, position_offset: 0.0\\}\n    - \\{name: y",
                   "rated_force: 40, max_torque_permille: 3000, direction: 0, position_offset: 0.0}\n    - {name: y"}},
                 "canopen.drives[0].direction: must be 1 or -1");
  expect_refused({{"timeout_ms: 150   ", "timeout_ms: 40    "}}, "canopen.heartbeat.timeout_ms: must exceed");
  expect_refused({{"    estop: .*\n", ""}}, "canopen.gpio.estop: missing");
  expect_refused({{"name: brake_z\\}", "name: brake_z, bogus: 1}"}}, "canopen.gpio.brake_release_z.bogus: unknown key");
  expect_refused({{"limit_high_z:    \\{chip: gpiochip0, name: limit_z_max\\}", "limit_high_z: {active_low: true}"}},
                 "canopen.gpio.limit_high_z: give the line's name");
  expect_refused({{"feedback_wait_ms: 0 ", "feedback_wait_ms: 2 "}}, "canopen.feedback_wait_ms: must be shorter");
  expect_refused({{"  interface: can0\n", ""}}, "canopen.interface: missing");
}

TEST(CanopenConfig, ShippedFilesLoad) {
  const DaemonConfig c = canopen_config();
  EXPECT_EQ(c.backend, "canopen");
  EXPECT_EQ(c.canopen.master.drives.size(), 3u);
  EXPECT_EQ(c.canopen.master.rate_hz, 1000);
  EXPECT_NEAR(c.canopen.load.load, 0.69, 0.005);
  EXPECT_NEAR(c.canopen.load.max_rate_hz, 1160, 1);
  const DaemonConfig s = load_config(std::string(CPM_SOURCE_DIR) + "/config/sil.yaml");
  EXPECT_EQ(s.canopen.interface, "vcan0");
  EXPECT_TRUE(s.canopen.master.velocity_from_drive);
  EXPECT_EQ(s.canopen.gpio[hal::Line::drive_enable].name, "enable");
}

}  // namespace
}  // namespace cpm::daemon::test
