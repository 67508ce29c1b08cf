// SPDX-License-Identifier: Apache-2.0
// CAN over Linux SocketCAN (CAN_RAW), non-blocking, with error frames.
#pragma once

#include <string>

#include "cpm/hal/can.hpp"

namespace cpm::hal {

class SocketCanBus final : public CanBus {
 public:
  // Opens a CAN_RAW socket on `interface` (e.g. "can0", "vcan0"), non-blocking,
  // with every error class enabled (CAN_RAW_ERR_FILTER) and kernel receive
  // timestamps (SO_TIMESTAMPNS). Throws Error naming the interface and the
  // failing call; when the kernel has no CAN support at all it says so.
  explicit SocketCanBus(const std::string& interface);
  ~SocketCanBus() override;
  SocketCanBus(const SocketCanBus&) = delete;
  SocketCanBus& operator=(const SocketCanBus&) = delete;

  Status send(const CanFrame& f) noexcept override;
  Status receive(CanFrame& f) noexcept override;
  void set_filters(std::span<const CanFilter> filters, bool error_frames) override;
  bool wait_receivable(std::int64_t timeout_ns) override;
  [[nodiscard]] const CanStats& stats() const noexcept override { return stats_; }
  [[nodiscard]] const std::string& interface() const noexcept { return interface_; }

  // Whether this kernel can open PF_CAN sockets at all. When not, `why`
  // gets a sentence saying so (for skip messages).
  static bool available(std::string* why = nullptr);

 private:
  std::string interface_;
  int fd_ = -1;
  CanStats stats_;
};

}  // namespace cpm::hal
