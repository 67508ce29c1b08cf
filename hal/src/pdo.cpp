// SPDX-License-Identifier: Apache-2.0
#include "cpm/hal/pdo.hpp"

#include <cmath>

#include "cpm/hal/canopen.hpp"

namespace cpm::hal::pdo {

using canopen::get_u16;
using canopen::get_u32;
using canopen::put_u16;

double position_m(std::int32_t counts, const Scaling& s) noexcept {
  return s.direction * static_cast<double>(counts) / s.counts_per_m + s.position_offset_m;
}

double velocity_mps(std::int32_t units, const Scaling& s) noexcept {
  return s.direction * static_cast<double>(units) / s.velocity_units_per_mps;
}

double force_n(std::int16_t permille, const Scaling& s) noexcept {
  return s.direction * static_cast<double>(permille) * s.rated_force_n / 1000.0;
}

std::int16_t torque_permille(double force, const Scaling& s, Code& code) noexcept {
  code = Code::ok;
  if (!std::isfinite(force)) {
    code = Code::not_finite;
    return 0;
  }
  const double raw = s.direction * force * 1000.0 / s.rated_force_n;
  const double lim = s.max_torque_permille;
  if (raw > lim) {
    code = Code::saturated;
    return static_cast<std::int16_t>(s.max_torque_permille);
  }
  if (raw < -lim) {
    code = Code::saturated;
    return static_cast<std::int16_t>(-s.max_torque_permille);
  }
  return static_cast<std::int16_t>(std::lround(raw));
}

CanFrame pack_rpdo1(std::uint8_t node, std::uint16_t controlword, std::int16_t torque) noexcept {
  CanFrame f;
  f.id = kRpdo1.cob_base + node;
  f.len = 4;
  put_u16(&f.data[0], controlword);
  put_u16(&f.data[2], static_cast<std::uint16_t>(torque));
  return f;
}

CanFrame pack_rpdo1_homing(std::uint8_t node, std::uint16_t controlword, std::int16_t torque, std::int8_t mode) noexcept {
  CanFrame f = pack_rpdo1(node, controlword, torque);
  f.len = static_cast<std::uint8_t>(kRpdo1Homing.bytes());
  f.data[4] = static_cast<std::uint8_t>(mode);
  return f;
}

bool unpack_tpdo1_homing(const CanFrame& f, std::uint16_t& statusword, std::int32_t& position,
                         std::int8_t& mode_display) noexcept {
  if (f.len != kTpdo1Homing.bytes()) return false;
  statusword = get_u16(&f.data[0]);
  position = static_cast<std::int32_t>(get_u32(&f.data[2]));
  mode_display = static_cast<std::int8_t>(f.data[6]);
  return true;
}

bool unpack_tpdo1(const CanFrame& f, std::uint16_t& statusword, std::int32_t& position) noexcept {
  if (f.len != kTpdo1.bytes()) return false;
  statusword = get_u16(&f.data[0]);
  position = static_cast<std::int32_t>(get_u32(&f.data[2]));
  return true;
}

bool unpack_tpdo2(const CanFrame& f, std::int32_t& velocity) noexcept {
  if (f.len != kTpdo2.bytes()) return false;
  velocity = static_cast<std::int32_t>(get_u32(&f.data[0]));
  return true;
}

}  // namespace cpm::hal::pdo
