// SPDX-License-Identifier: Apache-2.0
// Bus load of a cyclic CANopen configuration: frames and worst-case stuffed
// bits per cycle against the bitrate.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

namespace cpm::hal {

// Worst-case length on the wire, in bits, of a classic CAN data frame with
// `data_bytes` (0..8) bytes, including the worst-case stuff bits and the
// 3-bit interframe space (Davis, Burns, Bril, Lukkien 2007, eq. for C_m):
//   standard id: 8n + 47 + floor((34 + 8n - 1) / 4)   (n = 8: 135 bits)
//   extended id: 8n + 67 + floor((54 + 8n - 1) / 4)   (n = 8: 160 bits)
constexpr int can_frame_bits_worst(int data_bytes, bool extended = false) noexcept {
  const int g = extended ? 54 : 34;
  return g + 8 * data_bytes + 13 + (g + 8 * data_bytes - 1) / 4;
}

struct BusLoadInput {
  double rate_hz = 1000.0;     // cycle (SYNC) rate
  double bitrate = 1e6;        // bit/s
  std::vector<int> cyclic_frames;  // data length of each frame sent every cycle
  struct Periodic {
    int data_bytes;
    double period_s;           // e.g. a heartbeat every 0.1 s
  };
  std::vector<Periodic> periodic;  // frames sent on their own period
  double max_load = 0.8;       // refuse above this average load (0..1]
};

struct BusLoad {
  int frames_per_cycle = 0;          // cyclic frames
  int bits_per_cycle = 0;            // their worst-case stuffed bits
  double periodic_bits_per_cycle = 0;  // average over cycles
  // Blocking: a cycle's frames may wait for one longer frame already on
  // the wire (the longest, 8 bytes: an SDO or heartbeat started just before SYNC).
  int blocking_bits = 0;
  double bits_available = 0;         // bitrate / rate
  double load = 0;                   // (bits_per_cycle + periodic average) / bits_available
  double worst_cycle_load = 0;       // (bits_per_cycle + blocking_bits) / bits_available
  double max_rate_hz = 0;            // highest rate with load <= max_load and worst cycle <= 1
  bool fits = false;                 // load <= max_load and worst_cycle_load <= 1
  // One line with the figures, e.g. "3 drives ... 970 bits per 1000-bit cycle (97.0 %) ..."
  [[nodiscard]] std::string describe() const;
};

BusLoad compute_bus_load(const BusLoadInput& in);

}  // namespace cpm::hal
