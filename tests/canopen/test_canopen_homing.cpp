// SPDX-License-Identifier: Apache-2.0
// Homing with the drives' own homing mode through cpmd's canopen backend,
// hal::Master and the virtual machine (three virtual drives, one plant of
// the true machine, incremental encoders, home and limit switches wired to
// the drives) on the fake bus. The test plays the loop's part: it asks the
// backend for homing on an axis and holds the others (the loop's homing
// sequence is not this test's). Also: the backend's mapping of the drive's
// homing status, position lost, the GPIO homing lines, and diagnostics().
#include <linux/can/error.h>

#include <cmath>

#include "canopen/rig.hpp"
#include "cpm/sim/virtual_drives_control.hpp"
#include "support/allocation_counter.hpp"

namespace cpm::daemon::test {
namespace {

using hal::cia402::State;

constexpr double kSearch = 0.02, kZero = 0.002, kAccel = 0.2;  // m/s, m/s^2
constexpr double kPeriod = 1e-3, kCount = 1e-7;                // 1 kHz, 0.1 um counts
constexpr double kHomeSwitch = 0.010;                          // the virtual machine's default (m of d)

bool contains(const std::string& s, const std::string& part) { return s.find(part) != std::string::npos; }

// config/canopen.yaml with the drive's homing on the given actuators.
DaemonConfig homing_config(std::initializer_list<int> axes, int method = 21, double offset = 0.0125) {
  DaemonConfig c = canopen_config();
  for (int a : axes) c.canopen.master.drives[static_cast<std::size_t>(a)].homing = {true, method, kSearch, kZero, kAccel, offset};
  return c;
}

// The backend cycle by cycle, the test in the loop's place: every axis the
// test does not home is held where it was enabled (PD with the actuator
// gains of docs/operating.md, plus the true machine's holding force).
struct Bench {
  Rig r;
  BackendInput in;
  BackendOutput out;
  std::int64_t k = 0;
  Vec3 hold = Vec3::Zero();
  bool holding = false;

  explicit Bench(const DaemonConfig& c, bool incremental = true, double index_pitch = 0)
      : r(c, false, sim::DriveTiming::synchronous, ctl::MachineModel::elkady(), {},
          [incremental, index_pitch](sim::VirtualMachineConfig& vc) {
            vc.incremental = incremental;
            vc.index_pitch = index_pitch;
          }) {
    r.backend->start(1.0 / r.cfg.loop.rate_hz);
  }
  void step() {
    ASSERT_EQ(r.backend->read(k, in), BackendResult::ok) << r.backend->fault_text();
    Vec3 weight = Vec3::Zero();
    (void)r.truth.holding_command(r.vm->plant().position(), r.vm->plant().kinematic_inputs(), weight);
    const bool all = in.drive_enabled[0] && in.drive_enabled[1] && in.drive_enabled[2];
    if (all && !holding) {
      for (int i = 0; i < 3; ++i) hold[i] = in.position[static_cast<std::size_t>(i)];
      holding = true;
    }
    for (std::size_t i = 0; i < 3; ++i) {
      const int a = static_cast<int>(i);
      out.force[i] = weight[a] + (holding ? 12691.0 * (hold[a] - in.position[i]) - 436.0 * in.velocity[i] : 0.0);
    }
    ASSERT_EQ(r.backend->write(k, out), BackendResult::ok) << r.backend->fault_text();
    ++k;
    r.clock.wait(r.period_ns());
  }
  void steps(int n) {
    for (int i = 0; i < n; ++i) step();
  }
  void enable() {
    out.enable = true;
    for (int n = 0; n < 50 && !holding; ++n) step();
    ASSERT_TRUE(holding) << r.backend->fault_text();
    steps(20);  // the brake opened, the platform settled
  }
  // Home actuator `a` with the drive until the backend says attained or
  // error; returns the cycles, -1 if neither came.
  int home(std::size_t a, int limit = 20000) {
    out.axis_drive[a] = AxisDrive::homing;
    out.start_homing[a] = true;
    for (int n = 0; n < limit; ++n) {
      step();
      if (in.drive_homing[a] == DriveHoming::attained || in.drive_homing[a] == DriveHoming::error) return n;
    }
    return -1;
  }
  double true_d(int a) const {
    Vec3 d, d_dot;
    (void)r.vm->plant().actuator_state(d, d_dot);
    return d[a];
  }
};

// Incremental encoders count from 0 where the carriages stand: the daemon
// reads position_offset (0) for every actuator whatever the platform's
// pose. The z drive homes on the machine's home switch with method 21 (its
// edge, left moving up) under the platform's weight; the backend says
// attained only once the drive is at rest at home, and from then on the
// position it reports is the true displacement plus what the offset says.
TEST(CanopenHoming, ZHomesOnItsSwitchUnderGravityAndTheCountsBecomeTrue) {
  Bench b(homing_config({2}));
  b.step();
  const Vec3 d0(b.true_d(0), b.true_d(1), b.true_d(2));
  for (std::size_t i = 0; i < 3; ++i) EXPECT_NEAR(b.in.position[i], 0.0, kCount) << "incremental: counts start at 0";
  EXPECT_GT(d0[2], 0.05);  // the platform is far from z's switch
  EXPECT_TRUE(b.r.backend->drive_homing_supported(2));
  EXPECT_FALSE(b.r.backend->drive_homing_supported(0));
  EXPECT_FALSE(b.r.backend->drive_homing_supported(5));
  b.enable();
  EXPECT_EQ(b.in.drive_homing[2], DriveHoming::idle);
  std::vector<DriveHoming> seen;
  b.out.axis_drive[2] = AxisDrive::homing;
  b.out.start_homing[2] = true;
  int n = 0;
  double max_x_error = 0;
  for (; n < 20000; ++n) {
    b.step();
    if (seen.empty() || seen.back() != b.in.drive_homing[2]) seen.push_back(b.in.drive_homing[2]);
    max_x_error = std::max(max_x_error, std::abs(b.true_d(0) - d0[0]));
    if (b.in.drive_homing[2] != DriveHoming::running && b.in.drive_homing[2] != DriveHoming::idle) break;
  }
  ASSERT_EQ(b.in.drive_homing[2], DriveHoming::attained) << b.r.backend->fault_text();
  // Idle until the drive shows mode 6, running, attained: never attained
  // while moving, nothing else on the way.
  EXPECT_EQ(seen, (std::vector<DriveHoming>{DriveHoming::idle, DriveHoming::running, DriveHoming::attained}));
  std::printf("canopen homing: z homed in %d cycles (%.2f s), x held within %.2f um\n", n, n * kPeriod, max_x_error * 1e6);
  // Attained only at rest at home: the counts say the offset, the platform stands on the edge.
  const double offset = 0.0125;
  EXPECT_NEAR(b.in.position[2], offset, kZero * kPeriod + kCount);
  EXPECT_NEAR(b.in.velocity[2], 0.0, 0.05 * kZero + kCount / kPeriod);
  const double d = b.true_d(2);
  EXPECT_GE(d - kHomeSwitch, -2 * kCount);
  EXPECT_LE(d - kHomeSwitch, 2 * kZero * kPeriod + 2 * kCount);
  // From now on the counts are the true displacement shifted by the offset
  // minus the home: within one period at the speed for zero of the edge.
  const double shift = b.in.position[2] - d;  // offset - home
  EXPECT_NEAR(shift, offset - kHomeSwitch, kZero * kPeriod + 2 * kCount);
  // The drive holds the weight at home.
  b.steps(500);
  EXPECT_EQ(b.in.drive_homing[2], DriveHoming::attained);
  EXPECT_NEAR(b.true_d(2), d, kZero * kPeriod + 2 * kCount);
  EXPECT_FALSE(b.r.vm->plant_failed());
  // Back to torque: the loop's holding force takes over where the drive is.
  b.hold[2] = b.in.position[2];
  b.out.axis_drive[2] = AxisDrive::torque;
  b.out.start_homing[2] = false;
  b.steps(300);
  EXPECT_EQ(b.in.drive_homing[2], DriveHoming::idle);
  EXPECT_EQ(b.r.vm->drive(2).mode_display(), hal::cia402::kModeCyclicSyncTorque);
  EXPECT_NEAR(b.in.position[2] - b.true_d(2), shift, 2 * kCount);  // the redefinition stays
  EXPECT_NEAR(b.true_d(2), d, 20e-6);
}

// Method 5 on the machine's index (one every 4 mm of d): the home is the
// first index above where the home switch releases (10 mm): 12 mm, exactly
// (the drive captures the index where it is).
TEST(CanopenHoming, IndexMethodHomesOnTheFirstIndexPastTheSwitch) {
  Bench b(homing_config({2}, 5), true, 0.004);
  b.enable();
  ASSERT_GE(b.home(2), 0) << b.r.backend->fault_text();
  ASSERT_EQ(b.in.drive_homing[2], DriveHoming::attained);
  const double shift = b.in.position[2] - b.true_d(2);
  EXPECT_NEAR(shift, 0.0125 - 0.012, 2 * kCount);
  EXPECT_NEAR(b.true_d(2), 0.012, kZero * kPeriod + 2 * kCount);
}

// The control socket's words for it.
TEST(CanopenHoming, HomeSwitchFaultFromTheControlProtocol) {
  Bench b(homing_config({2}));
  bool quit = false;
  EXPECT_EQ(sim::execute_control(*b.r.vm, "home-switch z dead", 0, quit), "ok home-switch z dead");
  EXPECT_TRUE(contains(sim::execute_control(*b.r.vm, "home-switch z maybe", 0, quit), "error: home-switch: expected dead or ok"));
  EXPECT_TRUE(contains(sim::execute_control(*b.r.vm, "home-switch 4 dead", 0, quit), "error: axis must be"));
  b.enable();
  ASSERT_GE(b.home(2), 0);
  EXPECT_EQ(b.in.drive_homing[2], DriveHoming::error);
  // Mended, a new start (bit 4 dropped and raised) homes. The error stays
  // (bit 4 falling does not clear it) until the drive starts again: the
  // cycle that raises start_homing still reads it, the next reads running.
  EXPECT_EQ(sim::execute_control(*b.r.vm, "home-switch 3 ok", 0, quit), "ok home-switch 3 ok");
  b.out.start_homing[2] = false;
  b.steps(3);
  EXPECT_EQ(b.in.drive_homing[2], DriveHoming::error);
  b.out.start_homing[2] = true;
  b.step();
  EXPECT_EQ(b.in.drive_homing[2], DriveHoming::error);
  b.step();
  EXPECT_EQ(b.in.drive_homing[2], DriveHoming::running);
  ASSERT_GE(b.home(2), 0);
  EXPECT_EQ(b.in.drive_homing[2], DriveHoming::attained) << b.r.backend->fault_text();
  // From below the switch (inside it) straight up out of it: the first
  // motion, at the speed for switch.
  EXPECT_GE(b.true_d(2) - kHomeSwitch, -2 * kCount);
  EXPECT_LE(b.true_d(2) - kHomeSwitch, kSearch * kPeriod + 2 * kCount);
}

// The home switch never actuates (virtual-drives: "home-switch z dead"):
// the search runs down to z's low limit switch, 3 mm inside the stroke:
// homing error, the drive stops and holds, the backend says error with a
// line people read, and the platform never left the strokes.
TEST(CanopenHoming, DeadHomeSwitchEndsInHomingErrorAtTheLimitSwitch) {
  Bench b(homing_config({2}));
  b.r.vm->break_home_switch(2, true);
  b.enable();
  ASSERT_GE(b.home(2), 0);
  EXPECT_EQ(b.in.drive_homing[2], DriveHoming::error);
  EXPECT_TRUE(contains(b.r.backend->fault_text(), "drive 3 (z, node 3): homing error (statusword 0x"))
      << b.r.backend->fault_text();
  EXPECT_TRUE(b.in.statusword[2] & hal::cia402::kSwHomingError);
  EXPECT_FALSE(b.in.drive_fault[2]) << "a homing error is not a drive fault";
  b.steps(500);
  EXPECT_EQ(b.in.drive_homing[2], DriveHoming::error);
  const double d = b.true_d(2);
  // Past the limit switch by the braking distance v^2 / 2a (1 mm), plus
  // the period it is seen in, the period the drive's torque waits for the
  // next SYNC, and its velocity loop's lag behind the braking profile: a
  // few periods at the search speed (measured: 63 um, 3 periods).
  EXPECT_LT(d, 0.003);
  EXPECT_GT(d, 0.003 - kSearch * kSearch / (2 * kAccel) - 5 * kSearch * kPeriod);
  EXPECT_FALSE(b.r.vm->plant_failed());
  char line[64];
  std::snprintf(line, sizeof line, "(statusword 0x%04X)", b.in.statusword[2]);
  EXPECT_TRUE(contains(b.r.backend->fault_text(), line)) << b.r.backend->fault_text();
}

// A drive fault during homing ends in fault as in torque mode; bit 4
// dropped (the loop stops asking) interrupts: the backend says running (the
// loop's timeout decides), the drive stops and holds.
TEST(CanopenHoming, FaultAndInterruptionDuringHoming) {
  {
    Bench b(homing_config({2}));
    b.enable();
    EXPECT_EQ(b.home(2, 200), -1);
    EXPECT_EQ(b.in.drive_homing[2], DriveHoming::running);
    b.r.vm->drive(2).inject_fault(0x2310, 0x03);
    b.step();  // the EMCY
    EXPECT_TRUE(b.in.drive_fault[2]);
    EXPECT_TRUE(contains(b.r.backend->fault_text(), "EMCY 0x2310")) << b.r.backend->fault_text();
    b.step();  // the statusword of the SYNC after it
    EXPECT_TRUE(b.in.drive_fault[2]);
    EXPECT_EQ(b.in.drive_homing[2], DriveHoming::idle);
    EXPECT_TRUE(contains(b.r.backend->fault_text(), "CiA 402 fault")) << b.r.backend->fault_text();
    EXPECT_EQ(b.r.vm->drive(2).applied_torque(), 0);
  }
  {
    Bench b(homing_config({2}));
    b.enable();
    EXPECT_EQ(b.home(2, 500), -1);
    b.out.start_homing[2] = false;
    b.steps(3);
    EXPECT_EQ(b.r.backend->feedback().drive[2].homing, hal::cia402::HomingStatus::interrupted);
    EXPECT_EQ(b.in.drive_homing[2], DriveHoming::running);
    b.steps(600);  // stopped (0.1 s) and settled on the position where it stopped
    const double stopped = b.true_d(2);
    b.steps(300);
    EXPECT_NEAR(b.true_d(2), stopped, 5 * kCount);
    EXPECT_GT(stopped, kHomeSwitch);
    EXPECT_EQ(b.r.vm->drive(2).position_shift(), 0);
  }
}

// A drive that boots again lost its counts: position_lost for one read.
// With incremental encoders the counts restart at 0 where the carriage is.
TEST(CanopenHoming, DrivesThatBootAgainReportPositionLost) {
  Bench b(homing_config({2}));
  b.steps(5);
  for (std::size_t i = 0; i < 3; ++i) EXPECT_FALSE(b.in.position_lost[i]);
  b.r.vm->disappear(true, b.r.clock.now_ns());
  b.r.vm->disappear(false, b.r.clock.now_ns());  // power back: boot-up
  b.r.backend->read(b.k, b.in);
  for (std::size_t i = 0; i < 3; ++i) EXPECT_TRUE(b.in.position_lost[i]) << i;
  b.r.clock.wait(b.r.period_ns());
  b.r.backend->read(b.k, b.in);
  for (std::size_t i = 0; i < 3; ++i) EXPECT_FALSE(b.in.position_lost[i]) << i;
}

// What the loop and the commissioning view get from the backend.
TEST(CanopenHoming, HomingLinesStatusesAndDiagnostics) {
  Bench b(homing_config({2}), false);
  b.r.io.inputs.home = {true, false, true};
  b.r.io.inputs.index = {false, true, false};
  b.r.io.inputs.limit_high = {false, true, false};
  b.step();
  EXPECT_EQ(b.in.home_switch, (std::array<bool, 3>{true, false, true}));
  EXPECT_EQ(b.in.index_pulse, (std::array<bool, 3>{false, true, false}));
  EXPECT_TRUE(b.in.digital_inputs & (1u << static_cast<unsigned>(hal::Line::home_x)));
  EXPECT_TRUE(b.in.digital_inputs & (1u << static_cast<unsigned>(hal::Line::home_z)));
  EXPECT_TRUE(b.in.digital_inputs & (1u << static_cast<unsigned>(hal::Line::index_y)));
  EXPECT_FALSE(b.in.digital_inputs & (1u << static_cast<unsigned>(hal::Line::home_y)));
  b.r.io.inputs.limit_high = {};
  b.steps(2);

  BackendDiagnostics g;
  b.r.backend->diagnostics(g);
  EXPECT_EQ(g.backend, 1);  // drives_t.BACKEND_CANOPEN
  for (std::size_t i = 0; i < 3; ++i) {
    EXPECT_EQ(g.drive[i].node_id, static_cast<int>(i) + 1);
    EXPECT_EQ(g.drive[i].nmt, 5);     // NMT_OPERATIONAL
    EXPECT_EQ(g.drive[i].cia402, 1);  // CIA402_SWITCH_ON_DISABLED
    EXPECT_EQ(g.drive[i].statusword, b.r.backend->feedback().drive[i].statusword);
    EXPECT_EQ(g.drive[i].controlword, 0);  // disable voltage
    EXPECT_GE(g.drive[i].heartbeat_age_ns, 0);
    EXPECT_LE(g.drive[i].heartbeat_age_ns, 50'000'000 + b.r.period_ns());
    EXPECT_EQ(g.drive[i].master_faults, 0u);
    EXPECT_EQ(g.drive[i].emcy_count, 0u);
  }
  EXPECT_EQ(g.drive[0].mode_display, 0);   // not mapped: no homing on x
  EXPECT_EQ(g.drive[2].mode_display, 10);  // mapped on z
  EXPECT_EQ(g.bus_state, 0);               // BUS_ERROR_ACTIVE
  EXPECT_EQ(g.tx_error_counter, -1);       // no error frame yet
  EXPECT_EQ(g.rx_error_counter, -1);
  // 1 kHz, 1 Mbit/s: 685 bits + 20 for z's two mode bytes, heartbeats 5.2 bits per cycle.
  EXPECT_NEAR(g.bus_load, (705 + 5.2) / 1000, 1e-9);
  EXPECT_FALSE(g.estop);
  EXPECT_EQ(g.home_switch, (std::array<bool, 3>{true, false, true}));

  b.enable();
  b.out.axis_drive[2] = AxisDrive::homing;
  b.steps(3);
  b.r.vm->drive(1).send_emcy(0x2310, 0x03);
  b.r.net.inject_error_frame(hal::make_error_frame(CAN_ERR_CRTL, CAN_ERR_CRTL_RX_WARNING, 0, 12, 97));
  b.r.backend->read(b.k, b.in);
  b.r.backend->diagnostics(g);
  EXPECT_EQ(g.drive[2].cia402, 4);  // CIA402_OPERATION_ENABLED
  EXPECT_EQ(g.drive[2].mode_display, 6);
  EXPECT_EQ(g.drive[2].controlword & 0x0F, 0x0F);  // enable operation; bit 4 low: not started
  EXPECT_EQ(b.in.drive_homing[2], DriveHoming::running);  // "not started" is the loop's to time out
  EXPECT_EQ(g.drive[1].emcy_count, 1u);
  EXPECT_EQ(g.drive[1].last_emcy_code, 0x2310);
  EXPECT_EQ(g.drive[1].last_emcy_register, 0x03);
  EXPECT_NE(g.drive[1].master_faults & hal::kFaultEmcy, 0u);
  EXPECT_EQ(g.tx_error_counter, 12);
  EXPECT_EQ(g.rx_error_counter, 97);
  EXPECT_GE(g.error_frames, 1u);
  EXPECT_EQ(g.bus_state, 1);  // BUS_ERROR_WARNING

  // The simulator's default is what a backend without diagnostics gives.
  struct Plain final : Backend {
    const char* name() const noexcept override { return "plain"; }
    void start(double) override {}
    void stop() noexcept override {}
    BackendResult read(std::int64_t, BackendInput&) noexcept override { return BackendResult::ok; }
    BackendResult write(std::int64_t, const BackendOutput&) noexcept override { return BackendResult::ok; }
  } plain;
  plain.diagnostics(g);
  EXPECT_EQ(g.drive[2].node_id, 0);
}

// The backend's cycle allocates nothing through a homing to its error (the
// fault text included) and the diagnostics of the commissioning view.
TEST(CanopenHoming, NoAllocationPerCycleWhileHoming) {
  Bench b(homing_config({0, 2}));
  b.r.vm->break_home_switch(2, true);
  b.enable();
  b.out.axis_drive = {AxisDrive::homing, AxisDrive::torque, AxisDrive::homing};
  b.out.start_homing = {true, false, true};
  std::size_t total = 0;
  BackendDiagnostics g;
  for (int n = 0; n < 4000 && b.in.drive_homing[2] != DriveHoming::error; ++n) {
    {
      const cpm::test::CountAllocations count;
      (void)b.r.backend->read(b.k, b.in);
      b.r.backend->diagnostics(g);
      (void)b.r.backend->write(b.k, b.out);
      total += count.count();
    }
    ++b.k;
    b.r.clock.wait(b.r.period_ns());  // the virtual drives may allocate: not the daemon's cycle
  }
  EXPECT_EQ(b.in.drive_homing[2], DriveHoming::error);
  EXPECT_NE(b.in.drive_homing[0], DriveHoming::idle);
  EXPECT_EQ(total, 0u);
}

// A drive without homing asked for homing stays in torque: the force acts.
TEST(CanopenHoming, HomingAskedOfADriveWithoutItIsTorque) {
  Bench b(homing_config({2}));
  b.enable();
  b.out.axis_drive[0] = AxisDrive::homing;
  b.out.start_homing[0] = true;
  b.steps(5);
  EXPECT_EQ(b.r.vm->drive(0).mode_display(), hal::cia402::kModeCyclicSyncTorque);
  EXPECT_EQ(b.in.drive_homing[0], DriveHoming::idle);
  // The master sends the holding force (3.7 N of the platform's weight, plus the PD): the drive applies it.
  EXPECT_NE(b.r.vm->drive(0).applied_torque(), 0);
  EXPECT_EQ(b.r.vm->drive(0).applied_torque(), b.r.backend->feedback().drive[0].torque_permille);
}

}  // namespace
}  // namespace cpm::daemon::test
