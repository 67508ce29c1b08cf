// SPDX-License-Identifier: Apache-2.0
// CiA 402 homing through the master, the virtual drive and a mass on each
// axis (tests/hal/rig.hpp): every method the virtual drive has ends where
// the standard puts the home, with the counts redefined to the home offset;
// the failures (switch never found, drive fault, bit 4 dropped); a load held
// through the switch into homing mode; the master's rising edge of bit 4;
// the mapping and bus load of a homing drive; position lost at a reboot.
#include <gtest/gtest.h>

#include <cmath>
#include <string>

#include "rig.hpp"

using namespace cpm::hal;
using namespace cpm::hal::test;
using cia402::HomingStatus;
using cia402::State;
using cia402::Target;

namespace {

// m/s, m/s^2, m. The rig runs at 500 Hz with 1 um counts.
constexpr double kSearch = 0.02, kZero = 0.002, kAccel = 0.2, kOffset = 0.123;
constexpr double kPeriod = 1.0 / 500, kCount = 1e-6;

MasterConfig homing_drives(int method, double rate_hz = 500) {
  MasterConfig c = three_drives(rate_hz, false);
  for (auto& d : c.drives) {
    d.homing.enabled = true;
    d.homing.method = method;
    d.homing.speed_search_mps = kSearch;
    d.homing.speed_zero_mps = kZero;
    d.homing.acceleration_mps2 = kAccel;
    d.homing.offset_m = kOffset;
  }
  return c;
}

// Switches planted on an axis of the rig: limit switches 5 mm inside a
// 0..0.4 m stroke, an index every 4 mm, a home switch edge at 50 mm.
constexpr double kLimitLow = 0.005, kLimitHigh = 0.395, kPitch = 0.004, kEdge = 0.050;
AxisSensors planted(bool negative_home_switch) {
  AxisSensors s;
  s.limit_low = kLimitLow;
  s.limit_high = kLimitHigh;
  s.index_pitch = kPitch;
  if (negative_home_switch) s.home_below = kEdge;
  else s.home_above = kEdge;
  return s;
}

struct Homing {
  std::vector<HomingStatus> seen;  // each change of DriveFeedback::homing
  int cycles = -1;                 // until completed or error
};
// Enable every drive, then home drive `i` until it completes or fails.
Homing home(Rig& r, std::size_t i, int limit = 20000) {
  r.target_all(Target::enabled);
  EXPECT_GE(r.until_all(State::operation_enabled), 0);
  r.cmd.drive[i].homing = true;
  r.cmd.drive[i].start_homing = true;
  Homing h;
  for (int k = 0; k < limit; ++k) {
    r.cycle();
    const HomingStatus s = r.fb.drive[i].homing;
    if (h.seen.empty() || h.seen.back() != s) h.seen.push_back(s);
    if (s == HomingStatus::completed || s == HomingStatus::error) {
      h.cycles = k;
      break;
    }
  }
  return h;
}

std::string describe(const Homing& h) {
  std::string s;
  for (auto x : h.seen) s += std::string(s.empty() ? "" : " -> ") + cia402::homing_status_name(x);
  return s;
}

}  // namespace

// Every method: where the standard puts the home from both sides of the
// switch, as the drive's redefined counts tell it. The home position in the
// plant is pos - (reported - offset): the counts say how far the axis is
// from the home it found. A switch edge is seen at the first SYNC past it,
// so within one period of the final approach's speed (the speed for zero
// after a reversal, the speed for switch when the first motion reaches the
// edge); an index is captured where it is.
TEST(Homing, EveryMethodEndsAtTheHomeTheStandardDefines) {
  struct Case {
    int method;
    bool negative_switch;  // the home switch's side (3, 4, 19, 20: positive)
    double start;          // m
    double home;           // m: where the standard puts it
    double speed;          // m/s of the final approach (0: an index, exact)
    int direction;         // of the final approach
  };
  const Case cases[] = {
      // Limit switches: search for the limit, leave it at the speed for zero.
      {17, true, 0.100, kLimitLow, kZero, +1},
      {17, true, 0.003, kLimitLow, kSearch, +1},  // starts on the limit: no search, no reversal
      {18, true, 0.300, kLimitHigh, kZero, -1},
      {1, true, 0.100, 0.008, 0, +1},             // then the first index above the release
      {1, true, 0.003, 0.008, 0, +1},
      {2, true, 0.300, 0.392, 0, -1},
      // Positive home switch (actuated above 50 mm).
      {19, false, 0.020, kEdge, kZero, -1},       // up into it, back down out of it
      {19, false, 0.080, kEdge, kSearch, -1},     // in it: straight down out of it
      {20, false, 0.020, kEdge, kSearch, +1},     // straight up into it
      {20, false, 0.080, kEdge, kZero, +1},       // down out of it, back up into it
      {3, false, 0.020, 0.048, 0, -1},
      {3, false, 0.080, 0.048, 0, -1},
      {4, false, 0.020, 0.052, 0, +1},
      {4, false, 0.080, 0.052, 0, +1},
      // Negative home switch (actuated below 50 mm), the virtual machine's.
      {21, true, 0.080, kEdge, kZero, +1},
      {21, true, 0.020, kEdge, kSearch, +1},
      {22, true, 0.080, kEdge, kSearch, -1},
      {22, true, 0.020, kEdge, kZero, -1},
      {5, true, 0.080, 0.052, 0, +1},
      {5, true, 0.020, 0.052, 0, +1},
      {6, true, 0.080, 0.048, 0, -1},
      {6, true, 0.020, 0.048, 0, -1},
      // Index only, and the current position.
      {33, true, 0.1003, 0.100, 0, -1},
      {34, true, 0.1003, 0.104, 0, +1},
      {35, true, 0.1003, 0.1003, 0, +1},
      {37, true, 0.1003, 0.1003, 0, +1},
  };
  for (const Case& c : cases) {
    SCOPED_TRACE("method " + std::to_string(c.method) + " from " + std::to_string(c.start) + " m");
    Rig r(homing_drives(c.method));
    r.sensors[1] = planted(c.negative_switch);
    r.pos_m[1] = c.start;
    r.master->start();
    const Homing h = home(r, 1);
    ASSERT_GE(h.cycles, 0) << describe(h);
    EXPECT_EQ(r.fb.drive[1].homing, HomingStatus::completed) << describe(h);
    // It went through "attained, target not reached" (stopping and
    // returning to the home position) to "completed"; 35 and 37 are at
    // their home at once.
    ASSERT_GE(h.seen.size(), 2u);
    const bool moves = c.method != 35 && c.method != 37;
    EXPECT_EQ(h.seen[h.seen.size() - 2], moves ? HomingStatus::attained : HomingStatus::interrupted) << describe(h);
    const double home_in_plant = r.pos_m[1] - (r.fb.drive[1].position_m - kOffset);
    if (c.speed == 0) {
      EXPECT_NEAR(home_in_plant, c.home, 1.5 * kCount);
    } else {
      // Past the edge in the direction of the approach, by less than a period.
      const double past = (home_in_plant - c.home) * c.direction;
      EXPECT_GE(past, -1.5 * kCount);
      EXPECT_LE(past, c.speed * kPeriod + 1.5 * kCount);
    }
    // At rest at the home position, within a period at the speed for zero.
    EXPECT_NEAR(r.fb.drive[1].position_m, kOffset, kZero * kPeriod + kCount);
    EXPECT_NEAR(r.pos_m[1], home_in_plant, kZero * kPeriod + kCount);
    EXPECT_NEAR(r.vel_mps[1], 0.0, 0.05 * kZero + kCount / kPeriod);
    // It holds the home position (within the limit cycle of its 0.4 N
    // torque unit on the 10 kg mass: a few counts).
    for (int k = 0; k < 200; ++k) {
      r.cycle();
      ASSERT_EQ(r.fb.drive[1].homing, HomingStatus::completed);
      ASSERT_NEAR(r.pos_m[1], home_in_plant, kZero * kPeriod + kCount);
    }
    // The other drives, in homing mode's mapping but told cyclic torque, did nothing.
    EXPECT_EQ(r.fb.drive[0].homing, HomingStatus::idle);
    EXPECT_EQ(r.fb.drive[0].mode_display, cia402::kModeCyclicSyncTorque);
    EXPECT_EQ(r.pos_m[0], 0.0);
  }
}

// The drive's direction is the master's scaling business: 0x607C carries
// the offset in counts with the direction, so the master reads offset_m at
// the home whichever way the drive counts.
TEST(Homing, HomeOffsetCarriesTheDirection) {
  MasterConfig c = homing_drives(21);
  c.drives[0].direction = -1;
  c.drives[0].position_offset_m = 0.5;
  Rig r(c);
  r.sensors[0] = planted(true);
  r.pos_m[0] = 0.08;
  r.master->start();
  // 0x607C = direction (offset - position_offset) counts_per_m.
  EXPECT_EQ(static_cast<std::int32_t>(r.drives[0]->od_value(cia402::kHomeOffset, 0)), -(123000 - 500000));
  const Homing h = home(r, 0);
  ASSERT_GE(h.cycles, 0);
  EXPECT_NEAR(r.fb.drive[0].position_m, kOffset, kZero * kPeriod + kCount);
}

// A hanging axis (a weight of 1 g on its mass) held in cyclic synchronous
// torque: entering homing mode, the drive's loops take over the torque it
// was applying (bumpless), home against the weight and hold it at home.
TEST(Homing, ALoadHeldThroughTheSwitchIntoHomingAndAtHome) {
  Rig r(homing_drives(21));
  r.sensors[2] = planted(true);
  r.pos_m[2] = 0.08;
  const double weight = -r.mass_kg * 9.81;
  r.master->start();
  r.target_all(Target::enabled);
  ASSERT_GE(r.until_all(State::operation_enabled), 0);
  // The weight hangs on the drive from the SYNC its holding force acts (a
  // brake let go then): the test's own hold, the loop's job on the machine.
  r.load_n[2] = weight;
  r.cmd.drive[2].force_n = -weight;
  r.cycles(5);
  const double held = r.pos_m[2];
  r.cmd.drive[2].homing = true;  // mode 6, bit 4 still low: the drive holds where it is
  double worst = 0;
  for (int k = 0; k < 100; ++k) {
    r.cycle();
    worst = std::max(worst, std::abs(r.pos_m[2] - held));
  }
  EXPECT_EQ(r.fb.drive[2].mode_display, cia402::kModeHoming);
  EXPECT_EQ(r.fb.drive[2].homing, HomingStatus::interrupted);  // "interrupted or not started"
  EXPECT_LT(worst, 5 * kCount) << "the axis dropped entering homing mode";
  const Homing h = home(r, 2);
  ASSERT_GE(h.cycles, 0) << describe(h);
  EXPECT_EQ(r.fb.drive[2].homing, HomingStatus::completed) << describe(h);
  const double home_in_plant = r.pos_m[2] - (r.fb.drive[2].position_m - kOffset);
  EXPECT_GE(home_in_plant - kEdge, -1.5 * kCount);
  EXPECT_LE(home_in_plant - kEdge, kZero * kPeriod + 1.5 * kCount);
  const double at = r.pos_m[2];
  r.cycles(500);
  EXPECT_NEAR(r.pos_m[2], at, 2 * kCount) << "the weight is not held at home";
  EXPECT_NEAR(r.drives[2]->applied_torque() * 400.0 / 1000.0, -weight, 0.5);  // the drive carries it: 98.1 N
}

// The home switch never actuates: the search runs on to the limit switch at
// the end it searches toward, which is not the method's: homing error, the
// drive stops there and holds, in operation enabled, the counts untouched.
TEST(Homing, SwitchNeverFoundEndsInHomingErrorAtTheLimit) {
  for (int method : {21, 19, 5}) {
    SCOPED_TRACE("method " + std::to_string(method));
    Rig r(homing_drives(method));
    r.sensors[0] = planted(method != 19);
    r.sensors[0].home_dead = true;
    // 21, 5: down to the negative limit (from inside the switch's would-be
    // side); 19: up to the positive limit.
    r.pos_m[0] = 0.020;
    r.master->start();
    const Homing h = home(r, 0);
    ASSERT_GE(h.cycles, 0) << describe(h);
    EXPECT_EQ(r.fb.drive[0].homing, HomingStatus::error) << describe(h);
    EXPECT_TRUE(r.fb.drive[0].statusword & cia402::kSwHomingError);
    EXPECT_EQ(r.fb.drive[0].state, State::operation_enabled);
    EXPECT_EQ(r.drives[0]->position_shift(), 0);
    const bool down = method != 19;
    // Stopped past the limit switch by at most the braking distance v^2 / 2a (1 mm).
    const double limit = down ? kLimitLow : kLimitHigh;
    const double past = down ? limit - r.pos_m[0] : r.pos_m[0] - limit;
    EXPECT_GE(past, 0.0);
    r.cycles(300);
    EXPECT_EQ(r.fb.drive[0].homing, HomingStatus::error);
    EXPECT_TRUE(r.fb.drive[0].statusword & cia402::kSwTargetReached) << "error at rest: 1 0 1";
    EXPECT_LE(down ? limit - r.pos_m[0] : r.pos_m[0] - limit, kSearch * kSearch / (2 * kAccel) + kSearch * kPeriod);
    EXPECT_NEAR(r.vel_mps[0], 0.0, 1e-4);
  }
}

TEST(Homing, DriveFaultDuringHomingEndsInFault) {
  Rig r(homing_drives(21));
  r.sensors[0] = planted(true);
  r.pos_m[0] = 0.2;
  r.master->start();
  const Homing h = home(r, 0, 100);  // searching
  EXPECT_EQ(h.cycles, -1);
  EXPECT_EQ(r.fb.drive[0].homing, HomingStatus::in_progress);
  EXPECT_LT(r.vel_mps[0], -0.5 * kSearch);
  r.drives[0]->inject_fault(0x2310, 0x03);
  r.cycles(3);
  EXPECT_EQ(r.fb.drive[0].state, State::fault);
  EXPECT_TRUE(r.fb.drive[0].faults & kFaultDrive);
  EXPECT_TRUE(r.fb.drive[0].faults & kFaultEmcy);
  EXPECT_EQ(r.fb.drive[0].last_error_emcy.code, 0x2310);
  EXPECT_EQ(r.fb.drive[0].homing, HomingStatus::idle);
  EXPECT_EQ(r.drives[0]->applied_torque(), 0);
  EXPECT_EQ(r.drives[0]->position_shift(), 0);
}

// Bit 4 falling interrupts: 0 0 1 at once, the drive stops and holds, the
// counts untouched; a new rising edge homes from where it stopped.
TEST(Homing, Bit4DroppedInterruptsAndANewEdgeHomes) {
  Rig r(homing_drives(21));
  r.sensors[0] = planted(true);
  r.pos_m[0] = 0.2;
  r.master->start();
  (void)home(r, 0, 100);
  ASSERT_EQ(r.fb.drive[0].homing, HomingStatus::in_progress);
  r.cmd.drive[0].start_homing = false;
  r.cycles(2);  // the RPDO, then its TPDO
  EXPECT_EQ(r.fb.drive[0].homing, HomingStatus::interrupted);
  EXPECT_TRUE(r.fb.drive[0].statusword & cia402::kSwTargetReached);
  EXPECT_FALSE(r.fb.drive[0].statusword & (cia402::kSwHomingAttained | cia402::kSwHomingError));
  r.cycles(200);
  EXPECT_NEAR(r.vel_mps[0], 0.0, 1e-4);
  const double stopped = r.pos_m[0];
  EXPECT_GT(stopped, kEdge);
  r.cycles(100);
  EXPECT_NEAR(r.pos_m[0], stopped, 2 * kCount);
  EXPECT_EQ(r.drives[0]->position_shift(), 0);
  const Homing again = home(r, 0);
  ASSERT_GE(again.cycles, 0);
  EXPECT_EQ(r.fb.drive[0].homing, HomingStatus::completed) << describe(again);
  EXPECT_NEAR(r.pos_m[0] - (r.fb.drive[0].position_m - kOffset), kEdge, kZero * kPeriod + 1.5 * kCount);
}

// The master raises bit 4 only once the drive displays mode 6 after an RPDO
// that had it low (the drive sees a rising edge in homing mode), sends zero
// torque in mode 6, and ignores homing for a drive not configured for it.
TEST(Homing, MasterMakesTheRisingEdgeInModeSixAndSendsNoTorque) {
  MasterConfig c = homing_drives(21);
  c.drives[0].homing = DriveHomingConfig{};  // drive 1: no homing
  Rig r(c);
  r.sensors[1] = planted(true);
  r.pos_m[1] = 0.08;
  r.master->start();
  r.target_all(Target::enabled);
  ASSERT_GE(r.until_all(State::operation_enabled), 0);
  for (std::size_t i = 0; i < 2; ++i) {
    r.cmd.drive[i].homing = true;
    r.cmd.drive[i].start_homing = true;
    r.cmd.drive[i].force_n = 20;
  }
  bool low_in_mode6_seen = false;
  int raised_at = -1;
  for (int k = 0; k < 10 && raised_at < 0; ++k) {
    r.master->read(r.fb);
    const std::int8_t display = r.fb.drive[1].mode_display;
    r.master->write(r.cmd);
    r.clock.wait(r.period_ns());  // the drive applies the RPDO at the SYNC
    const auto sent = static_cast<std::uint16_t>(r.drives[1]->od_value(cia402::kControlword, 0));
    if (sent & cia402::kCwHomingStart) {
      raised_at = k;
      EXPECT_EQ(display, cia402::kModeHoming) << "raised before the drive displayed mode 6";
      EXPECT_TRUE(low_in_mode6_seen) << "no cycle with bit 4 low in mode 6 before the edge";
    } else if (r.drives[1]->mode_display() == cia402::kModeHoming) {
      low_in_mode6_seen = true;
    }
    EXPECT_EQ(static_cast<std::int16_t>(r.drives[1]->od_value(cia402::kTargetTorque, 0)), 0) << "torque in mode 6";
  }
  // Cycle 0: mode 6 with bit 4 low; cycle 1 reads the TPDO of that SYNC
  // (mode 6 displayed, bit 4 seen low in it) and raises bit 4: the edge.
  EXPECT_EQ(raised_at, 1);
  r.cycles(3);
  EXPECT_EQ(r.fb.drive[1].homing, HomingStatus::in_progress);
  // Drive 1 has no homing: mode 10, and the force it was given.
  EXPECT_EQ(r.drives[0]->mode_display(), cia402::kModeCyclicSyncTorque);
  EXPECT_EQ(r.drives[0]->applied_torque(), 50);  // 20 N of 400 N
  EXPECT_EQ(r.fb.drive[0].mode_display, 0);      // not mapped
  EXPECT_EQ(r.fb.drive[0].homing, HomingStatus::idle);
  // Back to torque: mode 10 and the force in the same RPDO.
  r.cmd.drive[1].homing = false;
  r.cycles(2);
  EXPECT_EQ(r.drives[1]->mode_display(), cia402::kModeCyclicSyncTorque);
  EXPECT_EQ(r.fb.drive[1].mode_display, cia402::kModeCyclicSyncTorque);
  EXPECT_EQ(r.drives[1]->applied_torque(), 50);
  EXPECT_EQ(r.fb.drive[1].homing, HomingStatus::idle);
}

// Only a drive with homing gets the 5- and 7-byte PDOs and the homing
// objects, each read back, in its units.
TEST(Homing, MappingAndObjectsOnlyOnHomingDrives) {
  MasterConfig c = three_drives(500, true);
  c.drives[2].homing = {true, 21, 0.02, 0.002, 0.2, 0.123};
  Rig r(c);
  r.master->start();
  for (std::size_t i = 0; i < 2; ++i) {
    auto& d = *r.drives[i];
    EXPECT_EQ(d.od_value(0x1600, 0), 2u);
    EXPECT_EQ(d.od_value(0x1A00, 0), 2u);
    EXPECT_EQ(d.od_value(cia402::kHomingMethod, 0), 0u) << "homing objects written to a drive without homing";
  }
  auto& z = *r.drives[2];
  EXPECT_EQ(z.od_value(0x1600, 0), 3u);
  EXPECT_EQ(z.od_value(0x1600, 1), 0x60400010u);
  EXPECT_EQ(z.od_value(0x1600, 2), 0x60710010u);
  EXPECT_EQ(z.od_value(0x1600, 3), 0x60600008u);
  EXPECT_EQ(z.od_value(0x1A00, 0), 3u);
  EXPECT_EQ(z.od_value(0x1A00, 1), 0x60410010u);
  EXPECT_EQ(z.od_value(0x1A00, 2), 0x60640020u);
  EXPECT_EQ(z.od_value(0x1A00, 3), 0x60610008u);
  EXPECT_EQ(z.od_value(0x1A01, 1), 0x606C0020u);  // TPDO2 as for any drive
  // 1e6 counts/m, velocity in counts/s.
  EXPECT_EQ(z.od_value(cia402::kHomingMethod, 0), 21u);
  EXPECT_EQ(z.od_value(cia402::kHomeOffset, 0), 123000u);
  EXPECT_EQ(z.od_value(cia402::kHomingSpeeds, 1), 20000u);
  EXPECT_EQ(z.od_value(cia402::kHomingSpeeds, 2), 2000u);
  EXPECT_EQ(z.od_value(cia402::kHomingAcceleration, 0), 200000u);
  r.cycles(3);
  EXPECT_EQ(r.fb.drive[2].mode_display, cia402::kModeCyclicSyncTorque);
  EXPECT_EQ(r.fb.drive[0].mode_display, 0);
  for (std::size_t i = 0; i < 3; ++i) {
    EXPECT_TRUE(r.fb.drive[i].fresh) << i;
    EXPECT_EQ(r.fb.drive[i].faults, 0u) << i;
  }
  // Torque as before through the 5-byte RPDO.
  r.target_all(Target::enabled);
  ASSERT_GE(r.until_all(State::operation_enabled), 0);
  r.cmd.drive[2].force_n = -100;
  r.cycles(2);
  EXPECT_EQ(z.applied_torque(), -250);
  // stop() disables it with its own RPDO length too.
  r.master->stop();
  r.clock.wait(r.period_ns());
  EXPECT_EQ(z.state(), State::switch_on_disabled);
  EXPECT_EQ(z.bad_pdos, 0u);
}

// Worst-case bits (docs/hal.md): 8n + 47 + floor((34 + 8n - 1) / 4): RPDO1
// 4 B 95 -> 5 B 105 bits, TPDO1 6 B 115 -> 7 B 125 bits; 20 more bits per
// homing drive. Three drives at 1 kHz on 1 Mbit/s, heartbeats 4 x 65 bits
// per 50 ms (5.2 bits per cycle).
TEST(Homing, BusLoadCountsTheModeBytes) {
  EXPECT_EQ(pdo::kRpdo1Homing.bytes(), 5);
  EXPECT_EQ(pdo::kTpdo1Homing.bytes(), 7);
  MasterConfig c = three_drives(1000, false);
  const BusLoad none = bus_load(c);
  EXPECT_EQ(none.bits_per_cycle, 55 + 3 * (95 + 115));  // 685: today's figure
  EXPECT_NEAR(none.load, (685 + 5.2) / 1000, 1e-9);
  c.drives[2].homing = {true, 21, 0.02, 0.002, 0.2, 0};
  const BusLoad z = bus_load(c);
  EXPECT_EQ(z.frames_per_cycle, 7);
  EXPECT_EQ(z.bits_per_cycle, 685 + 20);
  // (0.8 x 1e6 - 5200 bits/s of heartbeats) / 705 bits.
  EXPECT_EQ(std::floor(z.max_rate_hz), 1127);
  for (auto& d : c.drives) d.homing = {true, 21, 0.02, 0.002, 0.2, 0};
  const BusLoad all = bus_load(c);
  EXPECT_EQ(all.bits_per_cycle, 55 + 3 * (105 + 125));  // 745
  EXPECT_NEAR(all.load, (745 + 5.2) / 1000, 1e-9);       // 75.0 %
  EXPECT_EQ(std::floor(all.max_rate_hz), 1066);
  EXPECT_TRUE(all.fits);
  Rig r(c);
  EXPECT_EQ(r.master->load().bits_per_cycle, 745);
}

TEST(Homing, ConfigurationErrorsNameTheKey) {
  auto error_of = [](const MasterConfig& c) {
    try {
      validate(c);
    } catch (const Error& e) {
      return std::string(e.what());
    }
    return std::string();
  };
  MasterConfig c = homing_drives(21);
  EXPECT_EQ(error_of(c), "");
  c.drives[1].homing.method = 0;
  EXPECT_NE(error_of(c).find("drives[1].homing.method"), std::string::npos) << error_of(c);
  c = homing_drives(21);
  c.drives[0].homing.speed_zero_mps = 0;
  EXPECT_NE(error_of(c).find("drives[0].homing.speed_zero_mps"), std::string::npos) << error_of(c);
  c = homing_drives(21);
  c.drives[2].homing.acceleration_mps2 = std::nan("");
  EXPECT_NE(error_of(c).find("drives[2].homing.acceleration_mps2"), std::string::npos) << error_of(c);
  c = homing_drives(21);
  c.drives[2].homing.offset_m = 3000;  // 3e9 counts
  EXPECT_NE(error_of(c).find("drives[2].homing.offset_m"), std::string::npos) << error_of(c);
  c = homing_drives(21);
  c.drives[0].homing.speed_search_mps = 1e-9;  // below one unit
  EXPECT_NE(error_of(c).find("drives[0].homing.speed_search_mps"), std::string::npos) << error_of(c);
  // A method the drive does not have: it refuses the write, start() says where.
  Rig r(homing_drives(7));
  std::string e;
  try {
    r.master->start();
  } catch (const Error& x) {
    e = x.what();
  }
  EXPECT_NE(e.find("node 1 (x): SDO write 0x6098:00 aborted by the drive: 0x06090030"), std::string::npos) << e;
}

// A boot-up while running: the drive's counts restarted (and its homing with
// them). Reported once, by the next read().
TEST(Homing, BootUpWhileRunningReportsPositionLostOnce) {
  Rig r(homing_drives(35));
  r.pos_m[1] = 0.1;
  r.master->start();
  const Homing h = home(r, 1);
  ASSERT_EQ(r.fb.drive[1].homing, HomingStatus::completed) << describe(h);
  EXPECT_NE(r.drives[1]->position_shift(), 0);
  r.cycles(3);
  for (std::size_t i = 0; i < 3; ++i) EXPECT_FALSE(r.fb.drive[i].position_lost);
  r.drives[1]->power_on(r.clock.now_ns());  // power cycle: boot-up, pre-operational
  EXPECT_EQ(r.drives[1]->position_shift(), 0);
  r.cycle();
  EXPECT_TRUE(r.fb.drive[1].position_lost);
  EXPECT_FALSE(r.fb.drive[0].position_lost);
  EXPECT_TRUE(r.fb.drive[1].faults & kFaultNmtState);
  r.cycle();
  EXPECT_FALSE(r.fb.drive[1].position_lost);
}
