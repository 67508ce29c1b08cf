// SPDX-License-Identifier: Apache-2.0
// Hostile input to a running daemon, through its public seams: the server's
// LCM handle (memq://, in-process: bytes published on it reach the same
// subscriptions as on the network) and the control loop on the simulator
// backend, cycle by cycle without threads. Malformed and hostile bytes are
// dropped, replayed ids and out-of-order stream chunks are absorbed or
// refused with a reason, and a flood of commands at 10x the loop rate while
// moving leaves the motion bit for bit as it was without the flood, with at
// most ControlLoop::kCommandsPerCycle commands taken in any cycle.
#include <gtest/gtest.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cmath>
#include <filesystem>
#include <limits>
#include <lcm/lcm-cpp.hpp>
#include <map>
#include <vector>

#include "cpm/daemon/server.hpp"
#include "loop_fixture.hpp"
#include "support/test_operators.hpp"

namespace cpm::daemon {
namespace {

using cpm_msgs::ack_t;
using cpm_msgs::control_command_t;
using cpm_msgs::trajectory_command_t;

struct Session {
  test::LoopHarness h;
  ModelStore models{std::make_unique<ctl::Machine>(ctl::MachineModel::elkady())};
  std::unique_ptr<Server> server;
  std::vector<ack_t> acks;
  std::vector<Vec3> path;          // measured position, every cycle
  int max_taken = 0;               // most commands the loop took in one cycle

  static DaemonConfig config() {
    DaemonConfig c = test::test_config();
    c.lcm.url = "memq://";
    return c;
  }
  Credentials who = test::credentials("alice");  // an engineer
  explicit Session(const DaemonConfig& c = config()) : h(c) {
    server = std::make_unique<Server>(h.cfg, *h.loop, models);
    server->set_wall_clock([] { return test::kWallClock; });
    server->set_boot_id(test::kTestBoot);
    server->set_operators(test::operator_table());
    server->bus().subscribe(h.cfg.lcm.ack_channel, &Session::on_ack, this);
    // Commands need the operator's MAC and the session (test_session.cpp,
    // tests/redteam); this commander holds it and publish() stamps and signs
    // every well-formed command.
    control_command_t acq{};
    acq.command = control_command_t::CMD_ACQUIRE;
    acq.session = 12345;  // nonce
    acq.seq = test::acquire_seq();
    publish(h.cfg.lcm.control_channel, encode(acq));
    if (acks.size() == 1 && acks[0].accepted) sid = acks[0].session;
    acks.clear();
  }
  std::int64_t sid = 0, seq = 0;
  // Session and seq sit at bytes 24..39 of both command types (after the
  // hash, utime and id); the MAC is the last 32 bytes. Bytes with a wrong
  // hash or too short stay as they are.
  void stamp(std::vector<std::uint8_t>& b) {
    if (b.size() < 40 + kMacBytes) return;
    std::uint64_t hash = 0;
    for (int i = 0; i < 8; ++i) hash = (hash << 8) | b[static_cast<std::size_t>(i)];
    if (hash != static_cast<std::uint64_t>(control_command_t::getHash()) &&
        hash != static_cast<std::uint64_t>(trajectory_command_t::getHash()))
      return;
    if (sid != 0) {
      const std::uint64_t v[2] = {static_cast<std::uint64_t>(sid), static_cast<std::uint64_t>(++seq)};
      for (int k = 0; k < 2; ++k)
        for (int i = 0; i < 8; ++i)
          b[static_cast<std::size_t>(24 + 8 * k + i)] = static_cast<std::uint8_t>(v[k] >> (56 - 8 * i));
    }
    sign_encoded(b.data(), b.size(), who.key, who.boot);
  }
  void on_ack(const lcm::ReceiveBuffer*, const std::string&, const ack_t* a) { acks.push_back(*a); }
  void pump() {
    while (server->bus().handleTimeout(0) > 0) {
    }
  }
  void publish(const std::string& channel, std::vector<std::uint8_t> bytes) {
    stamp(bytes);
    server->bus().publish(channel, bytes.data(), static_cast<unsigned>(bytes.size()));
    pump();  // the server's subscriptions decode and validate
  }
  // Encoded with this commander's name in it (publish() signs).
  template <class M>
  static std::vector<std::uint8_t> encode(M m) {
    set_operator_name(m.operator_name, "alice");
    std::vector<std::uint8_t> b(static_cast<std::size_t>(m.getEncodedSize()));
    m.encode(b.data(), 0, static_cast<int>(b.size()));
    return b;
  }
  void control(std::int8_t cmd, std::int64_t id) {
    control_command_t m{};
    m.command = cmd;
    m.id = id;
    publish(h.cfg.lcm.control_channel, encode(m));
  }
  void trajectory(const trajectory_command_t& m) { publish(h.cfg.lcm.trajectory_channel, encode(m)); }
  // One control cycle, then the server publishes what the loop answered.
  void cycle() {
    const std::int64_t before = h.loop->cycles_done();
    const std::size_t queued = h.loop->commands().size();
    h.loop->cycle(h.k++, 0);
    ASSERT_EQ(h.loop->cycles_done(), before + 1);
    max_taken = std::max(max_taken, static_cast<int>(queued - h.loop->commands().size()));
    path.push_back(h.position());
    server->drain();
    pump();
  }
  void cycles(int n) {
    for (int i = 0; i < n; ++i) cycle();
  }
  const ack_t* ack_of(std::int64_t id) const {
    for (const auto& a : acks)
      if (a.id == id) return &a;
    return nullptr;
  }
  int acks_of(std::int64_t id) const {
    int n = 0;
    for (const auto& a : acks) n += a.id == id;
    return n;
  }
};

trajectory_command_t move_to(const Vec3& p, std::int64_t id, double v = 0.05) {
  trajectory_command_t m{};
  m.id = id;
  m.kind = trajectory_command_t::KIND_MOVE;
  for (int i = 0; i < 3; ++i) m.target[i] = p[i];
  m.max_velocity = v, m.max_acceleration = 1.0, m.max_jerk = 50.0;
  return m;
}

// A stream chunk from `a` to `b` (at rest at both ends), `n` points over T s.
trajectory_command_t chunk(const Vec3& a, const Vec3& b, std::int64_t id, double T = 0.3, int n = 7) {
  trajectory_command_t m{};
  m.id = id;
  m.kind = trajectory_command_t::KIND_STREAM;
  m.count = static_cast<std::int16_t>(n);
  for (int i = 0; i < n; ++i) {
    const double s = static_cast<double>(i) / (n - 1);
    const double h = s * s * (3 - 2 * s), dh = 6 * s * (1 - s) / T;
    m.time[i] = T * s;
    for (int j = 0; j < 3; ++j) {
      m.position[i][j] = a[j] + (b[j] - a[j]) * h;
      m.velocity[i][j] = (b[j] - a[j]) * dh;
    }
  }
  return m;
}

TEST(HostileSession, MalformedBytesAreDroppedAndTheDaemonGoesOn) {
  Session s;
  control_command_t ping{};
  ping.command = control_command_t::CMD_PING;
  ping.id = 1;
  const auto good = Session::encode(ping);
  std::vector<std::vector<std::uint8_t>> bad;
  bad.push_back({});                                          // empty
  bad.push_back(std::vector<std::uint8_t>(good.begin(), good.begin() + 20));  // truncated
  auto wrong_hash = good;
  wrong_hash[3] ^= 0x40;
  bad.push_back(wrong_hash);
  // model_path's length prefix (the only string, 4 bytes before its bytes):
  // 0, -1, INT32_MIN and beyond the message. lcm-gen's decoder would call
  // std::string::assign with a negative size for the first three.
  for (std::uint32_t len : {0u, 0xFFFFFFFFu, 0x80000000u, 0x7FFFFFFFu}) {
    auto b = good;
    const std::size_t at = b.size() - 5 - kOperatorNameBytes - kMacBytes;  // "" is encoded as length 1 + NUL
    b[at] = static_cast<std::uint8_t>(len >> 24), b[at + 1] = static_cast<std::uint8_t>(len >> 16);
    b[at + 2] = static_cast<std::uint8_t>(len >> 8), b[at + 3] = static_cast<std::uint8_t>(len);
    bad.push_back(b);
  }
  for (const auto& b : bad) {
    s.publish(s.h.cfg.lcm.control_channel, b);
    s.publish(s.h.cfg.lcm.trajectory_channel, b);
  }
  EXPECT_EQ(s.server->undecodable(), static_cast<std::int64_t>(2 * bad.size()));
  s.cycles(3);
  EXPECT_TRUE(s.acks.empty()) << "an undecodable message was answered";
  // The daemon still answers.
  s.publish(s.h.cfg.lcm.control_channel, good);
  s.cycles(1);
  ASSERT_EQ(s.acks.size(), 1u);
  EXPECT_TRUE(s.acks[0].accepted);
}

TEST(HostileSession, LoadModelRefusesDevicesAndFifos) {
  // Read whole, /dev/zero would exhaust memory and a FIFO would block the
  // thread that has to hear the next stop. (Were they read, this test would
  // not end.) Inside the model directory as well as outside it; the answer
  // names the reason and never echoes the path.
  Session s;
  const std::string dir = s.h.cfg.security.model_dir;
  std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir + "/sub.yaml");
  ASSERT_EQ(::mkfifo((dir + "/fifo.yaml").c_str(), 0600), 0);
  std::filesystem::create_symlink("/dev/zero", dir + "/zero.yaml");
  std::int64_t id = 40;
  for (const std::string& path : {std::string("/dev/zero"), std::string("/dev/stdin"), std::string("/"),
                                  std::string("fifo.yaml"), dir + "/fifo.yaml", std::string("zero.yaml"),
                                  std::string("sub.yaml")}) {
    control_command_t m{};
    m.command = control_command_t::CMD_LOAD_MODEL;
    m.id = id;
    m.model_path = path;
    s.publish(s.h.cfg.lcm.control_channel, Session::encode(m));
    // Read on the model loader's thread: its answer comes with a drain (5 s at most).
    for (int i = 0; i < 5000 && !s.ack_of(id); ++i) {
      if (i) ::usleep(1000);
      s.server->drain();
      s.pump();
    }
    const ack_t* a = s.ack_of(id++);
    ASSERT_NE(a, nullptr) << path;
    EXPECT_FALSE(a->accepted) << path;
    EXPECT_EQ(a->reason, ack_t::REASON_LOAD_FAILED) << path;
    EXPECT_EQ(a->message.find(path), std::string::npos) << a->message;
    EXPECT_FALSE(a->message.empty());
  }
  std::filesystem::remove_all(dir);
}

TEST(HostileSession, ExtremeIdsAreEchoed) {
  Session s;
  const std::int64_t ids[] = {std::numeric_limits<std::int64_t>::min(), -1, 0,
                              std::numeric_limits<std::int64_t>::max()};
  for (std::int64_t id : ids) s.control(control_command_t::CMD_PING, id);
  s.cycles(2);
  for (std::int64_t id : ids) EXPECT_EQ(s.acks_of(id), 1) << id;
}

TEST(HostileSession, ReplayedCommandsAreAbsorbedOrRefused) {
  Session s;
  s.control(control_command_t::CMD_ENABLE, 5);
  s.cycles(20);
  ASSERT_EQ(s.h.mode(), Mode::holding);
  s.control(control_command_t::CMD_ENABLE, 5);  // replayed
  s.cycles(2);
  EXPECT_EQ(s.acks_of(5), 2);
  EXPECT_EQ(s.h.mode(), Mode::holding);
  // A move, and its exact replay: the replay starts where the first ends and
  // goes nowhere, so the machine ends where one move takes it.
  const Vec3 start = s.h.position();
  const Vec3 target = start + Vec3(-0.01, 0.005, 0);
  s.trajectory(move_to(target, 10));
  s.trajectory(move_to(target, 10));
  s.cycles(1500);
  ASSERT_EQ(s.acks_of(10), 2);
  for (const auto& a : s.acks) {
    if (a.id == 10 && !a.accepted) {
      EXPECT_NE(a.reason, ack_t::REASON_NONE);
    }
  }
  EXPECT_EQ(s.h.mode(), Mode::holding);
  EXPECT_EQ(s.h.state().faults, 0);
  EXPECT_LT((s.h.position() - target).norm(), 1e-5);
  // Replayed stop and disable: refused as illegal or done once; never a fault.
  s.control(control_command_t::CMD_DISABLE, 11);
  s.control(control_command_t::CMD_DISABLE, 11);
  s.control(control_command_t::CMD_STOP, 12);
  s.cycles(3);
  EXPECT_EQ(s.acks_of(11), 2);
  EXPECT_EQ(s.acks_of(12), 1);
  const ack_t* stop = s.ack_of(12);
  ASSERT_NE(stop, nullptr);
  EXPECT_FALSE(stop->accepted);
  EXPECT_EQ(stop->reason, ack_t::REASON_ILLEGAL_IN_MODE);
  EXPECT_EQ(s.h.mode(), Mode::disabled);
}

TEST(HostileSession, OutOfOrderStreamChunksAreRefusedThenPlayInOrder) {
  Session s;
  s.control(control_command_t::CMD_ENABLE, 1);
  s.cycles(20);
  const Vec3 a = s.h.position();
  const Vec3 b = a + Vec3(-0.004, 0, 0), c = b + Vec3(-0.004, 0.002, 0);
  s.trajectory(chunk(b, c, 22));  // the second chunk first
  s.cycles(1);
  const ack_t* early = s.ack_of(22);
  ASSERT_NE(early, nullptr);
  EXPECT_FALSE(early->accepted);
  EXPECT_EQ(early->reason, ack_t::REASON_NOT_CONTINUOUS) << early->message;
  s.trajectory(chunk(a, b, 21));
  s.trajectory(chunk(b, c, 22));  // now in order
  s.cycles(800);
  ASSERT_NE(s.ack_of(21), nullptr);
  EXPECT_TRUE(s.ack_of(21)->accepted) << s.ack_of(21)->message;
  int accepted22 = 0;
  for (const auto& x : s.acks) accepted22 += x.id == 22 && x.accepted;
  EXPECT_EQ(accepted22, 1);
  EXPECT_EQ(s.h.state().faults, 0);
  EXPECT_EQ(s.h.state().last_segment_id, 22);
  EXPECT_LT((s.h.position() - c).norm(), 1e-5);
}

// A state drained after the ack of a stream chunk but made in a cycle before
// it (states wait in their ring; decimated, the next comes cycles later)
// holds a queue that ends before the chunk: the next chunk was refused as
// not continuous against it (a 30 s experiment through the virtual drives
// in the emulated SIL guest stopped at row 595 of its file).
TEST(HostileSession, AStateOlderThanAChunksAckDoesNotHideTheChunkFromTheNext) {
  DaemonConfig cfg = Session::config();
  cfg.lcm.state_decimation = 2;
  Session s(cfg);
  s.control(control_command_t::CMD_ENABLE, 1);
  s.cycles(20);
  if (s.h.k % 2 != 0) s.cycle();  // the next cycle makes a state
  const Vec3 a = s.h.position();
  const Vec3 b = a + Vec3(-0.004, 0, 0), c = b + Vec3(-0.004, 0.002, 0);
  s.h.loop->cycle(s.h.k++, 0);    // its state waits, not yet drained
  s.trajectory(chunk(a, b, 21));
  s.cycle();                      // the chunk taken and acked, no state of this cycle; then both drained
  ASSERT_NE(s.ack_of(21), nullptr);
  ASSERT_TRUE(s.ack_of(21)->accepted) << s.ack_of(21)->message;
  s.trajectory(chunk(b, c, 22));
  s.cycle();
  ASSERT_NE(s.ack_of(22), nullptr);
  EXPECT_TRUE(s.ack_of(22)->accepted) << s.ack_of(22)->message;
  s.cycles(800);
  EXPECT_EQ(s.h.state().faults, 0);
  EXPECT_EQ(s.h.state().last_segment_id, 22);
  EXPECT_LT((s.h.position() - c).norm(), 1e-5);
}

// The same 0.9 s move, alone and under a flood of 10 messages per cycle
// (10x the loop rate): pings, refused controller selections, malformed
// bytes and segments that do not join the queue.
TEST(HostileSession, AFloodAtTenTimesTheLoopRateChangesNothingAndIsBounded) {
  auto run = [](bool flood, Session& s) {
    s.control(control_command_t::CMD_ENABLE, 1);
    s.cycles(20);
    const Vec3 target = s.h.position() + Vec3(-0.03, 0.01, 0);
    s.trajectory(move_to(target, 2));
    std::int64_t id = 1000;
    for (int k = 0; k < 900; ++k) {
      if (flood) {
        for (int j = 0; j < 7; ++j) s.control(control_command_t::CMD_PING, id++);
        control_command_t sel{};
        sel.command = control_command_t::CMD_SELECT_CONTROLLER;
        sel.id = id++;
        sel.law = 3;
        sel.kp[0] = NAN;  // refused by the server: never reaches the loop
        s.publish(s.h.cfg.lcm.control_channel, Session::encode(sel));
        s.publish(s.h.cfg.lcm.control_channel, {1, 2, 3});  // dropped
        const Vec3 off = target + Vec3(0.01, 0, 0);
        s.trajectory(chunk(off, off + Vec3(0, 0.001, 0), id++));  // does not start at the queue's end
      }
      s.cycle();
    }
    s.cycles(300);
    return id - 1000;
  };
  Session quiet, loud;
  run(false, quiet);
  const std::int64_t sent = run(true, loud);
  ASSERT_EQ(sent, 900 * 9);  // the malformed ones carry no id

  // The motion is the same, bit for bit: the flood took nothing from the loop.
  ASSERT_EQ(quiet.path.size(), loud.path.size());
  for (std::size_t i = 0; i < quiet.path.size(); ++i)
    ASSERT_EQ(quiet.path[i], loud.path[i]) << "cycle " << i;
  EXPECT_EQ(loud.h.state().last_segment_id, 2);
  EXPECT_EQ(loud.h.state().faults, 0);
  EXPECT_EQ(loud.h.mode(), Mode::holding);

  // Bounded: never more than kCommandsPerCycle commands in one cycle, and the
  // loop ran at full bound while flooded.
  EXPECT_EQ(loud.max_taken, ControlLoop::kCommandsPerCycle);
  EXPECT_LE(quiet.max_taken, ControlLoop::kCommandsPerCycle);
  // Every message with an id was answered exactly once: accepted, or refused
  // with a reason (busy: the loop's queue was full; invalid; not continuous).
  std::map<std::int16_t, int> reasons;
  int accepted = 0;
  for (std::int64_t id = 1000; id < 1000 + sent; ++id) {
    ASSERT_EQ(loud.acks_of(id), 1) << "id " << id;
    const ack_t& a = *loud.ack_of(id);
    if (a.accepted) ++accepted;
    else reasons[a.reason]++;
  }
  EXPECT_EQ(reasons[ack_t::REASON_INVALID], 900);          // the NaN gains
  EXPECT_EQ(reasons[ack_t::REASON_NOT_CONTINUOUS], 900);   // the segments
  EXPECT_GT(reasons[ack_t::REASON_BUSY], 0);               // the pings beyond the loop's pace
  EXPECT_EQ(accepted + reasons[ack_t::REASON_BUSY], 900 * 7);
  EXPECT_EQ(loud.server->undecodable(), 900);
  std::printf("flood: %lld messages in 900 cycles, %d pings accepted, %d refused busy, at most %d per cycle\n",
              static_cast<long long>(sent), accepted, reasons[ack_t::REASON_BUSY], loud.max_taken);
}

}  // namespace
}  // namespace cpm::daemon
