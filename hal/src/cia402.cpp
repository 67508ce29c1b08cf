// SPDX-License-Identifier: Apache-2.0
#include "cpm/hal/cia402.hpp"

#include <array>

namespace cpm::hal::cia402 {

namespace {

constexpr std::array<StateNames, 9> kStateNames = {{
    {State::not_ready_to_switch_on, "not_ready_to_switch_on", "not ready", "not ready to switch on"},
    {State::switch_on_disabled, "switch_on_disabled", "sw-on disabled", "switch on disabled"},
    {State::ready_to_switch_on, "ready_to_switch_on", "ready", "ready to switch on"},
    {State::switched_on, "switched_on", "switched on", "switched on"},
    {State::operation_enabled, "operation_enabled", "op enabled", "operation enabled"},
    {State::quick_stop_active, "quick_stop_active", "quick stop", "quick stop active"},
    {State::fault_reaction_active, "fault_reaction_active", "fault reaction", "fault reaction active"},
    {State::fault, "fault", "fault", "fault"},
    {State::unknown, "unknown", "unknown", "unknown"},
}};

constexpr std::array<OperationMode, 9> kOperationModes = {{
    {1, "PP", "profile position"},
    {2, "VL", "velocity"},
    {3, "PV", "profile velocity"},
    {4, "PT", "profile torque"},
    {kModeHoming, "home", "homing"},
    {7, "IP", "interpolated position"},
    {8, "CSP", "cyclic synchronous position"},
    {9, "CSV", "cyclic synchronous velocity"},
    {kModeCyclicSyncTorque, "CST", "cyclic synchronous torque"},
}};

}  // namespace

const StateNames& names(State s) noexcept { return find_names(kStateNames, s); }

const char* state_name(State s) noexcept { return names(s).full; }

const OperationMode* operation_mode(std::int8_t code) noexcept {
  for (const OperationMode& m : kOperationModes)
    if (m.code == code) return &m;
  return nullptr;
}

State decode_statusword(std::uint16_t sw) noexcept {
  // The statusword table: masks over bits 0-3 (ready, switched on, operation
  // enabled, fault), 5 (quick stop) and 6 (switch on disabled).
  const unsigned a = sw & 0x4F;  // states where bit 5 does not matter
  const unsigned b = sw & 0x6F;
  if (a == 0x00) return State::not_ready_to_switch_on;
  if (a == 0x40) return State::switch_on_disabled;
  if (b == 0x21) return State::ready_to_switch_on;
  if (b == 0x23) return State::switched_on;
  if (b == 0x27) return State::operation_enabled;
  if (b == 0x07) return State::quick_stop_active;
  if (a == 0x0F) return State::fault_reaction_active;
  if (a == 0x08) return State::fault;
  return State::unknown;
}

std::uint16_t statusword_state_bits(State s) noexcept {
  switch (s) {
    case State::not_ready_to_switch_on: return 0x00;
    case State::switch_on_disabled: return 0x40;
    case State::ready_to_switch_on: return 0x21;
    case State::switched_on: return 0x23;
    case State::operation_enabled: return 0x27;
    case State::quick_stop_active: return 0x07;
    case State::fault_reaction_active: return 0x0F;
    case State::fault: return 0x08;
    case State::unknown: return 0x4F;  // no row of the table
  }
  return 0x4F;
}

const char* command_name(Command c) noexcept {
  switch (c) {
    case Command::shutdown: return "shutdown";
    case Command::switch_on: return "switch on";
    case Command::enable_operation: return "enable operation";
    case Command::disable_voltage: return "disable voltage";
    case Command::quick_stop: return "quick stop";
    case Command::fault_reset: return "fault reset";
  }
  return "invalid";
}

std::uint16_t controlword(Command c) noexcept {
  switch (c) {
    case Command::shutdown: return 0x06;
    case Command::switch_on: return 0x07;
    case Command::enable_operation: return 0x0F;
    case Command::disable_voltage: return 0x00;
    case Command::quick_stop: return 0x02;
    case Command::fault_reset: return kCwFaultReset;
  }
  return 0x00;
}

Command decode_controlword(std::uint16_t cw) noexcept {
  if (cw & kCwFaultReset) return Command::fault_reset;
  if (!(cw & 0x02)) return Command::disable_voltage;  // enable voltage = 0
  if (!(cw & 0x04)) return Command::quick_stop;       // quick stop is active low
  if (!(cw & 0x01)) return Command::shutdown;
  if (!(cw & 0x08)) return Command::switch_on;
  return Command::enable_operation;
}

Step apply(State s, Command c, bool quick_stop_stays) noexcept {
  using S = State;
  using C = Command;
  switch (s) {
    case S::switch_on_disabled:
      if (c == C::shutdown) return {S::ready_to_switch_on, 2};
      if (c == C::disable_voltage || c == C::quick_stop || c == C::fault_reset) return {s, 0};
      return {s, -1};
    case S::ready_to_switch_on:
      if (c == C::switch_on) return {S::switched_on, 3};
      if (c == C::enable_operation) return {S::operation_enabled, 34};  // 3 then 4 at once
      if (c == C::disable_voltage || c == C::quick_stop) return {S::switch_on_disabled, 7};
      if (c == C::shutdown) return {s, 0};
      return {s, -1};
    case S::switched_on:
      if (c == C::enable_operation) return {S::operation_enabled, 4};
      if (c == C::shutdown) return {S::ready_to_switch_on, 6};
      if (c == C::disable_voltage || c == C::quick_stop) return {S::switch_on_disabled, 10};
      if (c == C::switch_on) return {s, 0};
      return {s, -1};
    case S::operation_enabled:
      if (c == C::switch_on) return {S::switched_on, 5};
      if (c == C::shutdown) return {S::ready_to_switch_on, 8};
      if (c == C::disable_voltage) return {S::switch_on_disabled, 9};
      if (c == C::quick_stop) return {S::quick_stop_active, 11};
      if (c == C::enable_operation) return {s, 0};
      return {s, -1};
    case S::quick_stop_active:
      if (c == C::disable_voltage) return {S::switch_on_disabled, 12};
      if (c == C::enable_operation && quick_stop_stays) return {S::operation_enabled, 16};
      if (c == C::quick_stop) return {s, 0};
      return {s, -1};
    case S::fault:
      if (c == C::fault_reset) return {S::switch_on_disabled, 15};
      if (c == C::disable_voltage || c == C::quick_stop) return {s, 0};
      return {s, -1};
    case S::not_ready_to_switch_on:
    case S::fault_reaction_active:
    case S::unknown:
      return {s, -1};  // automatic transitions only
  }
  return {s, -1};
}

HomingStatus decode_homing(std::uint16_t sw) noexcept {
  // CiA 402-2, homing mode: bits 13 (homing error), 12 (homing attained) and
  // 10 (target reached). With bit 13 set, 12 and 10 only say whether the
  // axis still moves (1 1 x is reserved): every such word is an error.
  if (sw & kSwHomingError) return HomingStatus::error;
  const bool attained = (sw & kSwHomingAttained) != 0;
  const bool reached = (sw & kSwTargetReached) != 0;
  if (attained) return reached ? HomingStatus::completed : HomingStatus::attained;
  return reached ? HomingStatus::interrupted : HomingStatus::in_progress;
}

const char* homing_status_name(HomingStatus h) noexcept {
  switch (h) {
    case HomingStatus::idle: return "idle";
    case HomingStatus::in_progress: return "in progress";
    case HomingStatus::interrupted: return "interrupted or not started";
    case HomingStatus::attained: return "attained, target not reached";
    case HomingStatus::completed: return "completed";
    case HomingStatus::error: return "error";
  }
  return "invalid";
}

const char* target_name(Target t) noexcept {
  switch (t) {
    case Target::disabled: return "disabled";
    case Target::enabled: return "enabled";
    case Target::quick_stop: return "quick_stop";
  }
  return "invalid";
}

Command next_command(State s, Target t, bool reset_fault) noexcept {
  using S = State;
  using C = Command;
  if (s == S::fault) return reset_fault ? C::fault_reset : C::disable_voltage;
  switch (t) {
    case Target::disabled:
      return C::disable_voltage;
    case Target::quick_stop:
      return (s == S::operation_enabled || s == S::quick_stop_active) ? C::quick_stop : C::disable_voltage;
    case Target::enabled:
      switch (s) {
        case S::switch_on_disabled: return C::shutdown;
        case S::ready_to_switch_on: return C::switch_on;
        case S::switched_on: return C::enable_operation;
        case S::operation_enabled: return C::enable_operation;
        // Leave quick stop through switch on disabled: the path every drive
        // supports whatever its quick stop option code.
        case S::quick_stop_active: return C::disable_voltage;
        default: return C::disable_voltage;
      }
  }
  return C::disable_voltage;
}

}  // namespace cpm::hal::cia402
