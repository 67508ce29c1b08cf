// SPDX-License-Identifier: Apache-2.0
// A daemon's command side in-process for the red team: the server on memq://
// (bytes published on its LCM handle reach the same subscriptions as on the
// network) and the loop on the simulator backend, cycle by cycle. The
// attacker publishes bytes; the honest operators of test_operators.hpp
// (alice engineer, bob operator, olga observer) sign theirs.
#pragma once

#include <gtest/gtest.h>
#include <unistd.h>

#include <filesystem>
#include <lcm/lcm-cpp.hpp>
#include <vector>

#include "cpm/daemon/server.hpp"
#include "daemon/loop_fixture.hpp"
#include "redteam/redteam.hpp"
#include "support/test_operators.hpp"

namespace cpm::redteam {

inline const Vec3 kP1(0.600, 0.425, 0.300);

struct Cell {
  daemon::test::LoopHarness h;
  daemon::ModelStore models{std::make_unique<ctl::Machine>(ctl::MachineModel::elkady())};
  std::unique_ptr<daemon::Server> server;
  std::vector<ack_t> acks;
  double now = 100.0;  // the session clock (s)
  std::int64_t next_id = 1000;
  std::string model_dir;
  const Credentials alice = daemon::test::credentials("alice"), bob = daemon::test::credentials("bob"),
                    olga = daemon::test::credentials("olga");

  static daemon::DaemonConfig config(const std::string& model_dir, const std::string& signing_key) {
    daemon::DaemonConfig c = daemon::test::test_config();
    c.lcm.url = "memq://";
    c.security.model_dir = model_dir;
    c.security.signing_key = signing_key;
    return c;
  }
  // `signing_key`: cpmd's key file (security.signing_key); empty: unsigned.
  explicit Cell(const std::string& signing_key = {})
      : h(config(testing::TempDir() + "cpm-redteam-models-" + std::to_string(::getpid()), signing_key)),
        model_dir(h.cfg.security.model_dir) {
    std::filesystem::remove_all(model_dir);
    std::filesystem::create_directories(model_dir);
    server = std::make_unique<daemon::Server>(h.cfg, *h.loop, models);
    server->set_clock([this] { return now; });
    server->set_boot_id(daemon::test::kTestBoot);
    server->set_wall_clock([] { return daemon::test::kWallClock; });
    server->set_operators(daemon::test::operator_table());
    server->bus().subscribe(h.cfg.lcm.ack_channel, &Cell::on_ack, this);
  }
  ~Cell() {
    std::error_code ec;
    std::filesystem::remove_all(model_dir, ec);
  }
  void on_ack(const lcm::ReceiveBuffer*, const std::string&, const ack_t* a) { acks.push_back(*a); }
  void pump() {
    while (server->bus().handleTimeout(0) > 0) {
    }
  }
  void publish(const std::string& channel, const Bytes& b) {
    server->bus().publish(channel, b.data(), static_cast<unsigned>(b.size()));
    pump();
  }
  void cycles(int n) {
    for (int i = 0; i < n; ++i) {
      h.loop->cycle(h.k++, 0);
      server->drain();
      pump();
    }
  }
  const ack_t* ack_of(std::int64_t id) const {
    for (auto it = acks.rbegin(); it != acks.rend(); ++it)
      if (it->id == id) return &*it;
    return nullptr;
  }
  // Publish bytes carrying `id`; run the loop until its ack is out (or give up).
  const ack_t* send_bytes(const std::string& channel, const Bytes& b, std::int64_t id) {
    publish(channel, b);
    for (int i = 0; i < 5 && !ack_of(id); ++i) cycles(1);
    // A model load is read and parsed on its own thread: wait for it (5 s at most).
    for (int i = 0; i < 5000 && !ack_of(id) && server->loading_model(); ++i) {
      ::usleep(1000);
      cycles(1);
    }
    for (int i = 0; i < 5 && !ack_of(id); ++i) cycles(1);
    return ack_of(id);
  }
  // A command signed as `who` (nullptr: no name, no MAC).
  template <class M>
  Bytes sign(M m, const Credentials* who) {
    if (who) return daemon::test::encode_signed(m, *who);
    return encode(m);
  }
  ack_t control(const Credentials* who, std::int8_t cmd, std::int64_t session, std::int64_t seq,
                const std::function<void(C&)>& edit = {}) {
    C m{};
    m.command = cmd;
    m.id = next_id++;
    m.session = session;
    m.seq = seq;
    if (edit) edit(m);
    const ack_t* a = send_bytes(h.cfg.lcm.control_channel, sign(m, who), m.id);
    EXPECT_NE(a, nullptr) << "no answer to command " << int(cmd);
    return a ? *a : ack_t{};
  }
  ack_t trajectory(const Credentials* who, trajectory_command_t m, std::int64_t session, std::int64_t seq) {
    m.id = next_id++;
    m.session = session;
    m.seq = seq;
    const ack_t* a = send_bytes(h.cfg.lcm.trajectory_channel, sign(m, who), m.id);
    EXPECT_NE(a, nullptr) << "no answer to trajectory kind " << int(m.kind);
    return a ? *a : ack_t{};
  }
  // The session for `who` (0 when refused); seq restarts at 1.
  std::int64_t acquire(const Credentials& who, std::int64_t nonce = 77) {
    const ack_t a = control(&who, C::CMD_ACQUIRE, nonce, daemon::test::acquire_seq());
    return a.accepted ? a.session : 0;
  }
  // Alice holding the machine enabled; returns her session (seq 1 used).
  std::int64_t alice_holding() {
    const std::int64_t s = acquire(alice);
    EXPECT_NE(s, 0);
    EXPECT_TRUE(control(&alice, C::CMD_ENABLE, s, 1).accepted);
    cycles(20);
    EXPECT_EQ(h.mode(), daemon::Mode::holding);
    return s;
  }
};

inline trajectory_command_t move_to(const Vec3& p, double v = 0.05) {
  trajectory_command_t m{};
  m.kind = trajectory_command_t::KIND_MOVE;
  for (int i = 0; i < 3; ++i) m.target[i] = p[i];
  m.max_velocity = v, m.max_acceleration = 1.0, m.max_jerk = 50.0;
  return m;
}
inline trajectory_command_t paper_circle() {
  trajectory_command_t m{};
  m.kind = trajectory_command_t::KIND_CIRCLE;
  m.centre[0] = 0.425, m.centre[1] = 0.425, m.centre[2] = 0.300;
  m.radius = 0.175, m.angular_speed = M_PI / 2, m.cruise_time = 4.0;
  m.allow_velocity_step = true;  // Elkady's start at speed: granted on the simulator
  return m;
}
// A stream from `a` along -x, at rest at both ends, n points over T s.
inline trajectory_command_t stream_from(const Vec3& a, int n = 100, double T = 1.0, double dx = -0.01) {
  trajectory_command_t m{};
  m.kind = trajectory_command_t::KIND_STREAM;
  m.count = static_cast<std::int16_t>(n);
  for (int i = 0; i < n; ++i) {
    const double s = static_cast<double>(i) / (n - 1);
    m.time[i] = T * s;
    m.position[i][0] = a.x() + dx * s * s * (3 - 2 * s);
    m.position[i][1] = a.y();
    m.position[i][2] = a.z();
    m.velocity[i][0] = dx * 6 * s * (1 - s) / T;
  }
  return m;
}

}  // namespace cpm::redteam
