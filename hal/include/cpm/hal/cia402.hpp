// SPDX-License-Identifier: Apache-2.0
// CiA 402 (IEC 61800-7-201) drive state machine: statusword decoding,
// controlword commands and the state table, shared by the master (which
// plans a path of commands toward a target) and the virtual drive (which
// applies them). Pure functions, no allocation.
#pragma once

#include <cstdint>

#include "cpm/hal/names.hpp"

namespace cpm::hal::cia402 {

// Object indices of the profile used here.
inline constexpr std::uint16_t kControlword = 0x6040;        // u16, rw
inline constexpr std::uint16_t kStatusword = 0x6041;         // u16, ro
inline constexpr std::uint16_t kAbortConnectionOption = 0x6007;  // i16: 0 none, 1 fault, 2 disable voltage, 3 quick stop
inline constexpr std::uint16_t kErrorCode = 0x603F;          // u16, ro: last error code
inline constexpr std::uint16_t kQuickStopOption = 0x605A;    // i16
inline constexpr std::uint16_t kModesOfOperation = 0x6060;   // i8
inline constexpr std::uint16_t kModesDisplay = 0x6061;       // i8, ro
inline constexpr std::uint16_t kPositionActual = 0x6064;     // i32, counts
inline constexpr std::uint16_t kVelocityActual = 0x606C;     // i32, counts/s (velocity units)
inline constexpr std::uint16_t kTargetTorque = 0x6071;       // i16, per mille of rated torque (force)
inline constexpr std::uint16_t kMaxTorque = 0x6072;          // u16, per mille of rated torque
inline constexpr std::uint16_t kRatedTorque = 0x6076;        // u32, mNm (mN for a linear drive)
inline constexpr std::uint16_t kTorqueActual = 0x6077;       // i16, per mille of rated torque
inline constexpr std::uint16_t kInterpolationPeriod = 0x60C2;  // rec: sub1 u8 value, sub2 i8 exponent (s)
inline constexpr std::int8_t kModeCyclicSyncTorque = 10;     // CST
inline constexpr std::int8_t kModeHoming = 6;
// Modes of operation (0x6060, shown in 0x6061), one row per mode of the
// standard (the table in cia402.cpp).
struct OperationMode {
  std::int8_t code;
  const char* brief;  // "CST"
  const char* full;   // "cyclic synchronous torque"
};
// nullptr for a code the standard does not name (0: no mode yet; below 0:
// the manufacturer's).
const OperationMode* operation_mode(std::int8_t code) noexcept;
// Homing mode objects.
inline constexpr std::uint16_t kHomeOffset = 0x607C;         // i32, position units
inline constexpr std::uint16_t kHomingMethod = 0x6098;       // i8
inline constexpr std::uint16_t kHomingSpeeds = 0x6099;       // rec: sub1 search for switch, sub2 search for zero (u32, velocity units)
inline constexpr std::uint16_t kHomingAcceleration = 0x609A; // u32, acceleration units (velocity units per s)
// Controlword bit 7: fault reset, acted on at its rising edge.
inline constexpr std::uint16_t kCwFaultReset = 1u << 7;
// Controlword bit 4 in homing mode: homing operation start (rising edge starts, 0 interrupts).
inline constexpr std::uint16_t kCwHomingStart = 1u << 4;
// Statusword bits 12, 13 in homing mode (bit 10: target reached).
inline constexpr std::uint16_t kSwHomingAttained = 1u << 12;
inline constexpr std::uint16_t kSwHomingError = 1u << 13;

// The homing status of a statusword in homing mode (CiA 402 homing mode,
// the table of bits 13, 12, 10).
enum class HomingStatus : std::uint8_t {
  idle,          // not started, or not in homing mode
  in_progress,   // 0 0 0
  interrupted,   // 0 0 1: interrupted or not started
  attained,      // 0 1 0: attained, target not reached (still moving to the home position)
  completed,     // 0 1 1: homing completed successfully
  error,         // 1 x x: homing error (velocity not zero: 1 0 0 / 1 1 0; zero: 1 0 1)
};
HomingStatus decode_homing(std::uint16_t sw) noexcept;
const char* homing_status_name(HomingStatus h) noexcept;

enum class State : std::uint8_t {
  not_ready_to_switch_on,
  switch_on_disabled,
  ready_to_switch_on,
  switched_on,
  operation_enabled,
  quick_stop_active,
  fault_reaction_active,
  fault,
  unknown,  // a statusword that matches no row of the table
};
// A state's names, one row per state (the table in cia402.cpp; `full` as
// the standard says it); the unknown state's row for a value outside the enum.
using StateNames = Names<State>;
const StateNames& names(State s) noexcept;
const char* state_name(State s) noexcept;  // names(s).full

// The state a statusword reports (CiA 402 statusword table: bits 0-3, 5, 6).
State decode_statusword(std::uint16_t sw) noexcept;

// Statusword bits other than the state.
inline constexpr std::uint16_t kSwVoltageEnabled = 1u << 4;
inline constexpr std::uint16_t kSwWarning = 1u << 7;
inline constexpr std::uint16_t kSwRemote = 1u << 9;
inline constexpr std::uint16_t kSwTargetReached = 1u << 10;
inline constexpr std::uint16_t kSwInternalLimit = 1u << 11;
inline constexpr std::uint16_t kSwFollowsCommand = 1u << 12;  // CSP/CSV/CST: drive follows the command value
// The state bits a drive reports in a state (bits 0-3, 5, 6).
std::uint16_t statusword_state_bits(State s) noexcept;

// Device control commands (controlword bits 0-3 and 7).
enum class Command : std::uint8_t {
  shutdown,          // 0x06: -> ready to switch on (2, 6, 8)
  switch_on,         // 0x07: -> switched on (3); also "disable operation" (5)
  enable_operation,  // 0x0F: -> operation enabled (4, 16); from ready: 3 + 4
  disable_voltage,   // 0x00: -> switch on disabled (7, 9, 10, 12)
  quick_stop,        // 0x02: -> quick stop active (11) or switch on disabled (7, 10)
  fault_reset,       // 0x80 (rising edge of bit 7): fault -> switch on disabled (15)
};
const char* command_name(Command c) noexcept;
std::uint16_t controlword(Command c) noexcept;
// The command a controlword means (bit 7 taken as fault reset; the edge is
// the drive's business).
Command decode_controlword(std::uint16_t cw) noexcept;

// One step of the drive's state table for a command. `transition` is the
// number of the state table (0 when the command leaves the state as it is:
// allowed but no change; -1 when the command is not allowed in that state,
// which the drive ignores). `quick_stop_stays` is true when the quick stop
// option code (0x605A = 5..8) keeps the drive in quick stop active, so that
// enable operation may return to operation enabled (transition 16).
struct Step {
  State next;
  int transition;
};
Step apply(State s, Command c, bool quick_stop_stays = false) noexcept;

// What the master wants a drive to be.
enum class Target : std::uint8_t {
  disabled,           // switch on disabled: power stage off
  enabled,            // operation enabled: follows target torque
  quick_stop,         // quick stop active (from operation enabled), else disabled
};
const char* target_name(Target t) noexcept;

// The command that moves a drive in state `s` one step toward `t`. A drive
// in fault stays there (disable voltage) unless `reset_fault` is set, in
// which case fault_reset is returned (the caller makes the rising edge by
// sending disable_voltage in between).
Command next_command(State s, Target t, bool reset_fault) noexcept;

}  // namespace cpm::hal::cia402
