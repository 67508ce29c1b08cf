// SPDX-License-Identifier: Apache-2.0
// The paper's circle (or any circle) through cpmd's loop: on the simulator
// backend, and through the canopen backend and the virtual drives (Rig), with
// the daemon's own tracking figures.
#pragma once

#include <cmath>
#include <limits>

#include "canopen/rig.hpp"
#include "cpm/daemon/sim_backend.hpp"

namespace cpm::daemon::test {

struct CircleFigures {
  double rmse = std::numeric_limits<double>::infinity();     // m, the segment's (state_t.last_segment_rmse)
  double settled = std::numeric_limits<double>::infinity();  // m, over the cycles at segment_elapsed >= 0.5 s
  bool ok = false;                                           // finished, holding, no fault
};

// Accumulates the daemon's |p_ref - p| of the playing segment once the
// start's transient has died out.
struct SettledError {
  double sum = 0.0;
  long n = 0;
  void add(const cpm_msgs::state_t& s) {
    if (s.segment_id < 0 || s.segment_elapsed < 0.5) return;
    sum += s.position_error_norm * s.position_error_norm;
    ++n;
  }
  [[nodiscard]] double rms() const { return n > 0 ? std::sqrt(sum / static_cast<double>(n)) : 0.0; }
};

inline Command circle_command(const Vec3& start, const ctl::CircleTrajectory& circle) {
  Command c;
  c.kind = CommandKind::segment;
  c.segment.start = start;
  c.segment.end = circle.sample(circle.duration()).p;
  c.segment.traj = circle;
  c.segment.allow_step = true;  // Elkady's start at speed: a bench with simulated drives
  return c;
}

// The same loop on the simulator backend (the plant stepped in-process, the
// command acting at once): the figure the bus is compared with.
inline CircleFigures circle_on_sim_backend(const DaemonConfig& cfg, const ctl::CircleTrajectory& circle) {
  SimBackendOptions so;
  so.enable_delay = 0;
  SimBackend sim(std::make_unique<ctl::Machine>(ctl::MachineModel::elkady()), so);
  sim.start(1.0 / cfg.loop.rate_hz);
  const ctl::Machine model(ctl::MachineModel::elkady());
  ControlLoop loop(cfg, sim, model, ctl::Controller(model, cfg.controller.law, cfg.controller.gains));
  std::int64_t k = 0;
  SettledError settled;
  auto run = [&](int n) {
    for (int i = 0; i < n; ++i) {
      loop.cycle(k++, 0);
      settled.add(loop.last_state());
      while (loop.snapshots().front()) loop.snapshots().release();
    }
  };
  auto push = [&](Command c) {
    c.id = k + 1;
    EXPECT_TRUE(loop.commands().push(c));
    run(1);
    Ack a;
    while (loop.acks().pop(a)) EXPECT_TRUE(a.accepted) << a.message;
  };
  run(2);
  Command e;
  e.kind = CommandKind::enable;
  push(e);
  run(10);
  EXPECT_EQ(loop.mode(), Mode::holding);
  const auto& st = loop.last_state();
  push(circle_command(Vec3(st.queue_end[0], st.queue_end[1], st.queue_end[2]), circle));
  run(static_cast<int>(circle.duration() * cfg.loop.rate_hz) + 10);
  CircleFigures f;
  f.ok = loop.mode() == Mode::holding && loop.last_state().faults == 0;
  f.rmse = loop.last_state().last_segment_rmse;
  f.settled = settled.rms();
  return f;
}

// The circle through the rig: enable, the segment, until holding again.
inline CircleFigures circle_through_bus(Rig& r, const ctl::CircleTrajectory& circle) {
  CircleFigures f;
  r.to_holding();
  if (r.mode() != Mode::holding) return f;
  if (!r.command(circle_command(r.queue_end(), circle)).accepted) return f;
  SettledError settled;
  const int limit = static_cast<int>(circle.duration() * r.cfg.loop.rate_hz) + 50;
  for (int n = 0; n < limit && r.mode() != Mode::holding && r.mode() != Mode::fault; ++n) {
    r.step();
    settled.add(r.state());
  }
  f.ok = r.mode() == Mode::holding && r.state().faults == 0;
  f.rmse = r.state().last_segment_rmse;
  f.settled = settled.rms();
  return f;
}

}  // namespace cpm::daemon::test
