// SPDX-License-Identifier: Apache-2.0
// The fixed PDO mappings of this master and their packing and scaling.
//
//   RPDO1 (0x200 + node, synchronous): controlword 0x6040 (u16), target torque 0x6071 (i16)  4 bytes
//   TPDO1 (0x180 + node, every SYNC):  statusword 0x6041 (u16), position actual 0x6064 (i32) 6 bytes
//   TPDO2 (0x280 + node, every SYNC):  velocity actual 0x606C (i32)                          4 bytes
//
// A drive that homes with its own homing mode (DriveHomingConfig::enabled)
// carries the mode in the same PDOs, so the cycle can switch between cyclic
// synchronous torque and homing without an SDO:
//   RPDO1: controlword, target torque, modes of operation 0x6060 (i8)             5 bytes
//   TPDO1: statusword, position actual, modes of operation display 0x6061 (i8)   7 bytes
// Drives without it keep the 4- and 6-byte PDOs (and the bus load of those).
//
// Why this split: the statusword travels with the position it was sampled
// with, so a state change and the feedback of the same SYNC are never torn
// apart; everything needed per cycle would be 10 bytes, more than one frame.
// TPDO2 is optional (MasterConfig::velocity_from_drive): without it the
// master differentiates the SYNC-sampled positions, which saves a frame per
// drive and is what lets three drives run at 1 kHz on a 1 Mbit/s bus
// (see bus_load.hpp and docs/hal.md for the figures).
#pragma once

#include <array>
#include <cstdint>

#include "cpm/hal/can.hpp"
#include "cpm/hal/common.hpp"

namespace cpm::hal::pdo {

struct MappedObject {
  std::uint16_t index;
  std::uint8_t sub;
  std::uint8_t bits;
};
// The 32-bit value written to a mapping sub-index: index, sub-index, length in bits.
constexpr std::uint32_t mapping_entry(MappedObject o) noexcept {
  return (std::uint32_t{o.index} << 16) | (std::uint32_t{o.sub} << 8) | o.bits;
}

struct Layout {
  bool receive;                  // RPDO (master -> drive) or TPDO
  std::uint8_t number;           // 1..4
  std::uint32_t cob_base;        // + node id
  std::uint16_t comm_index;      // 0x1400 + n - 1 or 0x1800 + n - 1
  std::uint16_t map_index;       // 0x1600 + n - 1 or 0x1A00 + n - 1
  std::uint8_t transmission_type;  // 1: every SYNC (TPDO); 0..240 synchronous (RPDO)
  std::uint8_t count;
  std::array<MappedObject, 3> objects;
  [[nodiscard]] constexpr int bytes() const noexcept {
    int b = 0;
    for (int i = 0; i < count; ++i) b += objects[static_cast<std::size_t>(i)].bits / 8;
    return b;
  }
};

inline constexpr Layout kRpdo1{true, 1, 0x200, 0x1400, 0x1600, 1, 2, {{{0x6040, 0, 16}, {0x6071, 0, 16}}}};
inline constexpr Layout kTpdo1{false, 1, 0x180, 0x1800, 0x1A00, 1, 2, {{{0x6041, 0, 16}, {0x6064, 0, 32}}}};
inline constexpr Layout kTpdo2{false, 2, 0x280, 0x1801, 0x1A01, 1, 1, {{{0x606C, 0, 32}, {0, 0, 0}}}};
// The homing drive's RPDO1 and TPDO1 (same PDOs and COB-IDs, one more object).
inline constexpr Layout kRpdo1Homing{true, 1, 0x200, 0x1400, 0x1600, 1, 3, {{{0x6040, 0, 16}, {0x6071, 0, 16}, {0x6060, 0, 8}}}};
inline constexpr Layout kTpdo1Homing{false, 1, 0x180, 0x1800, 0x1A00, 1, 3, {{{0x6041, 0, 16}, {0x6064, 0, 32}, {0x6061, 0, 8}}}};

// Drive units <-> SI, from the drive's configuration.
struct Scaling {
  double counts_per_m = 0;          // position 0x6064 counts per metre
  double velocity_units_per_mps = 0;  // 0x606C units per m/s
  double rated_force_n = 0;         // force at 1000 per mille of 0x6071
  int max_torque_permille = 1000;   // saturation of 0x6071, 1..32767
  int direction = 1;                // +1, or -1 when the drive counts the other way
  double position_offset_m = 0;     // actuator displacement at count 0
};

double position_m(std::int32_t counts, const Scaling& s) noexcept;
double velocity_mps(std::int32_t units, const Scaling& s) noexcept;
double force_n(std::int16_t permille, const Scaling& s) noexcept;
// Force in N to 0x6071 per mille: rounded, clamped to +-max_torque_permille
// (Code::saturated), NaN/inf give 0 (Code::not_finite).
std::int16_t torque_permille(double force_n, const Scaling& s, Code& code) noexcept;

CanFrame pack_rpdo1(std::uint8_t node, std::uint16_t controlword, std::int16_t torque) noexcept;
CanFrame pack_rpdo1_homing(std::uint8_t node, std::uint16_t controlword, std::int16_t torque, std::int8_t mode) noexcept;
// False when the frame has the wrong length for the mapping.
bool unpack_tpdo1(const CanFrame& f, std::uint16_t& statusword, std::int32_t& position) noexcept;
bool unpack_tpdo1_homing(const CanFrame& f, std::uint16_t& statusword, std::int32_t& position,
                         std::int8_t& mode_display) noexcept;
bool unpack_tpdo2(const CanFrame& f, std::int32_t& velocity) noexcept;

}  // namespace cpm::hal::pdo
