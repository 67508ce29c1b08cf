// SPDX-License-Identifier: Apache-2.0
// One control cycle of cpmd (read sim backend, estimate, trajectory, IK,
// computed torque, safety, write, publish) while playing Elkady's circle.
// The wall-clock figures of a 60 s run at 1 kHz come from daemon/latency-run.sh.
#include <benchmark/benchmark.h>

#include "cpm/daemon/loop.hpp"
#include "cpm/daemon/sim_backend.hpp"

namespace {

using namespace cpm;
using namespace cpm::daemon;

void BM_DaemonCycleMoving(benchmark::State& st) {
  DaemonConfig cfg;
  const ctl::Machine machine(ctl::MachineModel::elkady());
  SimBackend sim(std::make_unique<ctl::Machine>(ctl::MachineModel::elkady()), SimBackendOptions{});
  sim.start(1e-3);
  ControlLoop loop(cfg, sim, machine, ctl::Controller(machine, cfg.controller.law, cfg.controller.gains));
  std::int64_t k = 0;
  auto drain = [&] {
    while (loop.snapshots().front()) loop.snapshots().release();
    Ack a;
    while (loop.acks().pop(a)) {
    }
    cpm_msgs::loop_stats_t s;
    while (loop.stats().pop(s)) {
    }
  };
  auto circle = [&] {
    Command c;
    c.kind = CommandKind::segment;
    c.id = k;
    c.segment.traj.emplace<ctl::CircleTrajectory>(ctl::CircleSpec{});
    c.segment.allow_step = true;  // Elkady's start at speed
    c.segment.start = Vec3(0.600, 0.425, 0.300);
    c.segment.end = c.segment.start;
    return c;
  };
  loop.commands().push([] {
    Command c;
    c.kind = CommandKind::enable;
    return c;
  }());
  for (int i = 0; i < 20; ++i) loop.cycle(k++, 0), drain();
  for (auto _ : st) {
    if (loop.mode() == Mode::holding) loop.commands().push(circle());
    loop.cycle(k++, 0);
    drain();
  }
  st.counters["cycles"] = static_cast<double>(k);
}
BENCHMARK(BM_DaemonCycleMoving);

}  // namespace
