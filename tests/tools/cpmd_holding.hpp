// SPDX-License-Identifier: Apache-2.0
// The first steps of a test that drives a running cpmd with `cpm`: wait for
// cpmd's first state, enable the machine, wait until it holds.
#pragma once

#include <gtest/gtest.h>

#include <optional>

#include "cpm/daemon/client.hpp"
#include "support/daemon_process.hpp"

namespace cpm::test {

// The holding state, or nothing once the failure (no state, enable refused,
// never holding) has been reported to the running test.
inline std::optional<cpm_msgs::state_t> enable_and_hold(daemon::Client& c, const Process& cpmd) {
  using cpm_msgs::state_t;
  std::optional<state_t> s;
  for (int i = 0; i < 50 && !s; ++i) s = c.state(0.2);
  if (!s) {
    ADD_FAILURE() << "cpmd published no state:\n" << cpmd.log();
    return std::nullopt;
  }
  const auto enable = c.control(cpm_msgs::control_command_t::CMD_ENABLE);
  if (!enable.accepted) {
    ADD_FAILURE() << "enable refused: " << enable.message;
    return std::nullopt;
  }
  for (int i = 0; i < 100 && (!s || s->mode != state_t::MODE_HOLDING); ++i) s = c.state(0.2);
  if (!s || s->mode != state_t::MODE_HOLDING) {
    ADD_FAILURE() << "cpmd did not reach holding after enable:\n" << cpmd.log();
    return std::nullopt;
  }
  return s;
}

}  // namespace cpm::test
