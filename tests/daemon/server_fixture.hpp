// SPDX-License-Identifier: Apache-2.0
// The server on memq:// (in-process LCM) with the loop on the simulator
// backend, cycle by cycle: commands signed by a test operator go in as bytes
// on the bus, acks come back; the session clock is a variable the test moves.
#pragma once

#include <gtest/gtest.h>

#include <lcm/lcm-cpp.hpp>
#include <vector>

#include "cpm/daemon/server.hpp"
#include "loop_fixture.hpp"
#include "support/test_operators.hpp"

namespace cpm::daemon::test {

using cpm_msgs::ack_t;
using cpm_msgs::control_command_t;
using cpm_msgs::state_t;
using cpm_msgs::trajectory_command_t;

struct ServerCell {
  LoopHarness h;
  ModelStore models{std::make_unique<ctl::Machine>(ctl::MachineModel::elkady())};
  std::unique_ptr<Server> server;
  std::vector<ack_t> acks;
  int states = 0;  // state messages heard by a subscriber that never commands
  double now = 100.0;
  std::int64_t next_id = 1;

  static DaemonConfig config() {
    DaemonConfig c = test_config();
    c.lcm.url = "memq://";
    c.lcm.session_timeout = 2.0;
    return c;
  }
  explicit ServerCell(const DaemonConfig& c = config()) : h(c) {
    server = std::make_unique<Server>(h.cfg, *h.loop, models);
    server->set_clock([this] { return now; });
    server->set_wall_clock([] { return kWallClock; });
    server->set_operators(operator_table());
    server->set_boot_id(kTestBoot);
    server->bus().subscribe(h.cfg.lcm.ack_channel, &ServerCell::on_ack, this);
    server->bus().subscribe(h.cfg.lcm.state_channel, &ServerCell::on_state, this);
  }
  void on_ack(const lcm::ReceiveBuffer*, const std::string&, const ack_t* a) { acks.push_back(*a); }
  void on_state(const lcm::ReceiveBuffer*, const std::string&, const state_t*) { ++states; }
  void pump() {
    while (server->bus().handleTimeout(0) > 0) {
    }
  }
  void cycles(int n) {
    for (int i = 0; i < n; ++i) {
      h.loop->cycle(h.k++, 0);
      server->drain();
      pump();
    }
  }
  Credentials who = credentials("alice");
  // Sign as `who`, publish, run the loop until the command's ack is out, return it.
  template <class M>
  ack_t send(const std::string& channel, const M& m) {
    const auto b = encode_signed(m, who);
    server->bus().publish(channel, b.data(), static_cast<unsigned>(b.size()));
    pump();
    for (int i = 0; i < 5; ++i) {
      for (auto it = acks.rbegin(); it != acks.rend(); ++it)
        if (it->id == m.id) return *it;
      cycles(1);
    }
    ADD_FAILURE() << "no ack for id " << m.id;
    return {};
  }
  ack_t control(std::int8_t cmd, std::int64_t session, std::int64_t seq) {
    control_command_t m{};
    m.command = cmd;
    m.id = next_id++;
    m.session = session;
    m.seq = seq;
    return send(h.cfg.lcm.control_channel, m);
  }
  std::int64_t acquire(std::int64_t nonce) {
    const ack_t a = control(control_command_t::CMD_ACQUIRE, nonce, acquire_seq());
    return a.accepted ? a.session : 0;
  }
  trajectory_command_t move_by(const Vec3& d, std::int64_t session, std::int64_t seq) {
    trajectory_command_t m{};
    m.id = next_id++;
    m.session = session;
    m.seq = seq;
    m.kind = trajectory_command_t::KIND_MOVE;
    const Vec3 p = h.position() + d;
    for (int i = 0; i < 3; ++i) m.target[i] = p[i];
    m.max_velocity = 0.05, m.max_acceleration = 1.0, m.max_jerk = 50.0;
    return m;
  }
  int segments_accepted() const {
    int n = 0;
    for (const auto& a : acks) n += a.source == 2 && a.accepted;
    return n;
  }
};

}  // namespace cpm::daemon::test
