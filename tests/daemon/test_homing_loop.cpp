// SPDX-License-Identifier: Apache-2.0
// Homing through the loop, cycle by cycle, on the simulator with
// incremental encoders and home switches (config/sim-homing.yaml): from a
// cold start whose actuator zeros are unknown, motion is refused, homing
// finds the zeros (checked against the simulator's true platform), and then
// the paper's circle runs with the in-process closed loop's tracking error.
// A switch that is not there ends in a readable homing fault.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>

#include <cpm_msgs/ack_t.hpp>

#include "cpm/daemon/fault_report.hpp"
#include "cpm/sim/closed_loop.hpp"
#include "loop_fixture.hpp"

namespace cpm::daemon {
namespace {

using cpm_msgs::ack_t;
using cpm_msgs::state_t;
using test::LoopHarness;

DaemonConfig homing_config() {
  DaemonConfig c = load_config(std::string(CPM_SOURCE_DIR) + "/config/sim-homing.yaml");
  c.model_file = "builtin:elkady";
  return c;
}

Command home_all() {
  Command c;
  c.kind = CommandKind::home;
  c.home_axes = 0;
  return c;
}

// Run until the mode leaves `m` (or `limit` cycles).
int run_while(LoopHarness& h, Mode m, int limit) {
  int n = 0;
  while (h.mode() == m && n < limit) {
    h.run(1);
    ++n;
  }
  return n;
}

TEST(HomingLoop, ColdStartRefusesMotionHomesThenRunsThePapersCircleAsInProcess) {
  const DaemonConfig cfg = homing_config();
  LoopHarness h(cfg, sim_backend_options(cfg.sim));
  // Cold: the encoders read d - encoder_zero, the loop does not know where it is.
  for (int i = 0; i < 3; ++i) EXPECT_FALSE(h.state().homed[i]);
  EXPECT_EQ(h.state().control_space, state_t::SPACE_ACTUATOR);
  h.to_holding();
  const Ack refused = h.command(h.move_to(Vec3(0.45, 0.40, 0.35)));
  EXPECT_FALSE(refused.accepted);
  EXPECT_EQ(refused.refusal, Refusal::not_homed);
  std::printf("before homing, a move: %s\n", refused.message);

  ASSERT_TRUE(h.command(home_all()).accepted);
  int order[3] = {-1, -1, -1}, seen = 0;
  int cycles = 0;
  while (h.mode() == Mode::homing && cycles < 120000) {
    const int a = h.state().homing_axis;
    if (a >= 0 && (seen == 0 || order[seen - 1] != a)) order[seen++] = a;
    h.run(1);
    ++cycles;
  }
  ASSERT_EQ(h.mode(), Mode::holding) << fault_report(h.state());
  EXPECT_EQ(seen, 3);
  EXPECT_EQ(order[0], 2);  // the configured order: z, x, y
  EXPECT_EQ(order[1], 0);
  EXPECT_EQ(order[2], 1);
  h.run(500);
  EXPECT_EQ(h.state().control_space, state_t::SPACE_TASK);
  // The zeros found: what the loop believes against where the simulator's
  // platform really is (the switch's edge seen at the latch speed, 4 mm/s:
  // a few um; z on the index mark: its half width).
  const Vec3 believed = h.position();
  const Vec3 truth = h.sim->plant().position();
  std::printf("homed in %.2f s; platform believed at (%.4f, %.4f, %.4f) mm, truly at (%.4f, %.4f, %.4f) mm\n",
              cycles * 1e-3, believed.x() * 1e3, believed.y() * 1e3, believed.z() * 1e3, truth.x() * 1e3,
              truth.y() * 1e3, truth.z() * 1e3);
  EXPECT_LT((believed - truth).cwiseAbs().maxCoeff(), 10e-6);
  // At the final positions, at rest.
  EXPECT_NEAR(h.state().d[0], cfg.homing.axes[0].final_position, 2e-5);
  EXPECT_NEAR(h.state().d[2], cfg.homing.axes[2].final_position, 2e-5);
  EXPECT_EQ(h.state().faults, 0);

  // To P1 and the paper's circle (its start at speed granted: the simulator).
  const ctl::CircleTrajectory circle{ctl::CircleSpec{}};
  const Vec3 p1 = circle.sample(0.0).p;
  ASSERT_TRUE(h.command(h.move_to(p1, 0.1)).accepted);
  run_while(h, Mode::moving, 20000);
  ASSERT_EQ(h.mode(), Mode::holding);
  h.run(1000);
  Command c;
  c.kind = CommandKind::segment;
  c.source = 2;
  c.segment.start = h.queue_end();
  c.segment.end = circle.sample(circle.duration()).p;
  c.segment.traj = circle;
  c.segment.allow_step = true;
  const Ack a = h.command(c);
  ASSERT_TRUE(a.accepted) << a.message;
  run_while(h, Mode::moving, 20000);
  ASSERT_EQ(h.state().last_segment_id, a.id);
  EXPECT_EQ(h.state().faults, 0);
  // The in-process reference: the same circle from rest at P1.
  sim::Plant plant(h.machine, sim::PlantOptions{});
  const ctl::Controller ctrl(h.machine, cfg.controller.law, cfg.controller.gains);
  sim::LoopOptions lo;
  lo.keep_log = false;
  const sim::RunResult ref = sim::run_closed_loop(ctrl, plant, circle, lo);
  ASSERT_TRUE(ref.ok());
  std::printf("paper circle after homing: RMS %.2f um (in-process %.2f um), max %.1f um\n",
              h.state().last_segment_rmse * 1e6, ref.metrics.position_rmse * 1e6, h.state().last_segment_max * 1e6);
  EXPECT_NEAR(h.state().last_segment_rmse, ref.metrics.position_rmse, 0.01 * ref.metrics.position_rmse);
}

TEST(HomingLoop, ASwitchThatIsNotThereEndsInAHomingFaultAnOperatorCanRead) {
  DaemonConfig cfg = homing_config();
  cfg.homing.axes[0].max_travel = 0.30;  // from d = 375 mm: gives up at 75 mm, inside the stroke
  SimBackendOptions so = sim_backend_options(cfg.sim);
  so.home_switch[0] = std::nan("");  // x's switch is dead
  LoopHarness h(cfg, so);
  h.to_holding();
  Command c = home_all();
  c.home_axes = 1;  // x only
  ASSERT_TRUE(h.command(c).accepted);
  run_while(h, Mode::homing, 120000);
  ASSERT_EQ(h.mode(), Mode::fault);
  EXPECT_EQ(h.state().first_fault, state_t::FAULT_HOMING);
  EXPECT_EQ(h.state().fault_axis, 0);
  const std::string r = fault_report(h.state());
  std::printf("%s\n", r.c_str());
  EXPECT_NE(r.find("homing on axis 1 (x)"), std::string::npos) << r;
  EXPECT_NE(r.find("the home switch was not found after 300.0"), std::string::npos) << r;
  EXPECT_NE(r.find("against a limit of 300.000 mm"), std::string::npos) << r;
  EXPECT_FALSE(h.state().homed[0]);
  // It gave up where it said: the true actuator went down by no more than the limit.
  EXPECT_GT(h.sim->plant().position().x() - 0.2250, 0.375 - 0.300 - 0.002);
}

}  // namespace
}  // namespace cpm::daemon
