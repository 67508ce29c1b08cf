// SPDX-License-Identifier: Apache-2.0
// A control loop on the simulator backend, driven cycle by cycle without
// threads: deterministic, for the state-machine and allocation tests.
#pragma once

#include <gtest/gtest.h>

#include <memory>

#include "cpm/daemon/loop.hpp"
#include "cpm/daemon/sim_backend.hpp"

namespace cpm::daemon::test {

inline DaemonConfig test_config() {
  DaemonConfig c;
  c.model_file = "builtin:elkady";
  c.loop.rate_hz = 1000;
  c.loop.max_consecutive_overruns = 3;
  c.lcm.state_decimation = 1;
  return c;
}

struct LoopHarness {
  DaemonConfig cfg = test_config();
  ctl::Machine machine{ctl::MachineModel::elkady()};
  SimBackend* sim = nullptr;
  std::unique_ptr<Backend> backend;
  std::unique_ptr<ControlLoop> loop;
  std::int64_t k = 0;
  std::int64_t next_id = 1;

  // `truth`: the simulator's machine; `believed`: the loop's model.
  explicit LoopHarness(const DaemonConfig& c = test_config(), double enable_delay = 0.005,
                       const ctl::MachineModel& truth = ctl::MachineModel::elkady(),
                       const ctl::MachineModel& believed = ctl::MachineModel::elkady())
      : LoopHarness(c, [&] {
          SimBackendOptions so;
          so.enable_delay = enable_delay;
          return so;
        }(), truth, believed) {}
  // The simulator as `so` says (incremental encoders, home switches, ...).
  LoopHarness(const DaemonConfig& c, const SimBackendOptions& so,
              const ctl::MachineModel& truth = ctl::MachineModel::elkady(),
              const ctl::MachineModel& believed = ctl::MachineModel::elkady())
      : cfg(c), machine(believed) {
    auto b = std::make_unique<SimBackend>(std::make_unique<ctl::Machine>(truth), so);
    sim = b.get();
    backend = std::move(b);
    backend->start(1.0 / cfg.loop.rate_hz);
    loop = std::make_unique<ControlLoop>(cfg, *backend, machine,
                                         ctl::Controller(machine, cfg.controller.law, cfg.controller.gains));
    run(2);
  }
  void run(int n) {
    for (int i = 0; i < n; ++i) {
      loop->cycle(k++, 0);
      drain_snapshots();
    }
  }
  void drain_snapshots() {
    while (loop->snapshots().front()) loop->snapshots().release();
  }
  Mode mode() const { return loop->mode(); }
  const cpm_msgs::state_t& state() const { return loop->last_state(); }
  Vec3 position() const {
    const auto& s = state();
    return Vec3(s.position[0], s.position[1], s.position[2]);
  }
  Vec3 queue_end() const {
    const auto& s = state();
    return Vec3(s.queue_end[0], s.queue_end[1], s.queue_end[2]);
  }
  // Send a command, run one cycle, return the ack.
  Ack command(Command c) {
    c.id = next_id++;
    EXPECT_TRUE(loop->commands().push(c));
    run(1);
    Ack a;
    EXPECT_TRUE(loop->acks().pop(a)) << "no ack";
    EXPECT_EQ(a.id, c.id);
    while (loop->acks().pop(a)) {
    }
    return a;
  }
  Ack simple(CommandKind k_) {
    Command c;
    c.kind = k_;
    return command(c);
  }
  Command move_to(const Vec3& to, double v = 0.1) {
    Command c;
    c.kind = CommandKind::segment;
    c.source = 2;
    c.segment.start = queue_end();
    c.segment.end = to;
    ctl::MotionLimits lim;
    lim.velocity = v;
    c.segment.traj.emplace<ctl::PointToPoint>(c.segment.start, to, lim);
    return c;
  }
  void to_holding() {
    ASSERT_TRUE(simple(CommandKind::enable).accepted);
    run(20);
    ASSERT_EQ(mode(), Mode::holding);
  }
  void to_moving() {
    to_holding();
    ASSERT_TRUE(command(move_to(queue_end() + Vec3(-0.05, 0, 0))).accepted);
    run(50);
    ASSERT_EQ(mode(), Mode::moving);
  }
  void to_stopping() {
    to_moving();
    run(200);  // at speed
    ASSERT_TRUE(simple(CommandKind::stop).accepted);
    ASSERT_EQ(mode(), Mode::stopping);
  }
  void to_fault() {
    sim->set_estop(true);
    run(1);
    sim->set_estop(false);
    ASSERT_EQ(mode(), Mode::fault);
  }
};

}  // namespace cpm::daemon::test
