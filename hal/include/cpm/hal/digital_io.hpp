// SPDX-License-Identifier: Apache-2.0
// Digital I/O of the machine: named lines, read and written as a whole once
// per cycle. Values are logical (true = asserted), whatever the wiring: the
// active level of each line comes from the configuration.
//
//   inputs   estop            true = emergency stop requested (an NC chain opened: wire it active-low)
//            limit_low[i]     true = axis i at its low-end limit switch
//            limit_high[i]    true = axis i at its high-end limit switch
//            home[i]          true = axis i's home switch actuated (homing by the daemon)
//            index[i]         true = axis i's encoder index pulse (read as a level each cycle)
//   outputs  drive_enable     true = drives' power / enable chain closed
//            brake_release_z  true = z brake released (coil energised); false = brake engaged
//
// All outputs false is the safe state: drives disabled, z brake engaged.
#pragma once

#include <array>
#include <cstdint>
#include <string>

#include "cpm/hal/common.hpp"

namespace cpm::hal {

inline constexpr int kAxes = 3;

enum class Line : std::uint8_t {
  estop = 0,
  limit_low_x, limit_low_y, limit_low_z,
  limit_high_x, limit_high_y, limit_high_z,
  drive_enable,
  brake_release_z,
  home_x, home_y, home_z,
  index_x, index_y, index_z,
  count_,
};
inline constexpr std::size_t kLineCount = static_cast<std::size_t>(Line::count_);
const char* line_name(Line l) noexcept;         // "estop", "limit_low_x", ...
inline bool is_output(Line l) noexcept { return l == Line::drive_enable || l == Line::brake_release_z; }

struct LineConfig {
  bool present = false;      // absent lines read false (inputs) or are not driven (outputs)
  std::string chip;          // "gpiochip0", "/dev/gpiochip0" or a chip label; empty: find `name` on any chip
  std::string name;          // line name (as in the device tree / gpio-sim); used when offset < 0
  int offset = -1;           // line offset on `chip`
  bool active_low = false;   // asserted = electrically low
};

struct DigitalIoConfig {
  std::array<LineConfig, kLineCount> lines{};
  std::string consumer = "cpmd";  // label the kernel shows for our requests
  LineConfig& operator[](Line l) { return lines[static_cast<std::size_t>(l)]; }
  const LineConfig& operator[](Line l) const { return lines[static_cast<std::size_t>(l)]; }
};
// Throws Error naming the key ("gpio.limit_low_x: ...") of a bad line: the
// estop input and drive_enable output are required, every present line needs
// a name or chip + offset, no line may be used twice.
void validate(const DigitalIoConfig& cfg);

struct DigitalInputs {
  bool estop = true;   // until read, assume the worst
  std::array<bool, kAxes> limit_low{};
  std::array<bool, kAxes> limit_high{};
  std::array<bool, kAxes> home{};
  std::array<bool, kAxes> index{};
};
struct DigitalOutputs {
  bool drive_enable = false;
  bool brake_release_z = false;
};

class DigitalIo {
 public:
  virtual ~DigitalIo() = default;
  // Per cycle: allocation-free, never throw. On error the inputs are set to
  // their unsafe reading (estop asserted) and io_error is returned.
  virtual Status read(DigitalInputs& in) noexcept = 0;
  virtual Status write(const DigitalOutputs& out) noexcept = 0;
  // Drive every output to its safe level (all false).
  Status safe_state() noexcept { return write(DigitalOutputs{}); }
};

// A fake for tests: inputs set by the test, outputs recorded, faults injected.
class FakeDigitalIo final : public DigitalIo {
 public:
  Status read(DigitalInputs& in) noexcept override;
  Status write(const DigitalOutputs& out) noexcept override;
  DigitalInputs inputs{.estop = false, .limit_low = {}, .limit_high = {}, .home = {}, .index = {}};
  DigitalOutputs outputs{};
  std::uint64_t writes = 0;
  bool fail_reads = false;    // read() reports io_error
  bool fail_writes = false;   // write() reports io_error (outputs unchanged)
};

}  // namespace cpm::hal
