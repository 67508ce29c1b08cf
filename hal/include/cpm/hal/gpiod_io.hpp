// SPDX-License-Identifier: Apache-2.0
// DigitalIo through libgpiod 1.6 (Debian bookworm's libgpiod-dev, v1 API).
#pragma once

#include <array>

#include "cpm/hal/digital_io.hpp"

struct gpiod_chip;
struct gpiod_line;

namespace cpm::hal {

class GpiodIo final : public DigitalIo {
 public:
  // Validates `cfg`, opens the chips, finds and requests every present line
  // (outputs start at their safe level, false). Throws Error naming the line
  // key, chip and offset or name on any failure.
  explicit GpiodIo(const DigitalIoConfig& cfg);
  ~GpiodIo() override;
  GpiodIo(const GpiodIo&) = delete;
  GpiodIo& operator=(const GpiodIo&) = delete;

  Status read(DigitalInputs& in) noexcept override;
  Status write(const DigitalOutputs& out) noexcept override;

  // Whether GPIO character devices exist here (/dev/gpiochip*); `why` says
  // what is missing when not.
  static bool available(std::string* why = nullptr);

 private:
  struct Held {
    gpiod_chip* chip = nullptr;
    gpiod_line* line = nullptr;
  };
  void release() noexcept;
  DigitalIoConfig cfg_;
  std::array<Held, kLineCount> held_{};
};

}  // namespace cpm::hal
