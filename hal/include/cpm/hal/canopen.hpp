// SPDX-License-Identifier: Apache-2.0
// CANopen (CiA 301) basics shared by the master and the virtual drive:
// COB-IDs of the predefined connection set, NMT, heartbeat, EMCY, SDO
// command specifiers and abort codes. Pure functions, no allocation.
#pragma once

#include <cstddef>
#include <cstdint>

#include "cpm/hal/can.hpp"
#include "cpm/hal/names.hpp"

namespace cpm::hal::canopen {

// Predefined connection set (CiA 301 §7.3.5): function code + node id.
inline constexpr std::uint32_t kNmt = 0x000;
inline constexpr std::uint32_t kSync = 0x080;
inline constexpr std::uint32_t kEmcyBase = 0x080;     // + node (1..127)
inline constexpr std::uint32_t kTpdo1Base = 0x180;
inline constexpr std::uint32_t kRpdo1Base = 0x200;
inline constexpr std::uint32_t kTpdo2Base = 0x280;
inline constexpr std::uint32_t kRpdo2Base = 0x300;
inline constexpr std::uint32_t kTpdo3Base = 0x380;
inline constexpr std::uint32_t kRpdo3Base = 0x400;
inline constexpr std::uint32_t kTpdo4Base = 0x480;
inline constexpr std::uint32_t kRpdo4Base = 0x500;
inline constexpr std::uint32_t kSdoTxBase = 0x580;    // server -> client
inline constexpr std::uint32_t kSdoRxBase = 0x600;    // client -> server
inline constexpr std::uint32_t kHeartbeatBase = 0x700;
inline constexpr std::uint32_t kCobIdInvalid = 0x80000000U;  // bit 31 of a PDO COB-ID: PDO not valid

// Communication objects (CiA 301 §7.5.2) the master sets up in each drive.
inline constexpr std::uint16_t kDeviceType = 0x1000;              // u32: bits 0-15 the device profile
inline constexpr std::uint16_t kConsumerHeartbeatTime = 0x1016;   // u32 array: node id << 16 | timeout ms
inline constexpr std::uint16_t kProducerHeartbeatTime = 0x1017;   // u16, ms
inline constexpr std::uint32_t kProfileDrive = 402;               // kDeviceType's profile of a CiA 402 drive

constexpr bool valid_node_id(int id) noexcept { return id >= 1 && id <= 127; }

// ---- NMT
enum class NmtCommand : std::uint8_t {
  start = 0x01,              // -> operational
  stop = 0x02,               // -> stopped
  enter_preoperational = 0x80,
  reset_node = 0x81,
  reset_communication = 0x82,
};
// State a node reports in its heartbeat (and boot-up = 0).
enum class NmtState : std::uint8_t {
  boot_up = 0x00,
  stopped = 0x04,
  operational = 0x05,
  preoperational = 0x7F,
  unknown = 0xFF,            // nothing heard yet
};
// A state's names, one row per state (the table in canopen.cpp); the
// unknown state's row for a value outside the enum.
using NmtNames = Names<NmtState>;
const NmtNames& names(NmtState s) noexcept;
const char* nmt_state_name(NmtState s) noexcept;  // names(s).full
CanFrame make_nmt(NmtCommand c, std::uint8_t node) noexcept;   // node 0: all nodes
CanFrame make_heartbeat(std::uint8_t node, NmtState s) noexcept;
CanFrame make_sync() noexcept;

// ---- EMCY (CiA 301 §7.2.7): error code (u16), error register (u8), 5 bytes
// manufacturer-specific.
struct Emcy {
  std::uint16_t code = 0;
  std::uint8_t error_register = 0;
  std::array<std::uint8_t, 5> manufacturer{};
};
// False if the frame is not 8 bytes long.
bool decode_emcy(const CanFrame& f, Emcy& out) noexcept;
CanFrame make_emcy(std::uint8_t node, const Emcy& e) noexcept;
// "0x2310 current, device output side: continuous over-current" — the
// class of the code (CiA 301 table 21) and, for the CiA 402 codes a drive
// commonly sends, the specific meaning. Static strings.
const char* emcy_class_text(std::uint16_t code) noexcept;
const char* emcy_code_text(std::uint16_t code) noexcept;   // nullptr when only the class is known
// Error register bits (0x1001) as text, e.g. "generic, current". Writes to out.
std::size_t error_register_text(std::uint8_t reg, char* out, std::size_t size) noexcept;
// Whole EMCY as one readable line. No allocation.
std::size_t describe_emcy(std::uint8_t node, const Emcy& e, char* out, std::size_t size) noexcept;

// ---- SDO (CiA 301 §7.2.4.3)
// Client command specifiers (bits 7..5 of byte 0 of a request).
inline constexpr std::uint8_t kCcsDownloadSegment = 0;
inline constexpr std::uint8_t kCcsInitiateDownload = 1;
inline constexpr std::uint8_t kCcsInitiateUpload = 2;
inline constexpr std::uint8_t kCcsUploadSegment = 3;
inline constexpr std::uint8_t kCsAbort = 4;
// Server command specifiers (responses).
inline constexpr std::uint8_t kScsUploadSegment = 0;
inline constexpr std::uint8_t kScsDownloadSegment = 1;
inline constexpr std::uint8_t kScsInitiateUpload = 2;
inline constexpr std::uint8_t kScsInitiateDownload = 3;

// Abort codes (CiA 301 table 22), the ones a drive or this master uses.
enum SdoAbort : std::uint32_t {
  kAbortToggle = 0x05030000,
  kAbortTimeout = 0x05040000,
  kAbortCommand = 0x05040001,
  kAbortOutOfMemory = 0x05040005,
  kAbortUnsupportedAccess = 0x06010000,
  kAbortWriteOnly = 0x06010001,
  kAbortReadOnly = 0x06010002,
  kAbortNoObject = 0x06020000,
  kAbortNotMappable = 0x06040041,
  kAbortPdoLength = 0x06040042,
  kAbortParamIncompatible = 0x06040043,
  kAbortInternalIncompatible = 0x06040047,
  kAbortHardware = 0x06060000,
  kAbortTypeLength = 0x06070010,
  kAbortTypeTooHigh = 0x06070012,
  kAbortTypeTooLow = 0x06070013,
  kAbortNoSubindex = 0x06090011,
  kAbortInvalidValue = 0x06090030,
  kAbortValueTooHigh = 0x06090031,
  kAbortValueTooLow = 0x06090032,
  kAbortMaxLessMin = 0x06090036,
  kAbortNoResource = 0x060A0023,
  kAbortGeneral = 0x08000000,
  kAbortDataStore = 0x08000020,
  kAbortLocalControl = 0x08000021,
  kAbortDeviceState = 0x08000022,
  kAbortNoDictionary = 0x08000023,
  kAbortNoData = 0x08000024,
};
// The standard's text for an abort code ("Object does not exist in the object
// dictionary"); "unknown abort code" otherwise. Static strings.
const char* sdo_abort_text(std::uint32_t code) noexcept;
CanFrame make_sdo_abort(std::uint32_t cob, std::uint16_t index, std::uint8_t sub, std::uint32_t code) noexcept;

// ---- little-endian helpers
inline void put_u16(std::uint8_t* p, std::uint16_t v) noexcept {
  p[0] = static_cast<std::uint8_t>(v);
  p[1] = static_cast<std::uint8_t>(v >> 8);
}
inline void put_u32(std::uint8_t* p, std::uint32_t v) noexcept {
  for (int i = 0; i < 4; ++i) p[i] = static_cast<std::uint8_t>(v >> (8 * i));
}
inline std::uint16_t get_u16(const std::uint8_t* p) noexcept {
  return static_cast<std::uint16_t>(p[0] | (p[1] << 8));
}
inline std::uint32_t get_u32(const std::uint8_t* p) noexcept {
  return std::uint32_t{p[0]} | (std::uint32_t{p[1]} << 8) | (std::uint32_t{p[2]} << 16) |
         (std::uint32_t{p[3]} << 24);
}

}  // namespace cpm::hal::canopen
