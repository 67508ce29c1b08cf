// SPDX-License-Identifier: Apache-2.0
// The master's frame handlers (TPDO, EMCY, heartbeat, SDO answers, NMT and
// SYNC from a stranger, error frames) against a started master with three
// virtual drives on the fake bus (tests/hal/rig.hpp), while it runs its
// cycle. A hostile node adds frames of its own between the cycles.
// Oracle, every cycle: read() and write() return, the feedback is finite,
// and torque goes only to a drive that reports operation enabled with the
// target enabled, never beyond its max_torque_permille.
//
// Script: can_common.hpp records; op bits 3-6 = cycles to run after the
// frame; node byte bit 5: target enabled (else disabled), bit 6: fault
// reset request, bit 7 with op bit 7: reset_faults(); op & 7 == 7 with
// node byte bit 4: an error frame (bus-off, passive, restarted) instead.
#include <cmath>

#include "can_common.hpp"
#include "hal/rig.hpp"

using namespace cpm;
using namespace cpm::hal;

namespace {
constexpr std::uint32_t kIds[8] = {0x000, 0x080, canopen::kEmcyBase, canopen::kTpdo1Base, canopen::kTpdo2Base,
                                   canopen::kSdoTxBase, canopen::kHeartbeatBase, 0xFFFF};
}

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  if (size > 16 * 1024) return 0;
  test::Rig rig;
  try {
    rig.master->start();
  } catch (const std::exception& e) {
    fuzz::fail(__FILE__, __LINE__, std::string("the clean start-up failed: ") + e.what());
  }
  FakeCanPort& stranger = rig.net.add_port("stranger");
  fuzz::Bytes in(data, size);
  fuzz::ScriptFrame s;
  int records = 0;
  std::array<cia402::State, 3> sent_state{};
  std::array<cia402::Target, 3> sent_target{};
  sent_state.fill(cia402::State::unknown);
  sent_target.fill(cia402::Target::disabled);
  while (records++ < 512 && fuzz::next_frame(in, kIds, s)) {
    if ((s.op & 7) == 7 && (s.node_byte & 0x10)) {
      switch (s.node_byte % 4) {
        case 0: rig.net.set_bus_off(true); break;
        case 1: rig.net.set_bus_off(false); break;
        case 2: rig.net.inject_error_frame(make_error_frame(0x04, 0x20 /* rx passive */)); break;
        default: rig.net.inject_error_frame(make_error_frame(s.frame.data[0], s.frame.data[1], s.frame.data[2],
                                                             s.frame.data[3], s.frame.data[4]));
      }
    } else {
      (void)stranger.send(s.frame);
    }
    rig.target_all((s.node_byte & 0x20) ? cia402::Target::enabled : cia402::Target::disabled);
    for (std::size_t i = 0; i < 3; ++i) {
      rig.cmd.drive[i].force_n = 150.0 * (static_cast<double>(i) - 1.0);
      rig.cmd.drive[i].reset_fault = (s.node_byte & 0x40) != 0;
    }
    if ((s.op & 0x80) && (s.node_byte & 0x80)) rig.master->reset_faults();
    for (int c = 0; c < s.after(); ++c) {
      rig.cycle();
      const Feedback& fb = rig.fb;
      FUZZ_CHECK(fb.count == 3, "feedback lost its drives");
      for (std::size_t i = 0; i < 3; ++i) {
        const DriveFeedback& d = fb.drive[i];
        FUZZ_CHECK(std::isfinite(d.position_m) && std::isfinite(d.velocity_mps), "non-finite feedback");
        // fb reports what the previous cycle's write() sent, on the state it read then.
        if (d.torque_permille != 0) {
          FUZZ_CHECK(sent_state[i] == cia402::State::operation_enabled, "torque sent to a drive not in operation enabled");
          FUZZ_CHECK(sent_target[i] == cia402::Target::enabled, "torque sent without the target enabled");
          FUZZ_CHECK(std::abs(d.torque_permille) <= rig.master->config().drives[i].max_torque_permille,
                     "torque beyond max_torque_permille");
        }
        sent_state[i] = d.state;
        sent_target[i] = rig.cmd.drive[i].target;
      }
    }
  }
  rig.master->stop();
  return 0;
}
