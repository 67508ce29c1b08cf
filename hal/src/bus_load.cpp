// SPDX-License-Identifier: Apache-2.0
#include "cpm/hal/bus_load.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>

namespace cpm::hal {

BusLoad compute_bus_load(const BusLoadInput& in) {
  BusLoad r;
  for (int n : in.cyclic_frames) {
    ++r.frames_per_cycle;
    r.bits_per_cycle += can_frame_bits_worst(n);
  }
  double periodic_bits_per_s = 0.0;
  for (const auto& p : in.periodic) {
    const int bits = can_frame_bits_worst(p.data_bytes);
    periodic_bits_per_s += bits / p.period_s;
  }
  r.blocking_bits = can_frame_bits_worst(8);
  r.periodic_bits_per_cycle = periodic_bits_per_s / in.rate_hz;
  r.bits_available = in.bitrate / in.rate_hz;
  r.load = (r.bits_per_cycle + r.periodic_bits_per_cycle) / r.bits_available;
  r.worst_cycle_load = (r.bits_per_cycle + r.blocking_bits) / r.bits_available;
  r.fits = r.load <= in.max_load && r.worst_cycle_load <= 1.0;
  if (r.bits_per_cycle > 0) {
    const double by_average = (in.max_load * in.bitrate - periodic_bits_per_s) / r.bits_per_cycle;
    const double by_burst = in.bitrate / (r.bits_per_cycle + r.blocking_bits);
    r.max_rate_hz = std::max(0.0, std::min(by_average, by_burst));
  }
  return r;
}

std::string BusLoad::describe() const {
  char buf[400];
  std::snprintf(buf, sizeof buf,
                "%d frames, %d worst-case bits per cycle + %.1f bits of heartbeats on average, "
                "against %.0f bits per cycle: load %.1f %%, worst cycle %.1f %%; highest rate "
                "for this mapping %.0f Hz",
                frames_per_cycle, bits_per_cycle, periodic_bits_per_cycle, bits_available,
                100.0 * load, 100.0 * worst_cycle_load, std::floor(max_rate_hz));
  return buf;
}

}  // namespace cpm::hal
