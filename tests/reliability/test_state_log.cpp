// SPDX-License-Identifier: Apache-2.0
// Nothing lost: the daemon's state stream recorded at the full loop rate,
// every message counted against the loop's own cycle counter (state_t.cycles
// counts the cycles run; state_t.cycle is the schedule's slot index, which
// jumps when a late cycle skips slots — those slots were never run, so they
// are no lost message). 20 s at 1 kHz here; CPM_STATE_LOG_SECONDS=600 gives
// the 10-minute run (docs/fault-matrix.md).
#include <cstdlib>
#include <set>

#include <gtest/gtest.h>

#include "cpm/daemon/client.hpp"
#include "support/daemon_process.hpp"

namespace cpm::daemon::test {
namespace {

using cpm_msgs::control_command_t;
using cpm_msgs::state_t;
using cpm_msgs::trajectory_command_t;

TEST(NothingLost, StateStreamHasNoGapsAtTheLoopRate) {
  const char* env = std::getenv("CPM_STATE_LOG_SECONDS");
  const double seconds = env ? std::atof(env) : 20.0;
  const cpm::test::TempDir dir("statelog");
  cpm::test::OperatorsDir ops(dir / "operators.d");
  const std::string cfg_path = cpm::test::sim_config(dir.path(), "sim.yaml", ops.path());
  const DaemonConfig cfg = load_config(cfg_path);
  ASSERT_EQ(cfg.lcm.state_decimation, 1);
  ASSERT_EQ(cfg.loop.rate_hz, 1000);
  Client c(cfg.lcm, ops.add("bob", Role::operator_));
  const auto d = cpm::test::start_cpmd(cfg_path, dir / "cpmd.log");
  std::optional<state_t> s;
  for (int i = 0; i < 100 && !s; ++i) s = c.state(0.2);
  ASSERT_TRUE(s) << d->log();
  ASSERT_TRUE(c.control(control_command_t::CMD_ENABLE).accepted);

  // Record; keep the machine busy with the paper's circle meanwhile.
  std::vector<std::int64_t> cycles, slots;
  cycles.reserve(static_cast<std::size_t>(seconds * 1100) + 1000);
  slots.reserve(cycles.capacity());
  std::int64_t dropped_first = -1, dropped_last = 0, skipped_first = -1, skipped_last = 0;
  c.on_state([&](const state_t& st) {
    cycles.push_back(st.cycles);
    slots.push_back(st.cycle);
    if (dropped_first < 0) dropped_first = st.dropped_snapshots, skipped_first = st.skipped;
    dropped_last = st.dropped_snapshots;
    skipped_last = st.skipped;
  });
  trajectory_command_t circle{};
  circle.kind = trajectory_command_t::KIND_CIRCLE;
  circle.centre[0] = 0.425;
  circle.centre[1] = 0.425;
  circle.centre[2] = 0.300;
  circle.radius = 0.175;
  circle.angular_speed = M_PI / 2;
  circle.cruise_time = 4.0;
  circle.allow_velocity_step = true;  // Elkady's start at speed, on the simulator
  c.handle(0.2);
  (void)c.send_trajectory(circle);
  const auto end = std::chrono::steady_clock::now() + std::chrono::duration<double>(seconds);
  while (std::chrono::steady_clock::now() < end) c.handle(0.05);
  c.on_state({});
  ASSERT_FALSE(cycles.empty());
  const std::set<std::int64_t> unique(cycles.begin(), cycles.end());
  const std::int64_t expected = cycles.back() - cycles.front() + 1;
  const auto received = static_cast<std::int64_t>(unique.size());
  const std::int64_t slot_span = slots.back() - slots.front() + 1;
  std::printf("state log: %.0f s, %lld messages received of %lld cycles run (%lld slots, %lld skipped by late "
              "cycles), %lld duplicates, %lld dropped in cpmd's ring\n",
              seconds, static_cast<long long>(received), static_cast<long long>(expected),
              static_cast<long long>(slot_span), static_cast<long long>(skipped_last - skipped_first),
              static_cast<long long>(cycles.size() - unique.size()), static_cast<long long>(dropped_last - dropped_first));
  EXPECT_EQ(received, expected) << "messages lost";
  EXPECT_EQ(cycles.size(), unique.size()) << "duplicated messages";
  EXPECT_EQ(dropped_last - dropped_first, 0) << "the loop dropped snapshots";
  EXPECT_GE(expected, static_cast<std::int64_t>(seconds * 1000 * 0.95));
  // Slots skipped by late cycles account for every difference between the two counters.
  EXPECT_EQ(slot_span - expected, skipped_last - skipped_first);
  EXPECT_EQ(d->terminate(), 0) << d->log();
}

}  // namespace
}  // namespace cpm::daemon::test
