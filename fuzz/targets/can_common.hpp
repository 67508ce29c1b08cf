// SPDX-License-Identifier: Apache-2.0
// Frame scripts for the CAN targets: each record is
//   op (u8), node (u8), len (u8), len % 9 data bytes
// op bits 0-2 pick the COB-ID family (kIds below, + node % 5, so node 4 is a
// node nobody has and 0 the broadcast), op bit 7 sets RTR, and op bits 3-6
// say how long time passes after the frame (target-specific).
#pragma once

#include "cpm/hal/canopen.hpp"
#include "fuzz_common.hpp"

namespace cpm::fuzz {

struct ScriptFrame {
  hal::CanFrame frame;
  std::uint8_t op = 0, node_byte = 0;
  [[nodiscard]] int after() const { return (op >> 3) & 0x0F; }
};

// Read the next record; false at the end of the input.
inline bool next_frame(Bytes& in, const std::uint32_t (&ids)[8], ScriptFrame& out) {
  if (in.left() < 3) return false;
  out.op = in.u8();
  out.node_byte = in.u8();
  const std::uint8_t len = in.u8() % 9;
  out.frame = hal::CanFrame{};
  const std::uint32_t base = ids[out.op & 7];
  if (base == 0xFFFF) out.frame.id = (std::uint32_t{out.node_byte} << 3 | len) & 0x7FF;  // anything
  else out.frame.id = base + (base == 0x000 || base == 0x080 ? 0 : out.node_byte % 5);
  if (out.op & 0x80) out.frame.id |= hal::CanFrame::kRtrFlag;
  out.frame.len = len;
  in.take(out.frame.data.data(), len);
  return true;
}

}  // namespace cpm::fuzz
