// SPDX-License-Identifier: Apache-2.0
// The CAN bus seam: classic CAN 2.0 frames, non-blocking send and receive,
// acceptance filters, receive timestamps and error frames.
//
// Error frames use the Linux SocketCAN encoding (CAN_ERR_FLAG in the id,
// class bits in the id, details in data[]) on every implementation, so the
// fake bus and SocketCAN share one decoder (decode_error_frame).
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <span>

#include "cpm/hal/common.hpp"

namespace cpm::hal {

struct CanFrame {
  // 11-bit or 29-bit identifier, plus the flags below (Linux encoding).
  std::uint32_t id = 0;
  std::uint8_t len = 0;                    // data length, 0..8
  std::array<std::uint8_t, 8> data{};
  // Receive time in ns: the bus implementation's clock (SocketCAN: kernel
  // receive time, CLOCK_REALTIME; fake bus: its Clock). 0 on frames to send.
  std::int64_t timestamp_ns = 0;

  static constexpr std::uint32_t kExtendedFlag = 0x80000000U;  // CAN_EFF_FLAG
  static constexpr std::uint32_t kRtrFlag = 0x40000000U;       // CAN_RTR_FLAG
  static constexpr std::uint32_t kErrorFlag = 0x20000000U;     // CAN_ERR_FLAG
  static constexpr std::uint32_t kStandardMask = 0x7FFU;
  static constexpr std::uint32_t kExtendedMask = 0x1FFFFFFFU;

  [[nodiscard]] bool is_error() const noexcept { return (id & kErrorFlag) != 0; }
  [[nodiscard]] bool is_extended() const noexcept { return (id & kExtendedFlag) != 0; }
  [[nodiscard]] bool is_rtr() const noexcept { return (id & kRtrFlag) != 0; }
  // The identifier without flags.
  [[nodiscard]] std::uint32_t cob_id() const noexcept {
    return id & (is_extended() ? kExtendedMask : kStandardMask);
  }
};

// Acceptance filter as in SocketCAN: a frame passes when
// (frame.id & mask) == (id & mask). Flags take part in the comparison.
struct CanFilter {
  std::uint32_t id = 0;
  std::uint32_t mask = 0;
};

// The controller's fault confinement state (ISO 11898-1).
enum class BusState : std::uint8_t { error_active = 0, error_warning, error_passive, bus_off };
const char* bus_state_name(BusState s) noexcept;

// What an error frame says, decoded. Plain data.
struct CanErrorInfo {
  bool tx_timeout = false;
  bool lost_arbitration = false;
  bool controller = false;       // controller problem (details below)
  bool protocol = false;         // protocol violation (bit, form, stuff, ...)
  bool transceiver = false;
  bool no_ack = false;
  bool bus_off = false;
  bool bus_error = false;
  bool restarted = false;        // controller restarted after bus-off
  bool rx_overflow = false;
  bool tx_overflow = false;
  bool warning = false;          // rx or tx error counter reached 96
  bool passive = false;          // rx or tx error counter reached 128
  bool back_to_active = false;   // recovered to error active
  std::uint8_t protocol_type = 0;      // data[2], CAN_ERR_PROT_*
  std::uint8_t protocol_location = 0;  // data[3], CAN_ERR_PROT_LOC_*
  std::uint8_t tx_error_count = 0;     // data[6]
  std::uint8_t rx_error_count = 0;     // data[7]
  // The bus state this frame moves to, if it says one (bus_off, passive,
  // warning, restarted/active); `has_state` false when it does not.
  bool has_state = false;
  BusState state = BusState::error_active;
};

// Decode a Linux-encoded error frame. A frame without kErrorFlag gives an
// empty CanErrorInfo.
CanErrorInfo decode_error_frame(const CanFrame& f) noexcept;
// Build one (the fake bus and tests inject these).
CanFrame make_error_frame(std::uint32_t class_bits, std::uint8_t ctrl = 0, std::uint8_t prot = 0,
                          std::uint8_t tx_count = 0, std::uint8_t rx_count = 0) noexcept;
// Human text, e.g. "bus-off; controller: rx passive (tx 0, rx 130)". Writes
// into `out` (always NUL-terminated), returns the length. No allocation.
std::size_t describe_error_frame(const CanErrorInfo& e, char* out, std::size_t size) noexcept;

// Counters kept by every bus implementation.
struct CanStats {
  std::uint64_t tx_frames = 0;
  std::uint64_t rx_frames = 0;
  std::uint64_t error_frames = 0;
  std::uint64_t tx_would_block = 0;
  std::uint64_t rx_dropped = 0;   // frames lost before we read them (kernel or fake queue overflow)
};

// A CAN channel. send/receive are non-blocking and allocation-free.
class CanBus {
 public:
  virtual ~CanBus() = default;
  // Queue one frame. would_block when the transmit queue is full, bus_off
  // when the controller is bus-off, io_error otherwise (errno in detail).
  virtual Status send(const CanFrame& f) noexcept = 0;
  // Take one received frame (data or error frame). would_block when none.
  virtual Status receive(CanFrame& f) noexcept = 0;
  // Replace the acceptance filters (non-real-time). An empty span accepts
  // every data frame. Error frames are delivered when `error_frames` is set.
  virtual void set_filters(std::span<const CanFilter> filters, bool error_frames) = 0;
  // Block up to `timeout_ns` for a frame to be receivable (non-real-time
  // start-up loops). Returns true when one may be. The fake bus returns at
  // once: its time moves with its Clock.
  virtual bool wait_receivable(std::int64_t timeout_ns) = 0;
  [[nodiscard]] virtual const CanStats& stats() const noexcept = 0;
};

}  // namespace cpm::hal
