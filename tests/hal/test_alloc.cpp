// The per-cycle path allocates nothing: read() and write() of the master
// (and the fake bus under them) with every global allocation counted.
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

  FakeDigitalIo io;
  DigitalInputs in;
  const long a0 = static_cast<long>(cpm::test::allocations_on_this_thread());
  for (int k = 0; k < 100; ++k) {
    io.read(in);
    io.write(DigitalOutputs{true, true});
  }
  EXPECT_EQ(static_cast<long>(cpm::test::allocations_on_this_thread()) - a0, 0);
}
