// SPDX-License-Identifier: Apache-2.0
// The per-cycle path allocates nothing: read() and write() of the master
// (and the fake bus under them) with every global allocation counted, in
// cyclic synchronous torque and through a homing cycle.
#include <gtest/gtest.h>

#include "cpm/hal/digital_io.hpp"
#include "rig.hpp"
#include "support/allocation_counter.hpp"

using namespace cpm::hal;
using namespace cpm::hal::test;

TEST(Allocation, MasterCycleAllocatesNothingEvenUnderFaults) {
  Rig r;
  r.master->start();
  r.target_all(cia402::Target::enabled);
  ASSERT_GE(r.until_all(cia402::State::operation_enabled), 0);
  for (std::size_t i = 0; i < 3; ++i) r.cmd.drive[i].force_n = 10.0 * static_cast<double>(i + 1);
  // The counter must see allocations at all, or the test proves nothing.
  const long before_probe = static_cast<long>(cpm::test::allocations_on_this_thread());
  void* probe = ::operator new(16);  // a direct call: never elided
  ::operator delete(probe);
  ASSERT_EQ(static_cast<long>(cpm::test::allocations_on_this_thread()), before_probe + 1);

  long in_cycle = 0;
  for (int k = 0; k < 200; ++k) {
    if (k == 50) r.drives[1]->inject_fault(0x2310, 0x03);   // EMCY and fault on the bus
    if (k == 80) r.net.set_bus_off(true);
    if (k == 81) r.net.set_bus_off(false);
    if (k == 100) r.drives[2]->stop_heartbeat(true);
    if (k == 120) r.cmd.drive[0].force_n = 1e12;            // saturation
    const long a0 = static_cast<long>(cpm::test::allocations_on_this_thread());
    r.master->read(r.fb);
    r.master->write(r.cmd);
    in_cycle += static_cast<long>(cpm::test::allocations_on_this_thread()) - a0;
    r.clock.wait(r.period_ns());  // the drives (test side) may allocate
  }
  EXPECT_EQ(in_cycle, 0);
  EXPECT_TRUE(r.fb.any_fault());  // the faults did happen

  // A homing cycle: the mode switch, the rising edge, the drive's own
  // procedure to completion, an interruption and a homing error, read back
  // through the 5- and 7-byte PDOs.
  MasterConfig hc = three_drives();
  for (auto& d : hc.drives) d.homing = {true, 21, 0.02, 0.002, 0.2, 0.1};
  Rig h(hc);
  for (std::size_t i = 0; i < 3; ++i) {
    h.pos_m[i] = 0.06;
    h.sensors[i].home_below = 0.05;
    h.sensors[i].limit_low = 0.005;
  }
  h.sensors[2].home_dead = true;  // drive 3 ends in homing error at the limit
  h.master->start();
  h.target_all(cia402::Target::enabled);
  ASSERT_GE(h.until_all(cia402::State::operation_enabled), 0);
  for (std::size_t i = 0; i < 3; ++i) h.cmd.drive[i].homing = h.cmd.drive[i].start_homing = true;
  long in_homing = 0;
  for (int k = 0; k < 3000; ++k) {
    if (k == 100) h.cmd.drive[1].start_homing = false;  // interrupted
    if (k == 200) h.cmd.drive[1].start_homing = true;   // and started again
    const long a0 = static_cast<long>(cpm::test::allocations_on_this_thread());
    h.master->read(h.fb);
    h.master->write(h.cmd);
    in_homing += static_cast<long>(cpm::test::allocations_on_this_thread()) - a0;
    h.clock.wait(h.period_ns());
  }
  EXPECT_EQ(in_homing, 0);
  EXPECT_EQ(h.fb.drive[0].homing, cia402::HomingStatus::completed);
  EXPECT_EQ(h.fb.drive[1].homing, cia402::HomingStatus::completed);
  EXPECT_EQ(h.fb.drive[2].homing, cia402::HomingStatus::error);

  FakeDigitalIo io;
  DigitalInputs in;
  const long a0 = static_cast<long>(cpm::test::allocations_on_this_thread());
  for (int k = 0; k < 100; ++k) {
    io.read(in);
    io.write(DigitalOutputs{true, true});
  }
  EXPECT_EQ(static_cast<long>(cpm::test::allocations_on_this_thread()) - a0, 0);
}
