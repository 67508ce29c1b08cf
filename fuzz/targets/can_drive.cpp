// SPDX-License-Identifier: Apache-2.0
// The virtual CiA 402 drive's handlers (NMT, SDO server with expedited and
// segmented transfers, RPDOs with the mapping the SDOs set, SYNC, master
// heartbeat) on the fake bus, fed by a hostile master port. Oracle: nothing
// throws out of poll(), the drive's statusword always decodes to a CiA 402
// state, the torque it applies stays within its 0x6072 max torque and is
// zero unless in operation enabled (in cyclic torque or its own homing
// mode), and every answer it sends is a well-formed frame (SDO answers 8
// bytes on 0x580 + node).
//
// Script: can_common.hpp records; op bits 3-6 = time passing after the
// frame, in 0.5 ms steps (heartbeats, consumer timeout, late answers).
#include <cmath>

#include "can_common.hpp"
#include "cpm/hal/fake_can.hpp"
#include "cpm/hal/virtual_drive.hpp"

using namespace cpm;
using namespace cpm::hal;

namespace {
constexpr std::uint32_t kIds[8] = {0x000, 0x080, canopen::kRpdo1Base, canopen::kRpdo2Base, canopen::kSdoRxBase,
                                   canopen::kSdoRxBase, canopen::kHeartbeatBase + 123, 0xFFFF};
}

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  if (size > 16 * 1024) return 0;
  FakeClock clock{0, 100'000};
  FakeCanNetwork net{clock};
  FakeCanPort& master = net.add_port("master");
  FakeCanPort& port = net.add_port("drive1");
  VirtualDriveConfig vc;
  vc.node_id = 1;
  vc.tune_loops(10, 400, 1e6, 1e-3);  // homing mode (6) makes its own torque: within 0x6072 too
  VirtualDrive drive(port, vc);
  drive.on_sync = [](VirtualDrive& d) { d.set_actual(1000, -20, d.applied_torque()); };
  auto check = [&] {
    FUZZ_CHECK(cia402::decode_statusword(drive.statusword()) != cia402::State::unknown,
               "the drive's statusword decodes to no state");
    const int t = drive.applied_torque();
    if (drive.state() != cia402::State::operation_enabled) FUZZ_CHECK(t == 0, "torque outside operation enabled");
    FUZZ_CHECK(std::abs(t) <= static_cast<int>(drive.od_value(cia402::kMaxTorque, 0)), "torque beyond 0x6072");
    CanFrame f;
    while (master.receive(f).ok()) {
      FUZZ_CHECK(f.len <= 8, "a frame longer than 8 bytes");
      if (f.cob_id() == canopen::kSdoTxBase + 1) FUZZ_CHECK(f.len == 8, "an SDO answer that is not 8 bytes");
    }
  };
  try {
    drive.power_on(clock.now_ns());
    check();
    fuzz::Bytes in(data, size);
    fuzz::ScriptFrame s;
    int records = 0;
    while (records++ < 1024 && fuzz::next_frame(in, kIds, s)) {
      (void)master.send(s.frame);
      clock.advance(100'000);  // the frame arrives
      drive.poll(clock.now_ns());
      check();
      for (int i = 0; i < s.after(); ++i) {
        clock.advance(500'000);
        drive.poll(clock.now_ns());
        check();
      }
    }
  } catch (const std::exception& e) {
    fuzz::fail(__FILE__, __LINE__, std::string("the drive threw: ") + e.what());
  }
  return 0;
}
