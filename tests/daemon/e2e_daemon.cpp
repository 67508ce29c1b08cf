// SPDX-License-Identifier: Apache-2.0
// End to end: cpmd on its simulator backend in its own process, this test as
// the client over LCM. The client enables, sends the paper's circle and a
// point-to-point move, records the state, and checks that the machine went
// where it was told within the controller's expected error (the in-process
// sim::run_closed_loop figure), that every command was acknowledged, and that
// rejected commands (outside the workspace, NaN, too fast, illegal in the
// mode) were rejected with a reason and changed nothing.
//
// LCM stays on the machine: the test runs in a fresh network namespace when
// it may (support/daemon_process.hpp, the harness every process-level test
// uses); commands are signed with a throw-away operator's key.
#include <gtest/gtest.h>

#include <chrono>
#include <cmath>
#include <thread>
#include <vector>

#include "cpm/daemon/client.hpp"
#include "cpm/sim/closed_loop.hpp"
#include "support/daemon_process.hpp"

namespace cpm::daemon {
namespace {

using cpm_msgs::ack_t;
using cpm_msgs::control_command_t;
using cpm_msgs::state_t;
using cpm_msgs::trajectory_command_t;
using cpm::test::g_netns;

Vec3 v3(const double* v) { return Vec3(v[0], v[1], v[2]); }

trajectory_command_t move_cmd(const Vec3& to, double v) {
  trajectory_command_t m{};
  m.kind = trajectory_command_t::KIND_MOVE;
  for (int i = 0; i < 3; ++i) m.target[i] = to[i];
  m.max_velocity = v;
  m.max_acceleration = 1.0;
  m.max_jerk = 50.0;
  return m;
}

trajectory_command_t paper_circle() {
  trajectory_command_t m{};
  m.kind = trajectory_command_t::KIND_CIRCLE;
  m.centre[0] = 0.425;
  m.centre[1] = 0.425;
  m.centre[2] = 0.300;
  m.radius = 0.175;
  m.angular_speed = M_PI / 2;
  m.cruise_time = 4.0;
  m.allow_velocity_step = true;  // Elkady's start at speed: granted on the simulator
  return m;
}

// A refused trajectory command changes nothing.
void expect_refused(Client& c, const trajectory_command_t& m, std::int16_t reason, const char* what) {
  SCOPED_TRACE(what);
  const auto before = c.state(1.0);
  ASSERT_TRUE(before);
  const ack_t a = c.trajectory(m);
  EXPECT_FALSE(a.accepted);
  EXPECT_EQ(a.reason, reason) << a.message;
  EXPECT_FALSE(a.message.empty());
  std::this_thread::sleep_for(std::chrono::milliseconds(50));
  const auto after = c.state(1.0);
  ASSERT_TRUE(after);
  EXPECT_EQ(after->mode, before->mode);
  EXPECT_EQ(after->queue_depth, 0);
  EXPECT_EQ(after->segment_id, -1);
  EXPECT_LT((v3(after->position_ref) - v3(before->position_ref)).norm(), 1e-9);
  EXPECT_LT((v3(after->position) - v3(before->position)).norm(), 1e-6);
}

TEST(DaemonEndToEnd, CircleMoveAndRejections) {
  const cpm::test::TempDir dir("e2e");
  cpm::test::OperatorsDir ops(dir / "operators.d");
  const Credentials alice = ops.add("alice", Role::engineer);
  // CI machines are noisy: a burst of late cycles must not fault the test.
  const std::string cfg_path = cpm::test::sim_config(dir.path(), "sim.yaml", ops.path());
  const DaemonConfig cfg = load_config(cfg_path);
  std::printf("e2e: %s, LCM %s\n", g_netns ? "private network namespace" : "host loopback, ttl=0", cfg.lcm.url.c_str());
  auto d = cpm::test::start_cpmd(cfg_path, dir / "cpmd.log");
  Client c(cfg.lcm, alice);

  // Up and disabled, at the configured start.
  std::optional<state_t> s;
  for (int i = 0; i < 50 && !s; ++i) s = c.state(0.2);
  ASSERT_TRUE(s) << "cpmd published no state:\n" << d->log();
  EXPECT_EQ(s->mode, state_t::MODE_DISABLED);
  const Vec3 p1(0.600, 0.425, 0.300);
  EXPECT_LT((v3(s->position) - p1).norm(), 1e-9);

  // Illegal in the mode: a trajectory while disabled, reset without a fault.
  expect_refused(c, move_cmd(Vec3(0.45, 0.40, 0.35), 0.1), ack_t::REASON_ILLEGAL_IN_MODE, "move while disabled");
  ack_t a = c.control(control_command_t::CMD_RESET);
  EXPECT_FALSE(a.accepted);
  EXPECT_EQ(a.reason, ack_t::REASON_ILLEGAL_IN_MODE);

  a = c.control(control_command_t::CMD_ENABLE);
  ASSERT_TRUE(a.accepted) << a.message;
  for (int i = 0; i < 100 && s->mode != state_t::MODE_HOLDING; ++i) s = c.state(0.2);
  ASSERT_EQ(s->mode, state_t::MODE_HOLDING);

  // Refused with a reason, changing nothing.
  expect_refused(c, move_cmd(Vec3(NAN, 0.40, 0.35), 0.1), ack_t::REASON_INVALID, "NaN target");
  expect_refused(c, move_cmd(Vec3(0.90, 0.40, 0.35), 0.1), ack_t::REASON_WORKSPACE, "outside the workspace");
  expect_refused(c, move_cmd(Vec3(0.45, 0.40, 0.35), 3.0), ack_t::REASON_LIMIT, "too fast");
  auto fast = paper_circle();
  fast.angular_speed = 10;
  expect_refused(c, fast, ack_t::REASON_LIMIT, "circle too fast");
  a = c.control(control_command_t::CMD_ENABLE);
  EXPECT_FALSE(a.accepted);  // already enabled

  // Record every state from here on.
  std::vector<state_t> rec;
  rec.reserve(20000);
  c.on_state([&](const state_t& st) { rec.push_back(st); });

  // The paper's circle from P1, and a move queued behind it.
  const ack_t ac = c.trajectory(paper_circle());
  ASSERT_TRUE(ac.accepted) << ac.message;
  const Vec3 target(0.45, 0.40, 0.35);
  const ack_t am = c.trajectory(move_cmd(target, 0.1));
  ASSERT_TRUE(am.accepted) << am.message;
  EXPECT_EQ(am.queue_depth, 2);
  const auto t_end = std::chrono::steady_clock::now() + std::chrono::seconds(30);
  while (std::chrono::steady_clock::now() < t_end && (rec.empty() || rec.back().last_segment_id != am.id)) c.handle(0.05);
  ASSERT_FALSE(rec.empty());
  ASSERT_EQ(rec.back().last_segment_id, am.id) << "the move did not finish; mode " << mode_text(rec.back().mode);
  c.handle(0.5);  // settle
  const state_t end = rec.back();
  EXPECT_EQ(end.mode, state_t::MODE_HOLDING);
  EXPECT_EQ(end.faults, 0);
  EXPECT_LT((v3(end.position) - target).norm(), 10e-6) << "not where it was told";

  // Tracking of the circle against the in-process closed loop.
  const ctl::Machine m(ctl::MachineModel::elkady());
  const ctl::Controller ctrl(m, ctl::ControlLaw::computed_torque, ctl::table3_gains(ctl::ControlLaw::computed_torque));
  sim::Plant plant(m, sim::PlantOptions{});
  const ctl::CircleTrajectory circle{ctl::CircleSpec{}};
  sim::LoopOptions lo;
  lo.keep_log = false;
  const auto ref = sim::run_closed_loop(ctrl, plant, circle, lo);
  ASSERT_TRUE(ref.ok());
  double sum = 0, mx = 0;
  long n = 0;
  std::int64_t first = -1, last = -1;
  for (const auto& st : rec)
    if (st.segment_id == ac.id) {
      sum += st.position_error_norm * st.position_error_norm;
      mx = std::max(mx, st.position_error_norm);
      ++n;
      if (first < 0) first = st.cycle;
      last = st.cycle;
    }
  ASSERT_GT(n, 3000) << "too few states recorded during the circle";
  const double rmse = std::sqrt(sum / n);
  const long overruns = static_cast<long>(end.overruns), skipped = static_cast<long>(end.skipped);
  std::printf("e2e: circle RMSE %.2f um (in-process %.2f um), max %.1f um; %ld of %lld states received; "
              "%ld overruns, %ld skipped slots\n",
              rmse * 1e6, ref.metrics.position_rmse * 1e6, mx * 1e6, n, static_cast<long long>(last - first + 1),
              overruns, skipped);
  EXPECT_GE(n, 0.9 * static_cast<double>(last - first + 1)) << "lost more than 10% of the state messages";
  if (skipped == 0)
    EXPECT_NEAR(rmse, ref.metrics.position_rmse, 0.02 * ref.metrics.position_rmse);  // same loop, same numbers
  else
    EXPECT_NEAR(rmse, ref.metrics.position_rmse, 0.25 * ref.metrics.position_rmse);  // late cycles cost a little
  EXPECT_LT(mx, ref.metrics.position_max * 1.25);

  // Disable, then SIGTERM: a clean exit.
  a = c.control(control_command_t::CMD_DISABLE);
  EXPECT_TRUE(a.accepted) << a.message;
  EXPECT_EQ(a.mode, state_t::MODE_DISABLED);
  EXPECT_EQ(d->terminate(), 0) << d->log();
}

}  // namespace
}  // namespace cpm::daemon
