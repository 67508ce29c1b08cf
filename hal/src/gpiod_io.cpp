// SPDX-License-Identifier: Apache-2.0
#include "cpm/hal/gpiod_io.hpp"

#include <gpiod.h>

#include <cerrno>
#include <filesystem>

namespace cpm::hal {

bool GpiodIo::available(std::string* why) {
  std::error_code ec;
  for (const auto& e : std::filesystem::directory_iterator("/dev", ec))
    if (e.path().filename().string().rfind("gpiochip", 0) == 0) return true;
  if (why) *why = "no GPIO character device (/dev/gpiochip*) on this machine (the kernel has no GPIO chip; the SIL VM runner provides gpio-sim)";
  return false;
}

GpiodIo::GpiodIo(const DigitalIoConfig& cfg) : cfg_(cfg) {
  validate(cfg_);
  for (std::size_t i = 0; i < kLineCount; ++i) {
    const LineConfig& l = cfg_.lines[i];
    if (!l.present) continue;
    const auto line = static_cast<Line>(i);
    const std::string key = std::string("gpio.") + line_name(line);
    const std::string where = l.offset >= 0 ? l.chip + " offset " + std::to_string(l.offset)
                                            : "line \"" + l.name + "\"" + (l.chip.empty() ? "" : " on " + l.chip);
    auto fail = [&](const std::string& what) {
      const int err = errno;
      release();
      throw Error(errno_text(key + " (" + where + "): " + what, err));
    };
    Held& h = held_[i];
    if (l.chip.empty()) {
      h.line = gpiod_line_find(l.name.c_str());
      if (h.line == nullptr) {
        if (errno == 0) errno = ENOENT;
        fail("no GPIO line of that name");
      }
      h.chip = gpiod_line_get_chip(h.line);
    } else {
      h.chip = gpiod_chip_open_lookup(l.chip.c_str());
      if (h.chip == nullptr) fail("cannot open the GPIO chip");
      h.line = l.offset >= 0 ? gpiod_chip_get_line(h.chip, static_cast<unsigned>(l.offset))
                             : gpiod_chip_find_line(h.chip, l.name.c_str());
      if (h.line == nullptr) {
        if (errno == 0) errno = ENOENT;
        fail("no such line on the chip");
      }
    }
    const int flags = l.active_low ? GPIOD_LINE_REQUEST_FLAG_ACTIVE_LOW : 0;
    const int r = is_output(line) ? gpiod_line_request_output_flags(h.line, cfg_.consumer.c_str(), flags, 0)
                                  : gpiod_line_request_input_flags(h.line, cfg_.consumer.c_str(), flags);
    if (r < 0) fail(is_output(line) ? "cannot request the line as output" : "cannot request the line as input");
  }
}

GpiodIo::~GpiodIo() {
  (void)safe_state();
  release();
}

void GpiodIo::release() noexcept {
  for (auto& h : held_) {
    if (h.line != nullptr && gpiod_line_is_requested(h.line)) gpiod_line_release(h.line);
    if (h.chip != nullptr) gpiod_chip_close(h.chip);
    h = Held{};
  }
}

Status GpiodIo::read(DigitalInputs& in) noexcept {
  auto get = [&](Line l, bool& v) -> Status {
    const Held& h = held_[static_cast<std::size_t>(l)];
    if (h.line == nullptr) {
      v = false;
      return {};
    }
    const int r = gpiod_line_get_value(h.line);
    if (r < 0) return {Code::io_error, static_cast<std::int8_t>(l), errno};
    v = r != 0;
    return {};
  };
  DigitalInputs got;
  Status st = get(Line::estop, got.estop);
  for (int a = 0; a < kAxes && st.ok(); ++a) {
    st = get(static_cast<Line>(static_cast<int>(Line::limit_low_x) + a), got.limit_low[static_cast<std::size_t>(a)]);
    if (st.ok()) st = get(static_cast<Line>(static_cast<int>(Line::limit_high_x) + a), got.limit_high[static_cast<std::size_t>(a)]);
    if (st.ok()) st = get(static_cast<Line>(static_cast<int>(Line::home_x) + a), got.home[static_cast<std::size_t>(a)]);
    if (st.ok()) st = get(static_cast<Line>(static_cast<int>(Line::index_x) + a), got.index[static_cast<std::size_t>(a)]);
  }
  in = st.ok() ? got : DigitalInputs{};  // on error: estop asserted
  return st;
}

Status GpiodIo::write(const DigitalOutputs& out) noexcept {
  auto set = [&](Line l, bool v) -> Status {
    const Held& h = held_[static_cast<std::size_t>(l)];
    if (h.line == nullptr) return {};
    if (gpiod_line_set_value(h.line, v ? 1 : 0) < 0) return {Code::io_error, static_cast<std::int8_t>(l), errno};
    return {};
  };
  const Status a = set(Line::drive_enable, out.drive_enable);
  const Status b = set(Line::brake_release_z, out.brake_release_z);
  return a.ok() ? b : a;
}

}  // namespace cpm::hal
