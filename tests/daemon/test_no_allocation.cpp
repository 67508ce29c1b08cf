// SPDX-License-Identifier: Apache-2.0
// The control cycle allocates nothing: global operator new is replaced in
// this test binary by one that counts, and the cycles of every mode
// (disabled, enabling, holding, moving through a circle and a move, stopping,
// fault, reset) run with the counter armed.
#include "loop_fixture.hpp"
#include "support/allocation_counter.hpp"

namespace cpm::daemon::test {
namespace {

// Run n cycles with the counter armed; return the allocations they made.
long counted(LoopHarness& h, int n) {
  long total = 0;
  for (int i = 0; i < n; ++i) {
    const cpm::test::CountAllocations count;
    h.loop->cycle(h.k++, 0);
    total += static_cast<long>(count.count());
    h.drain_snapshots();
  }
  return total;
}

TEST(NoAllocation, CountingWorks) {
  // The counter itself must see an allocation, or the test below proves nothing.
  const cpm::test::CountAllocations count;
  auto* p = new std::vector<double>(100);
  delete p;
  EXPECT_GE(count.count(), 1u);
}

TEST(NoAllocation, EveryModeOfTheCycle) {
  LoopHarness h;
  EXPECT_EQ(counted(h, 50), 0) << "disabled";
  ASSERT_TRUE(h.loop->commands().push([] { Command c; c.kind = CommandKind::enable; c.id = 1; return c; }()));
  EXPECT_EQ(counted(h, 3), 0) << "enabling";
  EXPECT_EQ(h.mode(), Mode::enabling);
  EXPECT_EQ(counted(h, 20), 0) << "enabling -> holding";
  ASSERT_EQ(h.mode(), Mode::holding);

  // The paper's circle (planned outside the loop), then a move behind it.
  Command circle;
  circle.kind = CommandKind::segment;
  circle.id = 2;
  circle.segment.traj.emplace<ctl::CircleTrajectory>(ctl::CircleSpec{});
  circle.segment.start = h.queue_end();
  circle.segment.end = std::get<ctl::CircleTrajectory>(circle.segment.traj).sample(4.0).p;
  circle.segment.allow_step = true;  // Elkady's start at speed (the simulator's grant)
  ASSERT_TRUE(h.loop->commands().push(circle));
  Command move = h.move_to(Vec3(0.45, 0.40, 0.35));
  move.segment.start = circle.segment.end;
  move.segment.traj.emplace<ctl::PointToPoint>(move.segment.start, move.segment.end, ctl::MotionLimits{});
  move.id = 3;
  ASSERT_TRUE(h.loop->commands().push(move));
  EXPECT_EQ(counted(h, 4500), 0) << "moving";
  EXPECT_EQ(h.mode(), Mode::moving);
  ASSERT_TRUE(h.loop->commands().push([] { Command c; c.kind = CommandKind::stop; c.id = 4; return c; }()));
  EXPECT_EQ(counted(h, 200), 0) << "stopping";
  EXPECT_EQ(h.mode(), Mode::holding);
  h.sim->set_estop(true);
  EXPECT_EQ(counted(h, 10), 0) << "fault";
  h.sim->set_estop(false);
  ASSERT_TRUE(h.loop->commands().push([] { Command c; c.kind = CommandKind::reset; c.id = 5; return c; }()));
  EXPECT_EQ(counted(h, 10), 0) << "reset";
  EXPECT_EQ(h.mode(), Mode::disabled);
  Ack a;
  int acks = 0;
  while (h.loop->acks().pop(a)) {
    ++acks;
    EXPECT_TRUE(a.accepted) << a.id << ": " << a.message;
  }
  EXPECT_EQ(acks, 5);
}

}  // namespace
}  // namespace cpm::daemon::test

namespace cpm::daemon::test {
namespace {

TEST(NoAllocation, HomingJoggingAndTheActuatorSpace) {
  // The simulator with incremental encoders, home switches and index marks:
  // cycles before homing, every homing phase, the switch to the task space,
  // and jogs in both frames (the actuator frame before and after homing)
  // with their deadman stops.
  const DaemonConfig cfg = [] {
    DaemonConfig c = load_config(std::string(CPM_SOURCE_DIR) + "/config/sim-homing.yaml");
    c.model_file = "builtin:elkady";
    return c;
  }();
  LoopHarness h(cfg, sim_backend_options(cfg.sim));
  auto push = [&](Command c) {
    c.id = h.next_id++;
    ASSERT_TRUE(h.loop->commands().push(c));
  };
  push([] { Command c; c.kind = CommandKind::enable; return c; }());
  EXPECT_EQ(counted(h, 30), 0) << "enabling in the actuator space";
  ASSERT_EQ(h.mode(), Mode::holding);
  push([] {
    Command c;
    c.kind = CommandKind::jog;
    c.jog_frame = 0;
    c.jog_velocity = Vec3(0, 0, 0.01);
    return c;
  }());
  EXPECT_EQ(counted(h, 600), 0) << "an actuator jog before homing, and its deadman stop";
  ASSERT_EQ(h.mode(), Mode::holding);
  push([] { Command c; c.kind = CommandKind::home; return c; }());
  long homing = counted(h, 1);  // the command taken
  ASSERT_EQ(h.mode(), Mode::homing);
  int n = 0;
  while (h.mode() == Mode::homing && n < 120000) {
    homing += counted(h, 1);
    ++n;
  }
  EXPECT_EQ(homing, 0) << "homing";
  ASSERT_EQ(h.mode(), Mode::holding);
  EXPECT_EQ(counted(h, 100), 0) << "into the task space";
  push([] {
    Command c;
    c.kind = CommandKind::jog;
    c.jog_frame = 1;
    c.jog_velocity = Vec3(0.02, 0.01, 0);
    return c;
  }());
  EXPECT_EQ(counted(h, 800), 0) << "a jog in the machine frame and its deadman stop";
  EXPECT_EQ(h.mode(), Mode::holding);
  push([] {
    Command c;
    c.kind = CommandKind::jog;
    c.jog_frame = 0;
    c.jog_velocity = Vec3(-0.01, 0.02, 0.01);
    return c;
  }());
  EXPECT_EQ(counted(h, 800), 0) << "an actuator jog once homed (its box through the kinematics) and its deadman stop";
  EXPECT_EQ(h.mode(), Mode::holding);
  EXPECT_EQ(h.state().faults, 0);
  Ack a;
  while (h.loop->acks().pop(a)) EXPECT_TRUE(a.accepted) << a.id << ": " << a.message;
}

}  // namespace
}  // namespace cpm::daemon::test
