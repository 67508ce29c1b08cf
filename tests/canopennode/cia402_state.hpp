// SPDX-License-Identifier: Apache-2.0
// A small CiA 402 drive state machine (IEC 61800-7-201, the device control
// state table), written for the CANopenNode drive nodes from the profile's
// tables and deliberately not shared with hal/cia402: a misreading there
// must not be repeated here, or the independent check would share it.
#pragma once

#include <cstdint>

namespace cpm::canopennode {

enum class DriveState : std::uint8_t {
  switch_on_disabled,
  ready_to_switch_on,
  switched_on,
  operation_enabled,
  quick_stop_active,
  fault_reaction_active,
  fault,
};

inline const char* name(DriveState s) {
  switch (s) {
    case DriveState::switch_on_disabled: return "switch on disabled";
    case DriveState::ready_to_switch_on: return "ready to switch on";
    case DriveState::switched_on: return "switched on";
    case DriveState::operation_enabled: return "operation enabled";
    case DriveState::quick_stop_active: return "quick stop active";
    case DriveState::fault_reaction_active: return "fault reaction active";
    case DriveState::fault: return "fault";
  }
  return "?";
}

// Statusword bits 0-6 per state (profile table "state coding"): ready to
// switch on (0), switched on (1), operation enabled (2), fault (3), voltage
// enabled (4), quick stop (5, active low), switch on disabled (6).
inline std::uint16_t state_bits(DriveState s) {
  switch (s) {
    case DriveState::switch_on_disabled: return 0x0040;
    case DriveState::ready_to_switch_on: return 0x0031;
    case DriveState::switched_on: return 0x0033;
    case DriveState::operation_enabled: return 0x0037;
    case DriveState::quick_stop_active: return 0x0017;
    case DriveState::fault_reaction_active: return 0x001F;
    case DriveState::fault: return 0x0018;
  }
  return 0;
}

// The next state for a controlword (bits 0-3 and 7), `previous` the last
// controlword received (fault reset is the rising edge of bit 7). Commands
// a state does not accept leave it as it is.
inline DriveState next_state(DriveState s, std::uint16_t cw, std::uint16_t previous) {
  const bool so = cw & 0x1, ev = cw & 0x2, qs = cw & 0x4, eo = cw & 0x8, fr = cw & 0x80;
  if (s == DriveState::fault) return fr && !(previous & 0x80) ? DriveState::switch_on_disabled : s;  // 15
  if (s == DriveState::fault_reaction_active) return s;
  if (fr) return s;                       // bit 7 outside fault: no device control command
  if (!ev) return DriveState::switch_on_disabled;  // disable voltage: 7, 9, 10, 12
  if (!qs) {                              // quick stop
    if (s == DriveState::operation_enabled) return DriveState::quick_stop_active;  // 11
    if (s == DriveState::quick_stop_active) return s;
    return DriveState::switch_on_disabled;  // 7, 10
  }
  switch (s) {
    case DriveState::switch_on_disabled:
      return !so ? DriveState::ready_to_switch_on : s;  // shutdown: 2
    case DriveState::ready_to_switch_on:
      if (!so) return s;
      return eo ? DriveState::operation_enabled : DriveState::switched_on;  // 3 (+4)
    case DriveState::switched_on:
      if (!so) return DriveState::ready_to_switch_on;  // 6
      return eo ? DriveState::operation_enabled : s;   // 4
    case DriveState::operation_enabled:
      if (!so) return DriveState::ready_to_switch_on;  // 8
      return eo ? s : DriveState::switched_on;         // 5
    case DriveState::quick_stop_active:
      return s;  // 16 only with quick stop options 5-8, not offered here
    default:
      return s;
  }
}

}  // namespace cpm::canopennode
