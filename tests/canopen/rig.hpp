// SPDX-License-Identifier: Apache-2.0
// cpmd's control loop on the canopen backend, against the virtual machine
// (three virtual CiA 402 drives coupled by the true plant) on the fake bus
// with a fake clock and fake GPIO: the daemon's whole hardware path in one
// thread, deterministic, cycle by cycle.
#pragma once

#include <gtest/gtest.h>

#include <fstream>
#include <functional>
#include <memory>
#include <regex>
#include <sstream>
#include <string>

#include "cpm/daemon/canopen_backend.hpp"
#include "cpm/daemon/loop.hpp"
#include "cpm/hal/fake_can.hpp"
#include "cpm/sim/virtual_machine.hpp"

namespace cpm::daemon::test {

inline std::string read_text(const std::string& path) {
  std::ifstream f(path);
  std::stringstream ss;
  ss << f.rdbuf();
  return ss.str();
}

// The shipped config/canopen.yaml, with `edits` (regex -> replacement) applied.
inline DaemonConfig canopen_config(const std::vector<std::pair<std::string, std::string>>& edits = {}) {
  std::string text = read_text(std::string(CPM_SOURCE_DIR) + "/config/canopen.yaml");
  for (const auto& [from, to] : edits) text = std::regex_replace(text, std::regex(from), to);
  return parse_config(text, "canopen.yaml", std::string(CPM_SOURCE_DIR) + "/config");
}

// 500 Hz with the drives' velocity TPDO: the encoder velocities reach the
// controller as in sim::run_closed_loop.
inline DaemonConfig config_500hz_with_velocity() {
  return canopen_config({{"rate_hz: 1000", "rate_hz: 500"}, {"velocity_from_drive: false", "velocity_from_drive: true"}});
}

struct Rig {
  DaemonConfig cfg;
  hal::FakeClock clock{0, 100'000};
  hal::FakeCanNetwork net{clock};
  hal::FakeCanPort& master_port = net.add_port("cpmd");
  hal::FakeCanPort& drives_port = net.add_port("virtual-drives");
  hal::FakeDigitalIo io;
  ctl::Machine truth{ctl::MachineModel::elkady()};
  ctl::Machine model{ctl::MachineModel::elkady()};
  std::unique_ptr<sim::VirtualMachine> vm;
  std::unique_ptr<CanopenBackend> backend;
  std::unique_ptr<ControlLoop> loop;
  std::int64_t k = 0;
  std::int64_t next_id = 1;
  bool pump = true;   // false: the virtual drives are frozen (their process hangs)
  std::function<void(const cpm_msgs::state_t&)> on_state;  // every cycle's published state, when set

  // `timing`: when the drives apply a torque (synchronous: from the SYNC
  // after the one whose positions it was computed from, as real CiA 402
  // drives; lockstep: at once, as the in-process loop). `believed`: the
  // model cpmd controls with.
  // `machine`: changes to the virtual machine's configuration (homing sensors, incremental encoders).
  // `true_machine`: the plant the virtual drives move (default the nominal machine).
  explicit Rig(const DaemonConfig& c = canopen_config(), bool start = true,
               sim::DriveTiming timing = sim::DriveTiming::synchronous,
               const ctl::MachineModel& believed = ctl::MachineModel::elkady(),
               const sim::EncoderModel& encoder = {},
               const std::function<void(sim::VirtualMachineConfig&)>& machine = {},
               const ctl::MachineModel& true_machine = ctl::MachineModel::elkady())
      : cfg(c), truth(true_machine), model(believed) {
    sim::VirtualMachineConfig vc = sim::VirtualMachineConfig::defaults();
    vc.timing = timing;
    vc.plant.encoder = encoder;
    if (machine) machine(vc);
    for (std::size_t i = 0; i < 3; ++i) {
      const auto& d = cfg.canopen.master.drives[i];
      vc.axes[i].node_id = d.node_id;
      vc.axes[i].scaling = {d.counts_per_m, d.velocity_units_per_mps, d.rated_force_n, d.max_torque_permille,
                            d.direction, d.position_offset_m};
    }
    vc.period = 1.0 / cfg.loop.rate_hz;
    vm = std::make_unique<sim::VirtualMachine>(drives_port, truth, vc);
    clock.set_hook([this](std::int64_t now) {
      if (pump) vm->pump(now);
    });
    vm->power_on(clock.now_ns());
    backend = std::make_unique<CanopenBackend>(cfg.canopen, master_port, clock, io);
    if (start) start_all();
  }
  void start_all() {
    backend->start(1.0 / cfg.loop.rate_hz);
    loop = std::make_unique<ControlLoop>(cfg, *backend, model,
                                         ctl::Controller(model, cfg.controller.law, cfg.controller.gains));
    run(2);
  }
  std::int64_t period_ns() const { return static_cast<std::int64_t>(std::llround(1e9 / cfg.loop.rate_hz)); }
  // One control cycle, then a period passes (the drives answer the SYNC).
  void step() {
    loop->cycle(k++, 0);
    if (on_state) on_state(loop->last_state());
    while (loop->snapshots().front()) loop->snapshots().release();
    clock.wait(period_ns());
  }
  void run(int n) {
    for (int i = 0; i < n; ++i) step();
  }
  // Run until `pred` or `limit` cycles; returns the cycles run, -1 if never.
  template <class P>
  int run_until(P pred, int limit) {
    for (int n = 0; n < limit; ++n) {
      if (pred()) return n;
      step();
    }
    return pred() ? limit : -1;
  }
  Mode mode() const { return loop->mode(); }
  const cpm_msgs::state_t& state() const { return loop->last_state(); }
  std::string fault_text() const {
    const auto& t = state().fault_text;
    return std::string(reinterpret_cast<const char*>(t), strnlen(reinterpret_cast<const char*>(t), sizeof t));
  }
  Vec3 position() const { return Vec3(state().position[0], state().position[1], state().position[2]); }
  Vec3 queue_end() const { return Vec3(state().queue_end[0], state().queue_end[1], state().queue_end[2]); }
  Ack command(Command c) {
    c.id = next_id++;
    EXPECT_TRUE(loop->commands().push(c));
    step();
    Ack a;
    EXPECT_TRUE(loop->acks().pop(a)) << "no ack";
    while (loop->acks().pop(a)) {
    }
    return a;
  }
  Ack simple(CommandKind kind) {
    Command c;
    c.kind = kind;
    return command(c);
  }
  Command move_to(const Vec3& to, double v = 0.1) {
    Command c;
    c.kind = CommandKind::segment;
    c.segment.start = queue_end();
    c.segment.end = to;
    ctl::MotionLimits lim;
    lim.velocity = v;
    c.segment.traj.emplace<ctl::PointToPoint>(c.segment.start, to, lim);
    return c;
  }
  void to_holding() {
    ASSERT_TRUE(simple(CommandKind::enable).accepted);
    ASSERT_GE(run_until([&] { return mode() == Mode::holding; }, 50), 0) << "not holding; " << fault_text();
  }
  // All drives really off and the z brake holding: the documented safe state.
  void expect_safe_outputs() const {
    EXPECT_FALSE(io.outputs.drive_enable);
    EXPECT_FALSE(io.outputs.brake_release_z);
    for (std::size_t i = 0; i < 3; ++i) {
      EXPECT_EQ(backend->commands().drive[i].target, hal::cia402::Target::disabled) << "drive " << i + 1;
      EXPECT_EQ(backend->commands().drive[i].force_n, 0.0) << "drive " << i + 1;
    }
  }
};

}  // namespace cpm::daemon::test
