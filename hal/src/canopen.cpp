// SPDX-License-Identifier: Apache-2.0
#include "cpm/hal/canopen.hpp"

#include <array>
#include <cstdio>

namespace cpm::hal::canopen {

namespace {

constexpr std::array<NmtNames, 5> kNmtNames = {{
    {NmtState::boot_up, "boot_up", "boot-up", "boot-up"},
    {NmtState::stopped, "stopped", "stopped", "stopped"},
    {NmtState::operational, "operational", "op", "operational"},
    {NmtState::preoperational, "pre_operational", "pre-op", "pre-operational"},
    {NmtState::unknown, "unknown", "-", "unknown"},
}};

}  // namespace

const NmtNames& names(NmtState s) noexcept { return find_names(kNmtNames, s); }

const char* nmt_state_name(NmtState s) noexcept { return names(s).full; }

CanFrame make_nmt(NmtCommand c, std::uint8_t node) noexcept {
  CanFrame f;
  f.id = kNmt;
  f.len = 2;
  f.data[0] = static_cast<std::uint8_t>(c);
  f.data[1] = node;
  return f;
}

CanFrame make_heartbeat(std::uint8_t node, NmtState s) noexcept {
  CanFrame f;
  f.id = kHeartbeatBase + node;
  f.len = 1;
  f.data[0] = static_cast<std::uint8_t>(s);
  return f;
}

CanFrame make_sync() noexcept {
  CanFrame f;
  f.id = kSync;
  f.len = 0;
  return f;
}

bool decode_emcy(const CanFrame& f, Emcy& out) noexcept {
  if (f.len != 8) return false;
  out.code = get_u16(&f.data[0]);
  out.error_register = f.data[2];
  for (int i = 0; i < 5; ++i) out.manufacturer[static_cast<std::size_t>(i)] = f.data[static_cast<std::size_t>(3 + i)];
  return true;
}

CanFrame make_emcy(std::uint8_t node, const Emcy& e) noexcept {
  CanFrame f;
  f.id = kEmcyBase + node;
  f.len = 8;
  put_u16(&f.data[0], e.code);
  f.data[2] = e.error_register;
  for (int i = 0; i < 5; ++i) f.data[static_cast<std::size_t>(3 + i)] = e.manufacturer[static_cast<std::size_t>(i)];
  return f;
}

const char* emcy_class_text(std::uint16_t code) noexcept {
  const unsigned hi = code >> 8;
  switch (hi) {
    case 0x00: return "error reset or no error";
    case 0x10: return "generic error";
    case 0x20: return "current";
    case 0x21: return "current, device input side";
    case 0x22: return "current inside the device";
    case 0x23: return "current, device output side";
    case 0x30: return "voltage";
    case 0x31: return "mains voltage";
    case 0x32: return "voltage inside the device";
    case 0x33: return "output voltage";
    case 0x40: return "temperature";
    case 0x41: return "ambient temperature";
    case 0x42: return "device temperature";
    case 0x43: return "drive temperature";
    case 0x50: return "device hardware";
    case 0x60: return "device software";
    case 0x61: return "internal software";
    case 0x62: return "user software";
    case 0x63: return "data set";
    case 0x70: return "additional modules";
    case 0x71: return "motor";
    case 0x73: return "sensor";
    case 0x80: return "monitoring";
    case 0x81: return "communication";
    case 0x82: return "protocol error";
    case 0x84: return "velocity control";
    case 0x85: return "position control";
    case 0x86: return "positioning controller";
    case 0x90: return "external error";
    case 0xF0: return "additional functions";
    case 0xFF: return "device specific";
    default: break;
  }
  switch (hi & 0xF0) {
    case 0x20: return "current";
    case 0x30: return "voltage";
    case 0x40: return "temperature";
    case 0x50: return "device hardware";
    case 0x60: return "device software";
    case 0x70: return "additional modules";
    case 0x80: return "monitoring";
    case 0x90: return "external error";
    default: return "unknown error class";
  }
}

const char* emcy_code_text(std::uint16_t code) noexcept {
  switch (code) {
    case 0x0000: return "error reset";
    case 0x1000: return "generic error";
    case 0x2310: return "continuous over-current";
    case 0x2320: return "short circuit or earth leakage";
    case 0x3210: return "DC link over-voltage";
    case 0x3220: return "DC link under-voltage";
    case 0x4210: return "excess temperature in the device";
    case 0x4310: return "excess temperature of the drive";
    case 0x5530: return "EEPROM (data storage) fault";
    case 0x6010: return "software reset (watchdog)";
    case 0x7121: return "motor blocked";
    case 0x7305: return "incremental sensor 1 fault";
    case 0x8110: return "CAN overrun (frames lost)";
    case 0x8120: return "CAN in error passive mode";
    case 0x8130: return "life guard or heartbeat error";
    case 0x8140: return "recovered from bus-off";
    case 0x8150: return "CAN-ID collision";
    case 0x8210: return "PDO not processed: length error";
    case 0x8220: return "PDO length exceeded";
    case 0x8240: return "unexpected SYNC data length";
    case 0x8250: return "RPDO timeout";
    case 0x8400: return "velocity controller error";
    case 0x8500: return "position controller error";
    case 0x8611: return "following error";
    case 0x8612: return "reference limit";
    case 0x9000: return "external error";
    default: return nullptr;
  }
}

std::size_t error_register_text(std::uint8_t reg, char* out, std::size_t size) noexcept {
  static const char* const names[8] = {"generic", "current", "voltage", "temperature",
                                       "communication", "device profile", "reserved", "manufacturer"};
  if (size == 0) return 0;
  out[0] = '\0';
  std::size_t n = 0;
  for (int b = 0; b < 8; ++b) {
    if (!(reg & (1u << b))) continue;
    const int w = std::snprintf(out + n, size - n, "%s%s", n ? ", " : "", names[b]);
    if (w < 0) break;
    n = n + static_cast<std::size_t>(w) < size ? n + static_cast<std::size_t>(w) : size - 1;
  }
  if (n == 0) n = static_cast<std::size_t>(std::snprintf(out, size, "none")) < size ? 4 : size - 1;
  return n;
}

std::size_t describe_emcy(std::uint8_t node, const Emcy& e, char* out, std::size_t size) noexcept {
  if (size == 0) return 0;
  char reg[96];
  error_register_text(e.error_register, reg, sizeof reg);
  const char* specific = emcy_code_text(e.code);
  const int w = std::snprintf(out, size, "node %u EMCY 0x%04X %s%s%s (error register 0x%02X: %s)",
                              unsigned{node}, unsigned{e.code}, emcy_class_text(e.code),
                              specific ? ": " : "", specific ? specific : "",
                              unsigned{e.error_register}, reg);
  if (w < 0) return 0;
  return static_cast<std::size_t>(w) < size ? static_cast<std::size_t>(w) : size - 1;
}

const char* sdo_abort_text(std::uint32_t code) noexcept {
  switch (code) {
    case 0x05030000: return "Toggle bit not alternated";
    case 0x05040000: return "SDO protocol timed out";
    case 0x05040001: return "Client/server command specifier not valid or unknown";
    case 0x05040002: return "Invalid block size";
    case 0x05040003: return "Invalid sequence number";
    case 0x05040004: return "CRC error";
    case 0x05040005: return "Out of memory";
    case 0x06010000: return "Unsupported access to an object";
    case 0x06010001: return "Attempt to read a write only object";
    case 0x06010002: return "Attempt to write a read only object";
    case 0x06020000: return "Object does not exist in the object dictionary";
    case 0x06040041: return "Object cannot be mapped to the PDO";
    case 0x06040042: return "The number and length of the objects to be mapped would exceed PDO length";
    case 0x06040043: return "General parameter incompatibility reason";
    case 0x06040047: return "General internal incompatibility in the device";
    case 0x06060000: return "Access failed due to a hardware error";
    case 0x06070010: return "Data type does not match, length of service parameter does not match";
    case 0x06070012: return "Data type does not match, length of service parameter too high";
    case 0x06070013: return "Data type does not match, length of service parameter too low";
    case 0x06090011: return "Sub-index does not exist";
    case 0x06090030: return "Invalid value for parameter (download only)";
    case 0x06090031: return "Value of parameter written too high (download only)";
    case 0x06090032: return "Value of parameter written too low (download only)";
    case 0x06090036: return "Maximum value is less than minimum value";
    case 0x060A0023: return "Resource not available: SDO connection";
    case 0x08000000: return "General error";
    case 0x08000020: return "Data cannot be transferred or stored to the application";
    case 0x08000021: return "Data cannot be transferred or stored to the application because of local control";
    case 0x08000022: return "Data cannot be transferred or stored to the application because of the present device state";
    case 0x08000023: return "Object dictionary dynamic generation fails or no object dictionary is present";
    case 0x08000024: return "No data available";
    default: return "unknown abort code";
  }
}

CanFrame make_sdo_abort(std::uint32_t cob, std::uint16_t index, std::uint8_t sub, std::uint32_t code) noexcept {
  CanFrame f;
  f.id = cob;
  f.len = 8;
  f.data[0] = static_cast<std::uint8_t>(kCsAbort << 5);
  put_u16(&f.data[1], index);
  f.data[3] = sub;
  put_u32(&f.data[4], code);
  return f;
}

}  // namespace cpm::hal::canopen
