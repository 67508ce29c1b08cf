// SPDX-License-Identifier: Apache-2.0
// Restart safety at the process level: cpmd (simulator backend) is brought
// to each state — disabled, enabling, holding, moving, stopping, fault — and
// killed with SIGKILL (no handler runs). A new cpmd, started as systemd's
// Restart=on-failure would, comes up disabled: every state it publishes is
// disabled, with zero force, no fault, the setpoint on the measured position
// and the platform still; it never enables on its own, and an operator's
// enable then holds where the platform is, without a jump.
// (The canopen half — the drives stop on their own heartbeat consumer when
// the master goes silent — is test_matrix_canopen's MatrixRestart and the
// SIL test sil.reliability.)
#include <gtest/gtest.h>

#include <functional>
#include <regex>

#include "cpm/daemon/client.hpp"
#include "support/daemon_process.hpp"

namespace cpm::daemon::test {
namespace {


Vec3 vec(const double* v) { return Vec3(v[0], v[1], v[2]); }

using cpm_msgs::ack_t;
using cpm_msgs::control_command_t;
using cpm_msgs::state_t;
using cpm_msgs::trajectory_command_t;

trajectory_command_t move_cmd(const Vec3& to, double v) {
  trajectory_command_t m{};
  m.kind = trajectory_command_t::KIND_MOVE;
  for (int i = 0; i < 3; ++i) m.target[i] = to[i];
  m.max_velocity = v;
  m.max_acceleration = 0.5;
  m.max_jerk = 20.0;
  return m;
}

std::optional<state_t> wait_for(Client& c, const std::function<bool(const state_t&)>& pred, double timeout_s) {
  const auto end = std::chrono::steady_clock::now() + std::chrono::duration<double>(timeout_s);
  while (std::chrono::steady_clock::now() < end)
    if (auto s = c.state(0.2); s && pred(*s)) return s;
  return std::nullopt;
}

struct Case {
  const char* name;
  std::int8_t mode;
};

class KilledIn : public ::testing::TestWithParam<Case> {};

TEST_P(KilledIn, RestartsDisabledAndNeverMovesOnItsOwn) {
  const Case cs = GetParam();
  const cpm::test::TempDir dir(std::string("restart-") + cs.name);
  cpm::test::OperatorsDir ops(dir / "operators.d");
  const Credentials bob = ops.add("bob", Role::operator_);
  std::vector<std::pair<std::string, std::string>> edits = {
      {"stop_deceleration: 2.0", "stop_deceleration: 0.05"}};  // a stop of 1 s at 50 mm/s
  if (cs.mode == state_t::MODE_ENABLING)
    edits.push_back({"enable_delay: 0.005", "enable_delay: 3.0"}), edits.push_back({"enable_timeout: 0.5", "enable_timeout: 10"});
  if (cs.mode == state_t::MODE_FAULT) edits.push_back({"following_error: 0.005", "following_error: 1.0e-7"});
  const std::string cfg_path = cpm::test::sim_config(dir.path(), "sim.yaml", ops.path(), edits);
  const DaemonConfig cfg = load_config(cfg_path);
  Client c(cfg.lcm, bob);

  auto a = cpm::test::start_cpmd(cfg_path, dir / "a.log");
  ASSERT_TRUE(wait_for(c, [](const state_t& s) { return s.mode == state_t::MODE_DISABLED; }, 20)) << a->log();
  // Bring the first cpmd to the state.
  if (cs.mode != state_t::MODE_DISABLED) {
    ASSERT_TRUE(c.control(control_command_t::CMD_ENABLE).accepted);
  }
  if (cs.mode == state_t::MODE_HOLDING || cs.mode == state_t::MODE_MOVING || cs.mode == state_t::MODE_STOPPING ||
      cs.mode == state_t::MODE_FAULT) {
    ASSERT_TRUE(wait_for(c, [](const state_t& s) { return s.mode == state_t::MODE_HOLDING; }, 10)) << a->log();
  }
  if (cs.mode == state_t::MODE_MOVING || cs.mode == state_t::MODE_STOPPING || cs.mode == state_t::MODE_FAULT) {
    const ack_t m = c.trajectory(move_cmd(Vec3(0.50, 0.425, 0.300), 0.05));
    ASSERT_TRUE(m.accepted) << m.message;
    if (cs.mode != state_t::MODE_FAULT) {
      ASSERT_TRUE(wait_for(c, [](const state_t& s) { return s.mode == state_t::MODE_MOVING && s.segment_elapsed > 0.3; }, 10));
    }
  }
  if (cs.mode == state_t::MODE_STOPPING) {
    ASSERT_TRUE(c.control(control_command_t::CMD_STOP).accepted);
  }
  const auto at = wait_for(c, [&](const state_t& s) { return s.mode == cs.mode; }, 10);
  ASSERT_TRUE(at) << "cpmd never reached " << cs.name;
  if (cs.mode == state_t::MODE_MOVING || cs.mode == state_t::MODE_STOPPING) {
    EXPECT_GT(vec(at->velocity).norm(), 0.01) << "not in motion when killed";
  }

  a->kill9();
  c.handle(0.3);  // drain what the dead process sent

  // The restart.
  auto b = cpm::test::start_cpmd(cfg_path, dir / "b.log");
  std::vector<state_t> seen;
  c.on_state([&](const state_t& s) { seen.push_back(s); });
  const auto t_end = std::chrono::steady_clock::now() + std::chrono::seconds(20);
  while (seen.size() < 1500 && std::chrono::steady_clock::now() < t_end) c.handle(0.05);
  c.on_state({});
  ASSERT_GE(seen.size(), 1000u) << "the restarted cpmd published too little:\n" << b->log();
  const Vec3 p0 = vec(seen.front().position);
  double moved = 0, max_force = 0, max_ref_off = 0;
  for (const auto& s : seen) {
    ASSERT_EQ(s.mode, state_t::MODE_DISABLED) << "cycle " << s.cycle << " after a kill in " << cs.name;
    EXPECT_EQ(s.faults, 0);
    for (double f : s.force) max_force = std::max(max_force, std::abs(f));
    moved = std::max(moved, (vec(s.position) - p0).norm());
    max_ref_off = std::max(max_ref_off, (vec(s.position_ref) - vec(s.position)).norm());
  }
  std::printf("killed in %s: the new cpmd published %zu states, all disabled; max |F| %.3g N, moved %.3g m\n",
              cs.name, seen.size(), max_force, moved);
  EXPECT_EQ(max_force, 0.0);
  EXPECT_EQ(moved, 0.0);
  EXPECT_EQ(max_ref_off, 0.0);
  EXPECT_LE(seen.front().cycles, 1000) << "not a fresh process";

  // An operator's enable: holding where the platform is, nothing jumps.
  ASSERT_TRUE(c.control(control_command_t::CMD_ENABLE).accepted);
  const auto h = wait_for(c, [](const state_t& s) { return s.mode == state_t::MODE_HOLDING; },
                          cs.mode == state_t::MODE_ENABLING ? 10 : 5);
  ASSERT_TRUE(h);
  EXPECT_LT((vec(h->position_ref) - p0).norm(), 1e-9);
  EXPECT_LT((vec(h->position) - p0).norm(), 5e-6);
  EXPECT_EQ(b->terminate(), 0) << b->log();
}

INSTANTIATE_TEST_SUITE_P(EveryState, KilledIn,
                         ::testing::Values(Case{"disabled", state_t::MODE_DISABLED}, Case{"enabling", state_t::MODE_ENABLING},
                                           Case{"holding", state_t::MODE_HOLDING}, Case{"moving", state_t::MODE_MOVING},
                                           Case{"stopping", state_t::MODE_STOPPING}, Case{"fault", state_t::MODE_FAULT}),
                         [](const auto& p) { return std::string(p.param.name); });

// Row: configuration invalid, at the process level: cpmd exits 1 with the
// place of the error before it opens the backend or publishes anything.
TEST(ProcessFaults, InvalidConfigurationExitsBeforeAnythingRuns) {
  const cpm::test::TempDir dir("badconfig");
  const std::string cfg_path =
      cpm::test::sim_config(dir.path(), "bad.yaml", dir / "operators.d", {{"velocity: 0.5 ", "velocity: fast "}});
  const auto p = cpm::test::start_cpmd(cfg_path, dir / "cpmd.log");
  EXPECT_EQ(p->wait_exit(), 1);
  const std::string log = p->log();
  EXPECT_TRUE(std::regex_search(log, std::regex("bad\\.yaml:\\d+:\\d+: limits\\.velocity"))) << log;
}

}  // namespace
}  // namespace cpm::daemon::test
