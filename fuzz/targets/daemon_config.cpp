// SPDX-License-Identifier: Apache-2.0
// cpmd's YAML configuration (daemon::parse_config) on arbitrary text.
// Oracle: refused only with cpm::Error or hal::Error (the CANopen section is
// checked by hal::validate); an accepted configuration has the ranges the
// loader promises.
#include <cmath>

#include "cpm/daemon/config.hpp"
#include "cpm/hal/common.hpp"
#include "fuzz_common.hpp"

using namespace cpm;

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::string text(reinterpret_cast<const char*>(data), size);
  daemon::DaemonConfig c;
  // The base folder does not exist: relative paths resolve to nothing readable.
  if (!fuzz::refused_cleanly<hal::Error>([&] { c = daemon::parse_config(text, "fuzz.yaml", "/nonexistent-fuzz"); }))
    return 0;
  FUZZ_CHECK(std::isfinite(c.loop.rate_hz) && c.loop.rate_hz > 0, "accepted a rate that is not a positive number");
  FUZZ_CHECK(c.lcm.state_decimation >= 1, "accepted a state decimation below 1");
  const auto& L = c.limits;
  FUZZ_CHECK(L.workspace_min.allFinite() && L.workspace_max.allFinite(), "accepted non-finite soft limits");
  for (double v : {L.velocity, L.acceleration, L.overspeed, L.force, L.following_error, L.stop_deceleration,
                   L.enable_timeout})
    FUZZ_CHECK(std::isfinite(v) && v > 0, "accepted a limit that is not a finite value > 0");
  FUZZ_CHECK(c.backend == "sim" || c.backend == "canopen", "accepted backend '" + c.backend + "'");
  return 0;
}
