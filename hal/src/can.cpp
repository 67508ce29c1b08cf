// SPDX-License-Identifier: Apache-2.0
#include <linux/can.h>
#include <linux/can/error.h>

#include <cstdarg>
#include <cstdio>

#include "cpm/hal/can.hpp"

namespace cpm::hal {

const char* bus_state_name(BusState s) noexcept {
  switch (s) {
    case BusState::error_active: return "error_active";
    case BusState::error_warning: return "error_warning";
    case BusState::error_passive: return "error_passive";
    case BusState::bus_off: return "bus_off";
  }
  return "unknown";
}

CanErrorInfo decode_error_frame(const CanFrame& f) noexcept {
  CanErrorInfo e;
  if (!f.is_error()) return e;
  const std::uint32_t c = f.id;
  e.tx_timeout = (c & CAN_ERR_TX_TIMEOUT) != 0;
  e.lost_arbitration = (c & CAN_ERR_LOSTARB) != 0;
  e.controller = (c & CAN_ERR_CRTL) != 0;
  e.protocol = (c & CAN_ERR_PROT) != 0;
  e.transceiver = (c & CAN_ERR_TRX) != 0;
  e.no_ack = (c & CAN_ERR_ACK) != 0;
  e.bus_off = (c & CAN_ERR_BUSOFF) != 0;
  e.bus_error = (c & CAN_ERR_BUSERROR) != 0;
  e.restarted = (c & CAN_ERR_RESTARTED) != 0;
  // Details are only meaningful with the full 8-byte payload the kernel sends.
  const std::uint8_t ctrl = f.len > 1 ? f.data[1] : 0;
  if (e.controller) {
    e.rx_overflow = (ctrl & CAN_ERR_CRTL_RX_OVERFLOW) != 0;
    e.tx_overflow = (ctrl & CAN_ERR_CRTL_TX_OVERFLOW) != 0;
    e.warning = (ctrl & (CAN_ERR_CRTL_RX_WARNING | CAN_ERR_CRTL_TX_WARNING)) != 0;
    e.passive = (ctrl & (CAN_ERR_CRTL_RX_PASSIVE | CAN_ERR_CRTL_TX_PASSIVE)) != 0;
    e.back_to_active = (ctrl & CAN_ERR_CRTL_ACTIVE) != 0;
  }
  if (e.protocol) {
    e.protocol_type = f.len > 2 ? f.data[2] : 0;
    e.protocol_location = f.len > 3 ? f.data[3] : 0;
  }
  if (f.len > 7) {
    e.tx_error_count = f.data[6];
    e.rx_error_count = f.data[7];
  }
  // The most severe state the frame announces wins.
  if (e.bus_off) {
    e.has_state = true;
    e.state = BusState::bus_off;
  } else if (e.passive) {
    e.has_state = true;
    e.state = BusState::error_passive;
  } else if (e.warning) {
    e.has_state = true;
    e.state = BusState::error_warning;
  } else if (e.restarted || e.back_to_active) {
    e.has_state = true;
    e.state = BusState::error_active;
  }
  return e;
}

CanFrame make_error_frame(std::uint32_t class_bits, std::uint8_t ctrl, std::uint8_t prot,
                          std::uint8_t tx_count, std::uint8_t rx_count) noexcept {
  CanFrame f;
  f.id = CanFrame::kErrorFlag | (class_bits & CAN_ERR_MASK);
  f.len = CAN_ERR_DLC;
  f.data[1] = ctrl;
  f.data[2] = prot;
  f.data[6] = tx_count;
  f.data[7] = rx_count;
  return f;
}

namespace {
struct Writer {
  char* out;
  std::size_t size;
  std::size_t n = 0;
  void add(const char* fmt, ...) __attribute__((format(printf, 2, 3))) {
    if (n + 1 >= size) return;
    va_list ap;
    va_start(ap, fmt);
    const int w = std::vsnprintf(out + n, size - n, fmt, ap);
    va_end(ap);
    if (w > 0) n = (n + static_cast<std::size_t>(w) < size) ? n + static_cast<std::size_t>(w) : size - 1;
  }
  void item(const char* s) { add("%s%s", n ? "; " : "", s); }
};
}  // namespace

std::size_t describe_error_frame(const CanErrorInfo& e, char* out, std::size_t size) noexcept {
  if (size == 0) return 0;
  out[0] = '\0';
  Writer w{out, size};
  if (e.bus_off) w.item("bus-off");
  if (e.restarted) w.item("controller restarted");
  if (e.passive) w.item("error passive");
  else if (e.warning) w.item("error warning");
  if (e.back_to_active) w.item("back to error active");
  if (e.rx_overflow) w.item("rx overflow");
  if (e.tx_overflow) w.item("tx overflow");
  if (e.controller && !(e.passive || e.warning || e.back_to_active || e.rx_overflow || e.tx_overflow))
    w.item("controller problem");
  if (e.protocol) {
    const char* t = "protocol violation";
    if (e.protocol_type & CAN_ERR_PROT_BIT) t = "protocol: bit error";
    else if (e.protocol_type & CAN_ERR_PROT_FORM) t = "protocol: form error";
    else if (e.protocol_type & CAN_ERR_PROT_STUFF) t = "protocol: stuff error";
    else if (e.protocol_type & CAN_ERR_PROT_BIT0) t = "protocol: cannot send dominant bit";
    else if (e.protocol_type & CAN_ERR_PROT_BIT1) t = "protocol: cannot send recessive bit";
    else if (e.protocol_type & CAN_ERR_PROT_OVERLOAD) t = "protocol: bus overload";
    w.item(t);
  }
  if (e.no_ack) w.item("no ACK (no other node on the bus?)");
  if (e.tx_timeout) w.item("tx timeout");
  if (e.lost_arbitration) w.item("lost arbitration");
  if (e.transceiver) w.item("transceiver problem (wiring)");
  if (e.bus_error) w.item("bus error");
  if (e.tx_error_count || e.rx_error_count)
    w.add(" (tx errors %u, rx errors %u)", unsigned{e.tx_error_count}, unsigned{e.rx_error_count});
  if (w.n == 0) w.add("error frame without class");
  return w.n;
}

}  // namespace cpm::hal
