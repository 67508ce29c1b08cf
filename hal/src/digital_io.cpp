// SPDX-License-Identifier: Apache-2.0
#include "cpm/hal/digital_io.hpp"

namespace cpm::hal {

const char* line_name(Line l) noexcept {
  switch (l) {
    case Line::estop: return "estop";
    case Line::limit_low_x: return "limit_low_x";
    case Line::limit_low_y: return "limit_low_y";
    case Line::limit_low_z: return "limit_low_z";
    case Line::limit_high_x: return "limit_high_x";
    case Line::limit_high_y: return "limit_high_y";
    case Line::limit_high_z: return "limit_high_z";
    case Line::drive_enable: return "drive_enable";
    case Line::brake_release_z: return "brake_release_z";
    case Line::home_x: return "home_x";
    case Line::home_y: return "home_y";
    case Line::home_z: return "home_z";
    case Line::index_x: return "index_x";
    case Line::index_y: return "index_y";
    case Line::index_z: return "index_z";
    case Line::count_: break;
  }
  return "invalid";
}

void validate(const DigitalIoConfig& cfg) {
  auto key = [](std::size_t i) { return std::string("gpio.") + line_name(static_cast<Line>(i)); };
  if (!cfg[Line::estop].present) throw Error("gpio.estop: the emergency-stop input is required");
  if (!cfg[Line::drive_enable].present) throw Error("gpio.drive_enable: the drive-enable output is required");
  if (cfg.consumer.empty()) throw Error("gpio.consumer: must not be empty");
  for (std::size_t i = 0; i < kLineCount; ++i) {
    const LineConfig& l = cfg.lines[i];
    if (!l.present) continue;
    if (l.offset < 0 && l.name.empty()) throw Error(key(i) + ": give a line name, or a chip and an offset");
    if (l.offset >= 0 && l.chip.empty()) throw Error(key(i) + ": offset " + std::to_string(l.offset) + " needs a chip");
    for (std::size_t j = 0; j < i; ++j) {
      const LineConfig& o = cfg.lines[j];
      if (!o.present) continue;
      const bool same = (l.offset >= 0) ? (o.offset == l.offset && o.chip == l.chip)
                                        : (o.offset < 0 && o.name == l.name && o.chip == l.chip);
      if (same) throw Error(key(i) + ": same line as " + key(j));
    }
  }
}

Status FakeDigitalIo::read(DigitalInputs& in) noexcept {
  if (fail_reads) {
    in = DigitalInputs{};  // estop asserted
    return {Code::io_error, -1, 5};
  }
  in = inputs;
  return {};
}

Status FakeDigitalIo::write(const DigitalOutputs& out) noexcept {
  if (fail_writes) return {Code::io_error, -1, 5};
  outputs = out;
  ++writes;
  return {};
}

}  // namespace cpm::hal
