// SPDX-License-Identifier: Apache-2.0
// The first steps of a test that drives a running cpmd with `cpm`: wait for
// cpmd's first state, enable the machine, wait until it holds; and the whole
// start of such a test as one object (cpmd on its simulator, one engineer).
#pragma once

#include <gtest/gtest.h>

#include <memory>
#include <optional>
#include <string>

#include "cpm/daemon/client.hpp"
#include "cpm/daemon/config.hpp"
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

// cpmd on its simulator (config/sim.yaml on a port of its own) in a folder of
// its own, with one engineer, "eng", enabled and holding. `holding` is empty
// once the failure has been reported; the test then stops
// (ASSERT_TRUE(h.holding)). The client keeps the engineer's session until
// the test releases it for the `cpm` commands it runs.
struct EngineerOnCpmd {
  explicit EngineerOnCpmd(const std::string& what)
      : dir(what),
        ops(dir / "operators.d"),
        eng(ops.add("eng", daemon::Role::engineer)),
        config(sim_config(dir.path(), "sim.yaml", ops.path())),
        cfg(daemon::load_config(config)),
        cpmd(start_cpmd(config, dir / "cpmd.log")),
        client(cfg.lcm, eng),
        holding(enable_and_hold(client, *cpmd)) {}

  // The flags a `cpm` command needs to reach this cpmd as the engineer.
  [[nodiscard]] std::string as_engineer() const {
    return " --url '" + cfg.lcm.url + "' --key " + ops.key_path("eng") + " --operator eng";
  }

  TempDir dir;
  OperatorsDir ops;
  daemon::Credentials eng;
  std::string config;  // the configuration file cpmd runs
  daemon::DaemonConfig cfg;
  std::unique_ptr<Process> cpmd;
  daemon::Client client;
  std::optional<cpm_msgs::state_t> holding;
};

}  // namespace cpm::test
