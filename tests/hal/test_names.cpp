// SPDX-License-Identifier: Apache-2.0
// The one table of names per enum (hal/src/cia402.cpp, canopen.cpp): every
// value has its row, keys are distinct, a code off the bus that is no value
// gets the unknown row.
#include <gtest/gtest.h>

#include <set>
#include <string>

#include "cpm/hal/canopen.hpp"
#include "cpm/hal/cia402.hpp"

namespace cpm::hal {
namespace {

TEST(Names, EveryCia402StateHasItsOwnRow) {
  std::set<std::string> keys, full;
  for (int v = 0; v <= static_cast<int>(cia402::State::unknown); ++v) {
    const auto s = static_cast<cia402::State>(v);
    const cia402::StateNames& n = cia402::names(s);
    EXPECT_EQ(n.value, s) << v;
    keys.insert(n.key);
    full.insert(n.full);
    EXPECT_STREQ(cia402::state_name(s), n.full);
  }
  EXPECT_EQ(keys.size(), 9u);
  EXPECT_EQ(full.size(), 9u);
  EXPECT_STREQ(cia402::names(cia402::State::switch_on_disabled).full, "switch on disabled");
  EXPECT_EQ(cia402::names(static_cast<cia402::State>(200)).value, cia402::State::unknown);
}

TEST(Names, NmtStatesByTheirHeartbeatCodes) {
  using canopen::NmtState;
  EXPECT_STREQ(canopen::names(static_cast<NmtState>(0x00)).key, "boot_up");
  EXPECT_STREQ(canopen::names(static_cast<NmtState>(0x04)).key, "stopped");
  EXPECT_STREQ(canopen::names(static_cast<NmtState>(0x05)).brief, "op");
  EXPECT_STREQ(canopen::names(static_cast<NmtState>(0x7F)).full, "pre-operational");
  EXPECT_EQ(canopen::names(static_cast<NmtState>(0x42)).value, NmtState::unknown);  // no NMT state
  EXPECT_STREQ(canopen::nmt_state_name(NmtState::unknown), "unknown");
}

TEST(Names, OperationModesOfTheStandard) {
  ASSERT_NE(cia402::operation_mode(cia402::kModeCyclicSyncTorque), nullptr);
  EXPECT_STREQ(cia402::operation_mode(cia402::kModeCyclicSyncTorque)->brief, "CST");
  EXPECT_STREQ(cia402::operation_mode(cia402::kModeHoming)->full, "homing");
  EXPECT_EQ(cia402::operation_mode(0), nullptr);   // no mode yet
  EXPECT_EQ(cia402::operation_mode(5), nullptr);   // reserved
  EXPECT_EQ(cia402::operation_mode(-3), nullptr);  // the manufacturer's
  std::set<std::string> brief;
  for (int m = 1; m <= 10; ++m)
    if (const cia402::OperationMode* o = cia402::operation_mode(static_cast<std::int8_t>(m))) {
      EXPECT_EQ(o->code, m);
      brief.insert(o->brief);
    }
  EXPECT_EQ(brief.size(), 9u);
}

}  // namespace
}  // namespace cpm::hal
