// SPDX-License-Identifier: Apache-2.0
// The paper's circle through the loop, cycle by cycle (no threads, no LCM):
// the tracking error the loop reports is the in-process closed loop's, and
// the exact figure is printed so that a change to the cycle that should not
// change its behaviour can be checked to the last digit (issue 17, part 6).
#include <cmath>
#include <cstdio>

#include "cpm/sim/closed_loop.hpp"
#include "loop_fixture.hpp"

namespace cpm::daemon::test {
namespace {

TEST(PaperCircle, LoopTracksLikeTheInProcessClosedLoop) {
  LoopHarness h;
  h.to_holding();
  Command c;
  c.kind = CommandKind::segment;
  c.source = 2;
  const ctl::CircleTrajectory circle{ctl::CircleSpec{}};
  c.segment.start = h.queue_end();
  c.segment.end = circle.sample(circle.duration()).p;
  ASSERT_LT((c.segment.start - circle.sample(0).p).norm(), 1e-6) << "the harness does not start at P1";
  c.segment.traj = circle;
  c.segment.allow_step = true;  // Elkady's test starts at full speed: granted on the simulator
  const Ack a = h.command(c);
  ASSERT_TRUE(a.accepted) << a.message;
  for (int i = 0; i < 20000 && h.state().last_segment_id != a.id; ++i) h.run(1);
  ASSERT_EQ(h.state().last_segment_id, a.id) << "the circle did not finish";
  EXPECT_EQ(h.state().faults, 0);

  sim::Plant plant(h.machine, sim::PlantOptions{});
  const ctl::Controller ctrl(h.machine, h.cfg.controller.law, h.cfg.controller.gains);
  sim::LoopOptions lo;
  lo.keep_log = false;
  const auto ref = sim::run_closed_loop(ctrl, plant, circle, lo);
  ASSERT_TRUE(ref.ok());
  std::printf("paper circle through the loop: RMSE %.17g m, max %.17g m over %d cycles (in-process RMSE %.17g m)\n",
              h.state().last_segment_rmse, h.state().last_segment_max, h.state().last_segment_cycles,
              ref.metrics.position_rmse);
  EXPECT_NEAR(h.state().last_segment_rmse, ref.metrics.position_rmse, 0.02 * ref.metrics.position_rmse);
}

}  // namespace
}  // namespace cpm::daemon::test
