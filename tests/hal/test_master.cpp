// SPDX-License-Identifier: Apache-2.0
// The master with three virtual drives on the fake bus: start-up, the CiA 402
// path to operation enabled and back, scaling end to end, and the faults it
// must detect (heartbeat, EMCY, PDO loss and length, bus-off, error passive,
// silent and wrong drives), all on a fake clock.
#include <gtest/gtest.h>

#include <cstring>

#include "rig.hpp"

using namespace cpm::hal;
using namespace cpm::hal::test;
using cia402::State;
using cia402::Target;

namespace {
std::string error_of(const std::function<void()>& f) {
  try {
    f();
  } catch (const Error& e) {
    return e.what();
  }
  return "";
}
}  // namespace

TEST(Master, StartConfiguresAndVerifiesEveryDrive) {
  Rig r;
  r.master->start();
  ASSERT_TRUE(r.master->started());
  for (auto& d : r.drives) {
    EXPECT_EQ(d->nmt_state(), canopen::NmtState::operational);
    EXPECT_EQ(d->state(), State::switch_on_disabled);
    EXPECT_EQ(d->mode_display(), cia402::kModeCyclicSyncTorque);
    // The mapping the master wrote is the one the drive now uses.
    EXPECT_EQ(d->od_value(0x1600, 0), 2u);
    EXPECT_EQ(d->od_value(0x1600, 1), 0x60400010u);
    EXPECT_EQ(d->od_value(0x1600, 2), 0x60710010u);
    EXPECT_EQ(d->od_value(0x1A00, 0), 2u);
    EXPECT_EQ(d->od_value(0x1A00, 1), 0x60410010u);
    EXPECT_EQ(d->od_value(0x1A00, 2), 0x60640020u);
    EXPECT_EQ(d->od_value(0x1A01, 0), 1u);
    EXPECT_EQ(d->od_value(0x1A01, 1), 0x606C0020u);
    EXPECT_EQ(d->od_value(0x1800, 2), 1u);  // every SYNC
    EXPECT_EQ(d->od_value(0x1801, 1), 0x280u + d->node_id());
    EXPECT_TRUE(d->od_value(0x1401, 1) & 0x80000000u);  // unused PDOs invalid
    EXPECT_TRUE(d->od_value(0x1802, 1) & 0x80000000u);
    EXPECT_EQ(d->od_value(0x1017, 0), 50u);
    EXPECT_EQ(d->od_value(0x1016, 1), (127u << 16) | 150u);
    EXPECT_EQ(d->od_value(0x6007, 0), 3u);
    EXPECT_EQ(d->od_value(0x60C2, 1), 2u);     // 500 Hz: 2 x 10^-3 s
    EXPECT_EQ(d->od_value(0x60C2, 2), 0xFDu);
    EXPECT_EQ(d->od_value(0x6072, 0), 2000u);
  }
}

// CiA 301 makes every PDO optional. The master used to read the COB-ID of
// RPDO 2-4 and TPDO 3-4 to invalidate them, and refused to start on a drive
// without them ("object does not exist"); one without them has nothing to
// invalidate. A drive without a PDO the mapping needs is still refused.
TEST(Master, StartAcceptsDrivesWithOnlyThePdosItMaps) {
  Rig r(three_drives(), 2);  // RPDO 1-2, TPDO 1-2
  r.master->start();
  ASSERT_TRUE(r.master->started());
  r.cycle();
  r.cycle();
  for (std::size_t i = 0; i < 3; ++i) {
    EXPECT_TRUE(r.fb.drive[i].fresh) << "drive " << i + 1;
    EXPECT_EQ(r.fb.drive[i].faults, 0u) << "drive " << i + 1;
    EXPECT_TRUE(r.drives[i]->od_value(0x1401, 1) & 0x80000000u);  // the RPDO it has but is not used: invalid
  }
  r.target_all(Target::enabled);
  for (int k = 0; k < 6; ++k) r.cycle();
  EXPECT_EQ(r.fb.drive[0].state, State::operation_enabled);

  MasterConfig with_velocity = three_drives();
  with_velocity.velocity_from_drive = true;
  Rig one(with_velocity, 1);  // TPDO1 only: no TPDO2 for the velocity
  const std::string e = error_of([&] { one.master->start(); });
  EXPECT_NE(e.find("0x1801:01"), std::string::npos) << e;
  EXPECT_NE(e.find("0x06020000 Object does not exist"), std::string::npos) << e;
}

TEST(Master, BootToOperationEnabledAndBackThroughEveryStep) {
  Rig r;
  r.master->start();
  r.cycle();
  r.cycle();
  for (std::size_t i = 0; i < 3; ++i) {
    EXPECT_EQ(r.fb.drive[i].state, State::switch_on_disabled);
    EXPECT_TRUE(r.fb.drive[i].fresh);
    EXPECT_EQ(r.fb.drive[i].faults, 0u);
  }
  r.target_all(Target::enabled);
  // Transitions 2, 3, 4: one per cycle, each confirmed by the statusword.
  std::vector<State> seen;
  for (int k = 0; k < 6; ++k) {
    r.cycle();
    if (seen.empty() || seen.back() != r.fb.drive[0].state) seen.push_back(r.fb.drive[0].state);
  }
  const std::vector<State> path = {State::switch_on_disabled, State::ready_to_switch_on, State::switched_on,
                                   State::operation_enabled};
  EXPECT_EQ(seen, path);
  for (auto& d : r.drives) EXPECT_EQ(d->state(), State::operation_enabled);
  // Quick stop (11), then the drive completes it on its own (12).
  r.target_all(Target::quick_stop);
  r.cycle();
  r.cycle();
  EXPECT_EQ(r.fb.drive[1].state, State::quick_stop_active);
  EXPECT_EQ(r.drives[1]->last_transition(), 11);
  EXPECT_GE(r.until_all(State::switch_on_disabled), 0);
  EXPECT_EQ(r.drives[1]->last_transition(), 12);
  // Enable again, then disable (9).
  r.target_all(Target::enabled);
  EXPECT_GE(r.until_all(State::operation_enabled), 0);
  r.target_all(Target::disabled);
  r.cycle();
  r.cycle();
  EXPECT_EQ(r.drives[2]->last_transition(), 9);
  EXPECT_EQ(r.fb.drive[2].state, State::switch_on_disabled);
  EXPECT_FALSE(r.fb.any_fault());
  r.master->stop();
  r.clock.wait(r.period_ns());
  for (auto& d : r.drives) {
    EXPECT_EQ(d->nmt_state(), canopen::NmtState::preoperational);
    EXPECT_EQ(d->state(), State::switch_on_disabled);
  }
}

TEST(Master, ForceReachesTheDriveScaledAndFeedbackComesBackInSI) {
  Rig r;
  r.master->start();
  r.target_all(Target::enabled);
  ASSERT_GE(r.until_all(State::operation_enabled), 0);
  // No torque was ever applied while enabling.
  for (std::size_t i = 0; i < 3; ++i) EXPECT_EQ(r.pos_m[i], 0.0);
  r.cmd.drive[0].force_n = 100.0;   // 250 per mille of 400 N
  r.cmd.drive[1].force_n = -40.0;
  r.cmd.drive[2].force_n = 5000.0;  // beyond 2000 per mille: clamped to 800 N
  const int n = 50;
  for (int k = 0; k < n; ++k) r.cycle();
  r.master->read(r.fb);
  EXPECT_EQ(r.drives[0]->applied_torque(), 250);
  EXPECT_EQ(r.drives[1]->applied_torque(), -100);
  EXPECT_EQ(r.drives[2]->applied_torque(), 2000);
  EXPECT_EQ(r.fb.drive[2].torque_code, Code::saturated);
  // The plant integrated exactly n SYNCs of F/m: v = F/m * n * dt.
  const double dt = 1.0 / 500;
  const double f[3] = {100.0, -40.0, 800.0};
  for (std::size_t i = 0; i < 3; ++i) {
    EXPECT_NEAR(r.fb.drive[i].velocity_mps, f[i] / r.mass_kg * n * dt, 1e-6) << i;
    EXPECT_NEAR(r.fb.drive[i].position_m, r.pos_m[i], 0.5e-6) << i;  // one count
    EXPECT_EQ(r.drives[i]->sync_count(), r.fb.cycle);
  }
  // NaN is never sent: zero torque and a status.
  r.cmd.drive[0].force_n = std::nan("");
  r.master->read(r.fb);
  const Status s = r.master->write(r.cmd);
  EXPECT_EQ(s.code, Code::not_finite);
  EXPECT_EQ(s.index, 0);
  r.clock.wait(r.period_ns());
  EXPECT_EQ(r.drives[0]->applied_torque(), 0);
}

TEST(Master, VelocityFromPositionDifferencesWhenNotMapped) {
  Rig r(three_drives(1000, false));
  r.master->start();
  EXPECT_TRUE(r.drives[0]->od_value(0x1801, 1) & 0x80000000u);  // TPDO2 left invalid
  r.target_all(Target::enabled);
  ASSERT_GE(r.until_all(State::operation_enabled), 0);
  r.cmd.drive[0].force_n = 200.0;
  for (int k = 0; k < 200; ++k) r.cycle();
  r.master->read(r.fb);
  // The rig's plant is symplectic Euler (v += a dt; p += v dt), so the
  // difference of positions sampled a period apart is exactly the new
  // velocity, up to the rounding of each position to a count (1 um / 1 ms).
  EXPECT_NEAR(r.fb.drive[0].velocity_mps, r.vel_mps[0], 1.0e-3 + 1e-9);
  EXPECT_GT(r.vel_mps[0], 3.9);  // it did move: 20 m/s^2 for 0.2 s
  EXPECT_TRUE(r.fb.drive[0].fresh);
}

TEST(Master, DriveHeartbeatLossIsDetectedWithinTheTimeout) {
  Rig r;
  r.master->start();
  r.cycles(5);
  EXPECT_FALSE(r.fb.any_fault());
  r.drives[1]->stop_heartbeat(true);
  const std::int64_t t0 = r.clock.now_ns();
  int k = 0;
  while (!(r.fb.drive[1].faults & kFaultHeartbeatLost) && k < 1000) {
    r.cycle();
    ++k;
  }
  ASSERT_TRUE(r.fb.drive[1].faults & kFaultHeartbeatLost);
  const std::int64_t detected = r.clock.now_ns() - r.period_ns() - t0;
  // Last heartbeat up to one heartbeat period before t0; detection at most a cycle after the timeout.
  EXPECT_LE(detected, 150'000'000 + r.period_ns());
  EXPECT_GE(detected, 150'000'000 - 50'000'000);
  EXPECT_GT(r.fb.drive[1].heartbeat_age_ns, 150'000'000);
  EXPECT_EQ(r.fb.drive[0].faults & kFaultHeartbeatLost, 0u);
  EXPECT_EQ(r.fb.drive[2].faults & kFaultHeartbeatLost, 0u);
  // Latched: the heartbeat coming back does not clear it; a reset does.
  r.drives[1]->stop_heartbeat(false);
  r.cycles(30);
  EXPECT_TRUE(r.fb.drive[1].faults & kFaultHeartbeatLost);
  r.master->reset_faults();
  r.cycle();
  EXPECT_EQ(r.fb.drive[1].faults, 0u);
}

TEST(Master, SilentMasterMakesTheDrivesQuickStopOnTheirOwn) {
  Rig r;
  r.master->start();
  r.target_all(Target::enabled);
  ASSERT_GE(r.until_all(State::operation_enabled), 0);
  // The master process dies: no more SYNC, RPDO or heartbeat. Its last
  // heartbeat went out at most 50 ms ago, so the drives' 150 ms consumer
  // fires between 100 and 150 ms from now.
  r.clock.wait(99'000'000);
  for (auto& d : r.drives) EXPECT_EQ(d->state(), State::operation_enabled);
  r.clock.wait(52'000'000);
  for (auto& d : r.drives) {
    EXPECT_EQ(d->master_heartbeat_timeouts, 1u);
    EXPECT_EQ(d->state(), State::quick_stop_active);  // 0x6007 = 3
    EXPECT_EQ(d->applied_torque(), 0);
  }
}

TEST(Master, EmcyBecomesAReadableLatchedFaultAndResetNeedsAnEdge) {
  Rig r;
  r.master->start();
  r.target_all(Target::enabled);
  ASSERT_GE(r.until_all(State::operation_enabled), 0);
  r.drives[2]->inject_fault(0x2310, 0x03);  // over-current: generic + current
  r.cycle();
  r.cycle();
  const DriveFeedback& d = r.fb.drive[2];
  EXPECT_TRUE(d.faults & kFaultEmcy);
  EXPECT_TRUE(d.faults & kFaultDrive);
  EXPECT_EQ(d.state, State::fault);
  EXPECT_EQ(d.last_emcy.code, 0x2310);
  char text[200];
  canopen::describe_emcy(3, d.last_emcy, text, sizeof text);
  EXPECT_STREQ(text, "node 3 EMCY 0x2310 current, device output side: continuous over-current "
                     "(error register 0x03: generic, current)");
  char faults[120];
  describe_drive_faults(d.faults, faults, sizeof faults);
  EXPECT_STREQ(faults, "EMCY, drive fault");
  // Target enabled alone never leaves the fault.
  r.cycles(10);
  EXPECT_EQ(r.fb.drive[2].state, State::fault);
  EXPECT_EQ(r.drives[2]->applied_torque(), 0);
  // A reset request makes the edge on bit 7; the drive answers with EMCY 0x0000.
  r.cmd.drive[2].reset_fault = true;
  EXPECT_GE(r.until_all(State::operation_enabled, 20), 0);
  EXPECT_FALSE(r.fb.drive[2].emcy_active);
  EXPECT_EQ(r.fb.drive[2].last_emcy.code, 0);
  EXPECT_TRUE(r.fb.drive[2].faults & kFaultEmcy);  // still latched in the master
  r.master->reset_faults();
  r.cycle();
  EXPECT_FALSE(r.fb.any_fault());
}

TEST(Master, PersistentFaultRefusesReset) {
  Rig r;
  r.master->start();
  r.drives[0]->inject_fault(0x4310, 0x09, /*persistent=*/true);
  r.cmd.drive[0].target = Target::enabled;
  r.cmd.drive[0].reset_fault = true;
  r.cycles(20);
  EXPECT_EQ(r.fb.drive[0].state, State::fault);
  EXPECT_EQ(r.drives[0]->last_transition(), -1);  // the reset was refused
  r.drives[0]->clear_fault();
  r.target_all(Target::enabled);
  EXPECT_GE(r.until_all(State::operation_enabled, 20), 0);
}

TEST(Master, RefusedTransitionLeavesTheDriveWhereItIsWithoutTorque) {
  Rig r;
  r.master->start();
  r.drives[1]->refuse(cia402::Command::enable_operation, true);
  r.target_all(Target::enabled);
  r.cycles(20);
  r.cmd.drive[1].force_n = 100;
  r.cycles(5);
  EXPECT_EQ(r.fb.drive[0].state, State::operation_enabled);
  EXPECT_EQ(r.fb.drive[1].state, State::switched_on);
  EXPECT_EQ(r.fb.drive[1].torque_permille, 0);
  EXPECT_EQ(r.drives[1]->applied_torque(), 0);
  r.drives[1]->refuse(cia402::Command::enable_operation, false);
  r.cycles(3);
  EXPECT_EQ(r.fb.drive[1].state, State::operation_enabled);
}

TEST(Master, MissingAndMalformedTpdosAreFaults) {
  Rig r;
  r.master->start();
  r.cycles(3);
  // Two lost TPDO1 of node 3: not yet a fault (3 cycles needed), then one more is.
  r.net.drop(0x183, 0x7FF, 2);
  r.cycles(4);
  EXPECT_EQ(r.fb.drive[2].faults, 0u);
  EXPECT_EQ(r.fb.drive[2].missed_cycles, 0u);
  r.net.drop(0x183, 0x7FF, 3);
  r.cycles(4);
  EXPECT_TRUE(r.fb.drive[2].faults & kFaultPdoTimeout);
  // A TPDO with the wrong length from node 1.
  r.net.corrupt(0x181, 0x7FF, Corruption::length, 1);
  r.cycles(2);
  EXPECT_TRUE(r.fb.drive[0].faults & kFaultBadPdo);
  EXPECT_EQ(r.fb.drive[1].faults, 0u);
  // An RPDO with the wrong length is refused by the drive with EMCY 0x8210.
  r.net.corrupt(0x202, 0x7FF, Corruption::length, 1);
  r.cycles(2);
  EXPECT_EQ(r.drives[1]->bad_pdos, 1u);
  EXPECT_EQ(r.fb.drive[1].last_emcy.code, 0x8210);
  EXPECT_TRUE(r.fb.drive[1].faults & kFaultEmcy);
}

TEST(Master, BusOffAndErrorPassiveAreReported) {
  Rig r;
  r.master->start();
  r.cycles(2);
  r.net.inject_error_frame(make_error_frame(0x4 /*CAN_ERR_CRTL*/, 0x20 /*TX_PASSIVE*/, 0, 128, 0));
  r.cycle();
  EXPECT_EQ(r.fb.bus_state, BusState::error_passive);
  EXPECT_FALSE(r.fb.bus_off_seen);
  r.net.set_bus_off(true);
  r.master->read(r.fb);
  EXPECT_EQ(r.fb.bus_state, BusState::bus_off);
  EXPECT_TRUE(r.fb.bus_off_seen);
  EXPECT_EQ(r.master->write(r.cmd).code, Code::bus_off);
  EXPECT_TRUE(r.fb.any_fault());
  r.clock.wait(r.period_ns());
  r.net.set_bus_off(false);
  r.cycle();
  r.cycle();
  EXPECT_EQ(r.fb.bus_state, BusState::error_active);
  EXPECT_TRUE(r.fb.bus_off_seen);  // latched
  r.master->reset_faults();
  r.cycle();
  EXPECT_FALSE(r.fb.bus_off_seen);
}

TEST(Master, DriveRebootIsSeen) {
  Rig r;
  r.master->start();
  r.cycles(3);
  r.drives[0]->power_on(r.clock.now_ns());  // a power glitch: boot-up, pre-operational
  r.cycles(5);
  EXPECT_TRUE(r.fb.drive[0].faults & kFaultNmtState);
  EXPECT_TRUE(r.fb.drive[0].faults & kFaultPdoTimeout);
}

TEST(Master, StartFailsClearlyForSilentWrongAndLateDrives) {
  {
    Rig r;
    r.drives[1]->go_silent(true);
    const std::string e = error_of([&] { r.master->start(); });
    EXPECT_NE(e.find("boot-up"), std::string::npos) << e;
    EXPECT_NE(e.find("node 2 (y)"), std::string::npos) << e;
    EXPECT_FALSE(r.master->started());
  }
  {
    MasterConfig c = three_drives();
    c.reset_on_start = false;
    Rig r(c);
    r.drives[2]->go_silent(true);
    const std::string e = error_of([&] { r.master->start(); });
    EXPECT_NE(e.find("node 3 (z): SDO read 0x1000:00 got no answer within 100 ms"), std::string::npos) << e;
  }
  {
    MasterConfig c = three_drives();
    c.reset_on_start = false;  // a reset would restore the drive's own 0x1000
    Rig r(c);
    r.drives[0]->od_set(0x1000, 0, 0x00000191);  // a CiA 401 I/O module
    const std::string e = error_of([&] { r.master->start(); });
    EXPECT_NE(e.find("node 1 (x): device type 0x1000 = 0x00000191 is not a CiA 402 drive"), std::string::npos) << e;
  }
  {
    // Reset communication restores 0x1000 from the drive's defaults, so break it after boot.
    MasterConfig c = three_drives();
    c.reset_on_start = false;
    Rig r(c);
    r.drives[1]->od_set(0x6061, 0, 0);  // ignores the mode: the read-back catches it
    // Make 0x6060 writes not reach 0x6061 by setting the display after every poll.
    r.clock.set_hook([&](std::int64_t now) {
      for (auto& d : r.drives) d->poll(now);
      r.drives[1]->od_set(0x6061, 0, 0);
    });
    const std::string e = error_of([&] { r.master->start(); });
    EXPECT_NE(e.find("node 2 (y): modes of operation display (cyclic synchronous torque = 10) 0x6061:00 reads back 0x00000000"),
              std::string::npos) << e;
  }
  {
    Rig r;
    r.drives[0]->answer_late(300'000'000);
    const std::string e = error_of([&] { r.master->start(); });
    EXPECT_NE(e.find("SDO timeout"), std::string::npos) << e;
  }
}

TEST(Master, SdoHelpersNameNodeObjectAndAbort) {
  Rig r;
  r.master->start();
  const std::string e = error_of([&] { r.master->sdo_write_u8(2, 0x6060, 0, 3); });
  EXPECT_EQ(e, "node 2 (y): SDO write 0x6060:00 aborted by the drive: 0x06090030 Invalid value for parameter (download only)");
  const std::string e2 = error_of([&] { (void)r.master->sdo_read(1, 0x5FFF, 0); });
  EXPECT_NE(e2.find("0x06020000 Object does not exist"), std::string::npos) << e2;
  // Segmented through the helpers.
  std::vector<std::uint8_t> blob(30);
  for (std::size_t i = 0; i < blob.size(); ++i) blob[i] = static_cast<std::uint8_t>(i);
  r.master->sdo_write(3, 0x2000, 0, blob);
  EXPECT_EQ(r.master->sdo_read(3, 0x2000, 0), blob);
  const auto name = r.master->sdo_read(1, 0x1008, 0);
  EXPECT_EQ(std::string(name.begin(), name.end()), "cpm virtual CiA 402 drive");
}

TEST(Master, ConfigurationIsValidatedWithTheKey) {
  FakeClock clock;
  FakeCanNetwork net(clock);
  auto& port = net.add_port("m");
  auto msg = [&](const std::function<void(MasterConfig&)>& edit) {
    MasterConfig c = three_drives();
    edit(c);
    return error_of([&] { Master m(port, clock, c); });
  };
  EXPECT_NE(msg([](auto& c) { c.drives[1].counts_per_m = 0; }).find("drives[1].counts_per_m"), std::string::npos);
  EXPECT_NE(msg([](auto& c) { c.drives[2].node_id = 1; }).find("drives[2].node_id: 1 is also drives[0].node_id"), std::string::npos);
  EXPECT_NE(msg([](auto& c) { c.drives[0].node_id = 128; }).find("drives[0].node_id"), std::string::npos);
  EXPECT_NE(msg([](auto& c) { c.drives[0].rated_force_n = std::nan(""); }).find("rated_force_n"), std::string::npos);
  EXPECT_NE(msg([](auto& c) { c.drives[0].direction = 0; }).find("direction"), std::string::npos);
  EXPECT_NE(msg([](auto& c) { c.drives[0].max_torque_permille = 40000; }).find("max_torque_permille"), std::string::npos);
  EXPECT_NE(msg([](auto& c) { c.bitrate = 300e3; }).find("bitrate"), std::string::npos);
  EXPECT_NE(msg([](auto& c) { c.rate_hz = 3000; }).find("rate_hz"), std::string::npos);  // 333.33 us
  EXPECT_NE(msg([](auto& c) { c.heartbeat_timeout_ms = 50; }).find("heartbeat_timeout_ms"), std::string::npos);
  EXPECT_NE(msg([](auto& c) { c.master_node_id = 2; }).find("equals master_node_id"), std::string::npos);
  EXPECT_NE(msg([](auto& c) { c.abort_connection_option = 4; }).find("abort_connection_option"), std::string::npos);
  EXPECT_NE(msg([](auto& c) { c.drives.clear(); }).find("drives"), std::string::npos);
  EXPECT_EQ(msg([](auto&) {}), "");
}

TEST(Master, CycleCallsBeforeStartDoNothing) {
  Rig r;
  EXPECT_EQ(r.master->write(r.cmd).code, Code::not_started);
  CanFrame f;
  int from_master = 0, boot_ups = 0;
  while (r.drive_ports[0]->receive(f).ok()) {
    if (f.cob_id() == 0x080 || (f.cob_id() & 0x780) == 0x200) ++from_master;
    if ((f.cob_id() & 0x780) == 0x700) ++boot_ups;
  }
  EXPECT_EQ(from_master, 0);
  EXPECT_EQ(boot_ups, 2);  // the other drives' boot-up messages: the port does receive
}
