// SPDX-License-Identifier: Apache-2.0
// The CiA 402 state machine against the standard's own tables (statusword
// table, controlword command table, state transition table).
#include <gtest/gtest.h>

#include <set>
#include <string>
#include <tuple>

#include "cpm/hal/cia402.hpp"

using namespace cpm::hal::cia402;

TEST(Cia402, StatuswordTableEveryStateWithDontCareBits) {
  // Rows of the statusword table; x bits given both values.
  struct Row {
    std::uint16_t sw;
    State s;
  };
  const Row rows[] = {
      {0x0000, State::not_ready_to_switch_on}, {0x0020, State::not_ready_to_switch_on},
      {0x0040, State::switch_on_disabled},     {0x0060, State::switch_on_disabled},
      {0x0021, State::ready_to_switch_on},     {0x0031, State::ready_to_switch_on},
      {0x0023, State::switched_on},            {0x0033, State::switched_on},
      {0x0027, State::operation_enabled},      {0x1637, State::operation_enabled},
      {0x0007, State::quick_stop_active},      {0x0017, State::quick_stop_active},
      {0x000F, State::fault_reaction_active},  {0x002F, State::fault_reaction_active},
      {0x0008, State::fault},                  {0x0028, State::fault},
      {0x0238, State::fault},
  };
  for (const auto& r : rows) EXPECT_EQ(decode_statusword(r.sw), r.s) << std::hex << r.sw;
  // High bits (warning, remote, target reached, manufacturer) never change the state.
  for (const auto& r : rows) EXPECT_EQ(decode_statusword(static_cast<std::uint16_t>(r.sw | 0xFE80)), r.s);
  // Patterns in no row of the table.
  EXPECT_EQ(decode_statusword(0x0001), State::unknown);
  EXPECT_EQ(decode_statusword(0x0041), State::unknown);
  EXPECT_EQ(decode_statusword(0x0067), State::unknown);
  // What the drive reports decodes back to its state.
  for (auto s : {State::not_ready_to_switch_on, State::switch_on_disabled, State::ready_to_switch_on,
                 State::switched_on, State::operation_enabled, State::quick_stop_active,
                 State::fault_reaction_active, State::fault})
    EXPECT_EQ(decode_statusword(statusword_state_bits(s)), s) << state_name(s);
}

TEST(Cia402, ControlwordCommandTable) {
  EXPECT_EQ(controlword(Command::shutdown), 0x06);
  EXPECT_EQ(controlword(Command::switch_on), 0x07);
  EXPECT_EQ(controlword(Command::enable_operation), 0x0F);
  EXPECT_EQ(controlword(Command::disable_voltage), 0x00);
  EXPECT_EQ(controlword(Command::quick_stop), 0x02);
  EXPECT_EQ(controlword(Command::fault_reset), 0x80);
  // Don't-care bits of the table: shutdown 0xx110, disable voltage 0xxx0x, quick stop 0xx01x.
  EXPECT_EQ(decode_controlword(0x0E), Command::shutdown);
  for (std::uint16_t cw : {0x00, 0x01, 0x04, 0x05, 0x08, 0x0D}) EXPECT_EQ(decode_controlword(cw), Command::disable_voltage) << cw;
  for (std::uint16_t cw : {0x02, 0x03, 0x0A, 0x0B}) EXPECT_EQ(decode_controlword(cw), Command::quick_stop) << cw;
  EXPECT_EQ(decode_controlword(0x8F), Command::fault_reset);
  for (auto c : {Command::shutdown, Command::switch_on, Command::enable_operation, Command::disable_voltage,
                 Command::quick_stop, Command::fault_reset})
    EXPECT_EQ(decode_controlword(controlword(c)), c) << command_name(c);
}

TEST(Cia402, EveryTransitionOfTheStateTableAndNothingElse) {
  using S = State;
  using C = Command;
  // (from, command, to, transition number) from the standard's table.
  const std::tuple<S, C, S, int> legal[] = {
      {S::switch_on_disabled, C::shutdown, S::ready_to_switch_on, 2},
      {S::ready_to_switch_on, C::switch_on, S::switched_on, 3},
      {S::ready_to_switch_on, C::enable_operation, S::operation_enabled, 34},
      {S::switched_on, C::enable_operation, S::operation_enabled, 4},
      {S::operation_enabled, C::switch_on, S::switched_on, 5},  // disable operation
      {S::switched_on, C::shutdown, S::ready_to_switch_on, 6},
      {S::ready_to_switch_on, C::disable_voltage, S::switch_on_disabled, 7},
      {S::ready_to_switch_on, C::quick_stop, S::switch_on_disabled, 7},
      {S::operation_enabled, C::shutdown, S::ready_to_switch_on, 8},
      {S::operation_enabled, C::disable_voltage, S::switch_on_disabled, 9},
      {S::switched_on, C::disable_voltage, S::switch_on_disabled, 10},
      {S::switched_on, C::quick_stop, S::switch_on_disabled, 10},
      {S::operation_enabled, C::quick_stop, S::quick_stop_active, 11},
      {S::quick_stop_active, C::disable_voltage, S::switch_on_disabled, 12},
      {S::fault, C::fault_reset, S::switch_on_disabled, 15},
  };
  const S states[] = {S::not_ready_to_switch_on, S::switch_on_disabled, S::ready_to_switch_on, S::switched_on,
                      S::operation_enabled, S::quick_stop_active, S::fault_reaction_active, S::fault};
  const C commands[] = {C::shutdown, C::switch_on, C::enable_operation, C::disable_voltage, C::quick_stop, C::fault_reset};
  int moves = 0;
  for (S s : states) {
    for (C c : commands) {
      const Step st = apply(s, c);
      bool listed = false;
      for (const auto& [from, cmd, to, n] : legal) {
        if (from == s && cmd == c) {
          listed = true;
          EXPECT_EQ(st.next, to) << state_name(s) << " + " << command_name(c);
          EXPECT_EQ(st.transition, n) << state_name(s) << " + " << command_name(c);
        }
      }
      if (!listed) {
        // Anything else leaves the state as it is (allowed no-op or ignored).
        EXPECT_EQ(st.next, s) << state_name(s) << " + " << command_name(c);
        EXPECT_LE(st.transition, 0);
      } else {
        ++moves;
      }
    }
  }
  EXPECT_EQ(moves, 15);
  // Illegal ones are flagged, not silently taken.
  EXPECT_EQ(apply(S::switch_on_disabled, C::enable_operation).transition, -1);
  EXPECT_EQ(apply(S::switch_on_disabled, C::switch_on).transition, -1);
  EXPECT_EQ(apply(S::fault, C::enable_operation).transition, -1);
  EXPECT_EQ(apply(S::quick_stop_active, C::enable_operation).transition, -1);
  EXPECT_EQ(apply(S::quick_stop_active, C::shutdown).transition, -1);
  // Transition 16 exists only with a quick stop option code that stays (5..8).
  EXPECT_EQ(apply(S::quick_stop_active, C::enable_operation, true).next, S::operation_enabled);
  EXPECT_EQ(apply(S::quick_stop_active, C::enable_operation, true).transition, 16);
}

TEST(Cia402, MasterPathReachesEveryTargetFromEveryState) {
  const State starts[] = {State::switch_on_disabled, State::ready_to_switch_on, State::switched_on,
                          State::operation_enabled, State::quick_stop_active, State::fault};
  for (State s0 : starts) {
    // enabled, with fault reset allowed
    State s = s0;
    for (int i = 0; i < 6 && s != State::operation_enabled; ++i) s = apply(s, next_command(s, Target::enabled, true)).next;
    EXPECT_EQ(s, State::operation_enabled) << "from " << state_name(s0);
    // disabled
    s = s0;
    for (int i = 0; i < 3; ++i) s = apply(s, next_command(s, Target::disabled, false)).next;
    EXPECT_EQ(s, s0 == State::fault ? State::fault : State::switch_on_disabled) << "from " << state_name(s0);
  }
  // A fault is never left without an explicit reset.
  EXPECT_EQ(next_command(State::fault, Target::enabled, false), Command::disable_voltage);
  EXPECT_EQ(next_command(State::operation_enabled, Target::quick_stop, false), Command::quick_stop);
}

// CiA 402-2, homing mode: the statusword's bits 13 (homing error), 12
// (homing attained) and 10 (target reached), every row of the standard's
// table, with every other bit given both values (the state bits, warning,
// remote, internal limit and the manufacturer's bits mean nothing here).
TEST(Cia402, HomingStatusTableOfBits13_12_10) {
  struct Row {
    int b13, b12, b10;
    HomingStatus h;
  };
  const Row rows[] = {
      {0, 0, 0, HomingStatus::in_progress},  // homing procedure in progress
      {0, 0, 1, HomingStatus::interrupted},  // interrupted or not started
      {0, 1, 0, HomingStatus::attained},     // attained, target not reached
      {0, 1, 1, HomingStatus::completed},    // completed successfully
      {1, 0, 0, HomingStatus::error},        // error, velocity not 0
      {1, 0, 1, HomingStatus::error},        // error, velocity 0
      {1, 1, 0, HomingStatus::error},        // reserved: still bit 13
      {1, 1, 1, HomingStatus::error},
  };
  const std::uint16_t table_bits = (1u << 13) | (1u << 12) | (1u << 10);
  for (const auto& r : rows) {
    const auto bits = static_cast<std::uint16_t>((r.b13 << 13) | (r.b12 << 12) | (r.b10 << 10));
    // Every combination of the other 13 bits.
    for (std::uint32_t other = 0; other < 0x10000; ++other) {
      if (other & table_bits) continue;
      ASSERT_EQ(decode_homing(static_cast<std::uint16_t>(bits | other)), r.h)
          << r.b13 << r.b12 << r.b10 << " with 0x" << std::hex << other;
    }
  }
  // A drive in operation enabled that completed homing (bits 12 and 10).
  EXPECT_EQ(decode_homing(0x1637), HomingStatus::completed);
  // The example of docs/canopen-backend.md: error, at rest.
  EXPECT_EQ(decode_homing(0x2637), HomingStatus::error);
  EXPECT_EQ(kCwHomingStart, 0x10);
  EXPECT_EQ(kSwHomingAttained, 0x1000);
  EXPECT_EQ(kSwHomingError, 0x2000);
}

TEST(Cia402, HomingStatusNamesAreDistinct) {
  std::set<std::string> names;
  for (auto h : {HomingStatus::idle, HomingStatus::in_progress, HomingStatus::interrupted, HomingStatus::attained,
                 HomingStatus::completed, HomingStatus::error}) {
    const std::string n = homing_status_name(h);
    EXPECT_NE(n, "invalid");
    EXPECT_TRUE(names.insert(n).second) << n;
  }
  EXPECT_STREQ(homing_status_name(static_cast<HomingStatus>(99)), "invalid");
}
