// SPDX-License-Identifier: Apache-2.0
// The red team against cpmd itself, over real UDP, each test in its own
// network namespace (support/daemon_process.hpp): a stranger on the bus, a
// bounded flood of 20 000 messages, two daemons, bad files at start, key
// rotation, malformed and oversized packets on every channel, full and
// read-only file systems. docs/security.md lists each with its outcome.
#include <fcntl.h>
#include <gtest/gtest.h>
#include <arpa/inet.h>
#include <netinet/in.h>
#include <sched.h>
#include <sys/mount.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <fstream>
#include <sstream>
#include <chrono>
#include <cmath>
#include <cstdlib>
#include <lcm/lcm-cpp.hpp>
#include <thread>

#include "cpm/daemon/client.hpp"
#include "cpm/io/model_file.hpp"
#include "redteam/redteam.hpp"
#include "support/daemon_process.hpp"

namespace cpm::redteam {
namespace {

using daemon::Client;
using daemon::Role;
using Clock = std::chrono::steady_clock;

const auto* const kEchoReport = ::testing::AddGlobalTestEnvironment(new EchoReport);

trajectory_command_t move_to(double x, double y, double z, double v) {
  trajectory_command_t m{};
  m.kind = trajectory_command_t::KIND_MOVE;
  m.target[0] = x, m.target[1] = y, m.target[2] = z;
  m.max_velocity = v, m.max_acceleration = 1.0, m.max_jerk = 50.0;
  return m;
}
trajectory_command_t circle(double cruise) {
  trajectory_command_t m{};
  m.kind = trajectory_command_t::KIND_CIRCLE;
  m.centre[0] = 0.425, m.centre[1] = 0.425, m.centre[2] = 0.300;
  m.radius = 0.175, m.angular_speed = M_PI / 2, m.cruise_time = cruise, m.ramp_time = 0.5;
  return m;
}

// A running cpmd on the simulator with operators alice (engineer) and bob
// (operator), and what a stranger on the bus has: a raw LCM handle.
struct Rig {
  cpm::test::TempDir dir;
  cpm::test::OperatorsDir ops;
  Credentials alice, bob;
  std::string config;
  daemon::DaemonConfig cfg;
  std::unique_ptr<cpm::test::Process> cpmd;
  daemon::Key signing_seed = daemon::generate_key();
  explicit Rig(const std::string& name, const std::vector<std::pair<std::string, std::string>>& edits = {},
               bool unsigned_daemon = false)
      : dir("redteam-" + name), ops(dir / "operators.d"), alice(ops.add("alice", Role::engineer)),
        bob(ops.add("bob", Role::operator_)) {
    std::filesystem::create_directories(dir / "models");
    std::filesystem::copy_file(std::string(CPM_SOURCE_DIR) + "/config/machine.yaml", dir / "models/machine.yaml");
    // cpmd signs its state and acks, as on a shop floor (docs/security.md, "Signed state");
    // a test's own signing_key edit, or `unsigned_daemon`, comes instead.
    std::vector<std::pair<std::string, std::string>> all = edits;
    if (!unsigned_daemon && std::none_of(edits.begin(), edits.end(), [](const auto& e) {
          return e.second.find("signing_key") != std::string::npos;
        })) {
      daemon::write_key_file(dir / "cpmd.key", signing_seed);
      all.insert(all.begin(), {"refusal_acks_per_second: 20", "refusal_acks_per_second: 20\n  signing_key: " +
                                                                  (dir / "cpmd.key")});
    }
    config = cpm::test::sim_config(dir.path(), "sim.yaml", ops.path(), all, dir / "models");
    cfg = daemon::load_config(config);
  }
  // cpmd's public key in a file, as an operator's client is given it.
  std::string public_key_file() {
    const std::string pub = dir / "cpmd.pub";
    daemon::write_public_key_file(pub, daemon::public_key_of(signing_seed));
    return pub;
  }
  // A client of `who` that verifies cpmd's seals, the machine enabled and
  // holding; `st` is the verified holding state.
  std::unique_ptr<Client> enabled_verifying(const Credentials& who, std::optional<state_t>& st) {
    auto c = std::make_unique<Client>(cfg.lcm, who);
    c->verify_with(daemon::public_key_of(signing_seed));
    EXPECT_TRUE(c->control(cpm_msgs::control_command_t::CMD_ENABLE).accepted);
    for (int i = 0; i < 50 && !(st && st->mode == state_t::MODE_HOLDING); ++i) st = c->state(0.2);
    EXPECT_TRUE(st && st->mode == state_t::MODE_HOLDING) << "cpmd did not reach holding";
    return c;
  }
  // Starts cpmd (with `extra` arguments) and waits for its first state.
  void start(const std::vector<std::string>& extra = {}) {
    cpmd = cpm::test::start_cpmd(config, dir / "cpmd.log", extra);
    Client watcher(cfg.lcm);
    for (int i = 0; i < 100; ++i)
      if (watcher.state(0.2)) return;
    FAIL() << "cpmd published no state:\n" << cpmd->log();
  }
  std::optional<state_t> state() {
    Client watcher(cfg.lcm);
    return watcher.state(2.0);
  }
  std::optional<cpm_msgs::security_t> security() {
    Client watcher(cfg.lcm);
    return watcher.security(3.0);
  }
};

// What anyone on the bus can do: publish bytes, read the acks.
struct Stranger {
  lcm::LCM bus;
  daemon::LcmConfig cfg;
  std::vector<ack_t> acks;
  std::int64_t next_id = 1 << 20;
  explicit Stranger(const daemon::LcmConfig& c) : bus(c.url), cfg(c) {
    bus.subscribe(cfg.ack_channel, &Stranger::on_ack, this);
  }
  void on_ack(const lcm::ReceiveBuffer* rb, const std::string&) {
    if (auto a = daemon::decode_ack(rb->data, rb->data_size)) acks.push_back(*a);
  }
  void publish(const std::string& ch, const Bytes& b) { bus.publish(ch, b.data(), static_cast<unsigned>(b.size())); }
  std::optional<ack_t> wait(std::int64_t id, double s = 2.0) {
    const auto end = Clock::now() + std::chrono::duration<double>(s);
    while (Clock::now() < end) {
      for (const auto& a : acks)
        if (a.id == id) return a;
      bus.handleTimeout(20);
    }
    return std::nullopt;
  }
  template <class M>
  std::optional<ack_t> send(const std::string& ch, M m, const Credentials* who = nullptr) {
    m.id = ++next_id;
    if (who) daemon::sign(m, *who);
    publish(ch, encode(m));
    return wait(m.id);
  }
};

// `cpm` as an operator without any key would run it: no key file, no $HOME key.
int run_cpm(const Rig& r, const std::vector<std::string>& args, std::string* out) {
  std::vector<std::string> argv{"/usr/bin/env", "-i", "HOME=" + (r.dir / "nohome"), CPM_EXE};
  argv.insert(argv.end(), args.begin(), args.end());
  argv.insert(argv.end(), {"--url", r.cfg.lcm.url});
  cpm::test::Process p(argv, r.dir / "cpm.log", /*stdout_log=*/true);
  const auto rc = p.wait_exit_for(30);
  if (out) *out = p.log();
  return rc ? *rc : -1;
}

// ---------------------------------------------------------------- a stranger

TEST(Stranger, CannotEnableMoveLoadAModelOrChangeGains) {
  Rig r("stranger");
  r.start();
  const auto before = r.state();
  ASSERT_TRUE(before);
  Stranger s(r.cfg.lcm);
  Credentials mallory = r.alice;  // alice's name, a key of its own
  mallory.key = daemon::generate_key();
  std::set<std::string> words;
  for (const Credentials* who : {static_cast<const Credentials*>(nullptr), static_cast<const Credentials*>(&mallory)}) {
    for (std::int8_t cmd : {C::CMD_ACQUIRE, C::CMD_ENABLE, C::CMD_SELECT_CONTROLLER, C::CMD_LOAD_MODEL, C::CMD_RESET}) {
      C m{};
      m.command = cmd;
      m.seq = std::chrono::duration_cast<std::chrono::microseconds>(std::chrono::system_clock::now().time_since_epoch()).count();
      m.law = 0;
      for (int i = 0; i < 3; ++i) m.kp[i] = 5e4, m.kd[i] = 500;
      m.model_path = "machine.yaml";
      const auto a = s.send(r.cfg.lcm.control_channel, m, who);
      ASSERT_TRUE(a) << "no answer to command " << int(cmd);
      EXPECT_EQ(a->reason, ack_t::REASON_NOT_AUTHORIZED) << int(cmd) << ": " << a->message;
      const Bytes sent_bytes = encode(m);
      expect_no_echo(a->message, std::string(sent_bytes.begin(), sent_bytes.end()), "a stranger's command");
      expect_no_echo(a->message, m.model_path, "a stranger's model path");
      words.insert(a->message);
    }
    const auto a = s.send(r.cfg.lcm.trajectory_channel, move_to(0.45, 0.40, 0.35, 0.1), who);
    ASSERT_TRUE(a);
    EXPECT_EQ(a->reason, ack_t::REASON_NOT_AUTHORIZED) << a->message;
  }
  EXPECT_EQ(words.size(), 1u);
  // The tool without a key refuses before sending anything.
  std::string out;
  EXPECT_NE(run_cpm(r, {"enable"}, &out), 0);
  EXPECT_NE(out.find("no operator key"), std::string::npos) << out;
  EXPECT_NE(run_cpm(r, {"load-model", "machine.yaml"}, &out), 0);
  EXPECT_NE(run_cpm(r, {"controller", "pd"}, &out), 0);
  std::this_thread::sleep_for(std::chrono::milliseconds(500));
  const auto after = r.state();
  ASSERT_TRUE(after);
  EXPECT_EQ(after->mode, state_t::MODE_DISABLED);
  EXPECT_EQ(after->controller, before->controller);
  EXPECT_EQ(after->position[0], before->position[0]);
  const auto sec = r.security();
  ASSERT_TRUE(sec);
  EXPECT_EQ(sec->refused_no_operator + sec->refused_bad_mac, 12);
  EXPECT_NE(r.cpmd->log().find("refused"), std::string::npos) << "the journal says nothing of the refusals";
  // An operator gets in as usual.
  Client alice(r.cfg.lcm, r.alice);
  EXPECT_TRUE(alice.control(C::CMD_ENABLE).accepted);
}

TEST(Stranger, CanStopTheMachine) {
  Rig r("stop");
  r.start();
  Client alice(r.cfg.lcm, r.alice);
  ASSERT_TRUE(alice.control(C::CMD_ENABLE).accepted);
  std::optional<state_t> st;
  for (int i = 0; i < 50 && !(st && st->mode == state_t::MODE_HOLDING); ++i) st = alice.state(0.2);
  ASSERT_EQ(st->mode, state_t::MODE_HOLDING);
  ASSERT_TRUE(alice.trajectory(move_to(0.40, 0.425, 0.300, 0.05)).accepted);  // 4 s
  for (int i = 0; i < 50 && st->mode != state_t::MODE_MOVING; ++i) st = alice.state(0.2);
  ASSERT_EQ(st->mode, state_t::MODE_MOVING);
  // A raw, unsigned stop without a session.
  Stranger s(r.cfg.lcm);
  C stop{};
  stop.command = C::CMD_STOP;
  const auto a = s.send(r.cfg.lcm.control_channel, stop);
  ASSERT_TRUE(a);
  EXPECT_TRUE(a->accepted) << a->message;
  for (int i = 0; i < 50 && st->mode != state_t::MODE_HOLDING; ++i) st = alice.state(0.2);
  EXPECT_EQ(st->mode, state_t::MODE_HOLDING);
  EXPECT_GT(st->position[0] - 0.40, 0.05) << "it went on to the target";
  // And `cpm stop` with no key at all.
  ASSERT_TRUE(alice.trajectory(move_to(0.40, 0.425, 0.300, 0.05)).accepted);
  for (int i = 0; i < 50 && st->mode != state_t::MODE_MOVING; ++i) st = alice.state(0.2);
  std::string out;
  EXPECT_EQ(run_cpm(r, {"stop"}, &out), 0) << out;
  st = alice.state(1.0);
  // Up to 3 s of states (the braking takes a fraction of that): 50 were too
  // few once the states queued while `cpm stop` started were read first.
  for (int i = 0; i < 3000 && st && st->mode != state_t::MODE_HOLDING; ++i) st = alice.state(0.2);
  ASSERT_TRUE(st);
  EXPECT_EQ(st->mode, state_t::MODE_HOLDING);
  EXPECT_GT(st->position[0] - 0.40, 0.01);
}

// ---------------------------------------------------------------- forged state

// Issue 27's first attack against a signing cpmd: forged "holding" states
// carrying the id of the move `cpm move` waits for (the genuine message,
// mode changed: no seal of cpmd lists it; and unsigned ones), sent
// every 5 ms for 1.5 s of a 4 s move. The waiting `cpm move` must not end
// early, `cpm status` must show the machine moving.
TEST(ForgedState, DoesNotEndAWaitingMoveNorShowInStatus) {
  Rig r("forged");
  const std::string pub = r.public_key_file();
  r.start();
  std::optional<state_t> st;
  auto alice_client = r.enabled_verifying(r.alice, st);
  ASSERT_FALSE(::testing::Test::HasFailure());
  Client& alice = *alice_client;
  alice.release();
  const auto t0 = Clock::now();
  std::vector<std::string> argv{"/usr/bin/env", "-i", "HOME=" + (r.dir / "nohome"), CPM_EXE, "move", "0.40,0.425,0.300",
                                "--vmax", "0.05", "--url", r.cfg.lcm.url, "--key", r.ops.key_path("alice"),
                                "--daemon-key", pub};
  cpm::test::Process move(argv, r.dir / "move.log", /*stdout_log=*/true);
  for (int i = 0; i < 50 && st->mode != state_t::MODE_MOVING; ++i) st = alice.state(0.2);
  ASSERT_EQ(st->mode, state_t::MODE_MOVING) << move.log();
  const std::int64_t move_id = st->segment_id;
  std::atomic<int> forged{0};
  std::thread forger([&] {
    Stranger s(r.cfg.lcm);
    const auto end = Clock::now() + std::chrono::milliseconds(1500);
    while (Clock::now() < end) {
      state_t f = *st;  // the genuine message, its counter raised
      f.mode = state_t::MODE_HOLDING;
      f.segment_id = -1;
      f.queue_depth = 0;
      f.last_segment_id = move_id;
      f.last_segment_rmse = f.last_segment_max = 1e-7;
      f.sign_counter = st->sign_counter + 1000000 + forged;
      s.publish(r.cfg.lcm.state_channel, encode(f));
      f.sign_counter = 0;
      s.publish(r.cfg.lcm.state_channel, encode(f));
      forged += 2;
      std::this_thread::sleep_for(std::chrono::milliseconds(5));
    }
  });
  std::string out;
  std::vector<std::string> status{"/usr/bin/env", "-i", "HOME=" + (r.dir / "nohome"), CPM_EXE, "status",
                                  "--url", r.cfg.lcm.url, "--daemon-key", pub};
  cpm::test::Process stat(status, r.dir / "status.log", /*stdout_log=*/true);
  const auto src = stat.wait_exit_for(10);
  forger.join();
  EXPECT_EQ(src.value_or(-1), 0) << stat.log();
  EXPECT_NE(stat.log().find("moving"), std::string::npos) << stat.log();
  EXPECT_EQ(stat.log().find("holding"), std::string::npos) << stat.log();
  EXPECT_FALSE(move.wait_exit_for(0.1).has_value()) << "cpm move ended on forged state:\n" << move.log();
  const auto rc = move.wait_exit_for(30);
  const double took = std::chrono::duration<double>(Clock::now() - t0).count();
  EXPECT_EQ(rc.value_or(-1), 0) << move.log();
  EXPECT_GT(took, 3.5) << move.log();
  std::printf("forged states sent while cpm move waited: %d; cpm move ended after %.2f s (a 4 s move)\n",
              forged.load(), took);
}

// Forged "disabled" states and forged drives with the e-stop pressed, every
// 5 ms, against a signing cpmd holding still: `cpm watch` and the example
// client, given cpmd's public key, show only what cpmd sealed and say that
// they refused the rest.
TEST(ForgedState, WatchAndTheExampleClientShowOnlyVerifiedMessages) {
  Rig r("forged-view");
  const std::string pub = r.public_key_file();
  r.start();
  std::optional<state_t> st;
  const auto alice = r.enabled_verifying(r.alice, st);  // her session holds the machine enabled
  ASSERT_FALSE(::testing::Test::HasFailure());
  std::atomic<bool> forging{true};
  std::atomic<int> forged{0};
  std::thread forger([&] {
    Stranger s(r.cfg.lcm);
    while (forging) {
      state_t f = *st;
      f.mode = state_t::MODE_DISABLED;
      f.cycle += 1000000;
      f.sign_counter += 1000000 + forged;
      s.publish(r.cfg.lcm.state_channel, encode(f));
      cpm_msgs::drives_t d{};
      d.cycle = f.cycle;
      d.estop = true;
      s.publish(r.cfg.lcm.drives_channel, encode(d));
      forged += 2;
      std::this_thread::sleep_for(std::chrono::milliseconds(5));
    }
  });
  std::vector<std::string> watch{"/usr/bin/env", "-i", "HOME=" + (r.dir / "nohome"), CPM_EXE, "watch", "--once",
                                 "--url", r.cfg.lcm.url, "--daemon-key", pub};
  cpm::test::Process w(watch, r.dir / "watch.log", /*stdout_log=*/true);
  EXPECT_EQ(w.wait_exit_for(15).value_or(-1), 0) << w.log();
#ifdef EXAMPLE_CLIENT_EXE
  std::vector<std::string> example{"/usr/bin/env", "-i", "HOME=" + (r.dir / "nohome"), "CPM_DAEMON_KEY=" + pub,
                                   "LCM_DEFAULT_URL=" + r.cfg.lcm.url, EXAMPLE_CLIENT_EXE};
  cpm::test::Process e(example, r.dir / "example.log", /*stdout_log=*/true);
  EXPECT_EQ(e.wait_exit_for(15).value_or(-1), 0) << e.log();
#endif
  forging = false;
  forger.join();
  EXPECT_NE(w.log().find("HOLDING"), std::string::npos) << w.log();
  EXPECT_EQ(w.log().find("DISABLED"), std::string::npos) << "forged state shown:\n" << w.log();
  EXPECT_EQ(w.log().find("PRESSED"), std::string::npos) << "forged drives shown:\n" << w.log();
  EXPECT_NE(w.log().find("refused"), std::string::npos) << w.log();
#ifdef EXAMPLE_CLIENT_EXE
  EXPECT_NE(e.log().find("holding"), std::string::npos) << e.log();
  EXPECT_NE(e.log().find("verified"), std::string::npos) << e.log();
  EXPECT_EQ(e.log().find("disabled"), std::string::npos) << "forged state shown:\n" << e.log();
#endif
  std::printf("forged messages sent while cpm watch and the example client read: %d\n", forged.load());
}

// What the seals cost a reader in time (docs/security.md, "Signed state"):
// a client verifying and one not, reading the same sealing cpmd at once.
// Asserts counts only (every stop answered, the verifying client's states
// all verified and in order); the delays are printed, not judged.
TEST(ForgedState, SealsDelayAVerifyingReaderWithinTheirBound) {
  Rig r("seal-latency");
  r.start();
  Client plain(r.cfg.lcm), verifying(r.cfg.lcm);
  verifying.verify_with(daemon::public_key_of(r.signing_seed));
  auto wall_us = [] {
    return std::chrono::duration_cast<std::chrono::microseconds>(
               std::chrono::system_clock::now().time_since_epoch())
        .count();
  };
  // The time from cpmd's publishing (state_t.utime) to the client's having it, per state.
  std::vector<double> d_plain, d_verified;
  std::int64_t last_cycle = -1;
  bool ordered = true;
  plain.on_state([&](const state_t& s) { d_plain.push_back(1e-3 * static_cast<double>(wall_us() - s.utime)); });
  verifying.on_state([&](const state_t& s) {
    d_verified.push_back(1e-3 * static_cast<double>(wall_us() - s.utime));
    ordered = ordered && s.cycle > last_cycle;
    last_cycle = s.cycle;
  });
  {  // each reading all the time, on its own thread
    std::thread t([&] { plain.handle(1.0); });
    verifying.handle(1.0);
    t.join();
  }
  // Stops (anyone may send one; disabled, it changes nothing): the answer's round trip.
  std::vector<double> rt_plain, rt_verified;
  for (int i = 0; i < 20; ++i)
    for (auto* c : {&plain, &verifying}) {
      const auto t0 = Clock::now();
      (void)c->control(C::CMD_STOP);
      (c == &plain ? rt_plain : rt_verified).push_back(std::chrono::duration<double, std::milli>(Clock::now() - t0).count());
    }
  ASSERT_GT(d_plain.size(), 100u);
  ASSERT_GT(d_verified.size(), 100u);
  EXPECT_TRUE(ordered);
  EXPECT_EQ(verifying.verifier()->refused_total(), 0);
  EXPECT_EQ(rt_verified.size(), 20u);
  auto med = [](std::vector<double> v) {
    std::sort(v.begin(), v.end());
    return v[v.size() / 2];
  };
  auto worst = [](const std::vector<double>& v) { return *std::max_element(v.begin(), v.end()); };
  std::printf("seal latency: state publish-to-client median %.2f ms (max %.2f) unverified, %.2f ms (max %.2f) "
              "verified, over %zu and %zu states; stop ack round trip median %.2f ms (max %.2f) unverified, %.2f ms "
              "(max %.2f) verified, 20 each\n",
              med(d_plain), worst(d_plain), med(d_verified), worst(d_verified), d_plain.size(), d_verified.size(),
              med(rt_plain), worst(rt_plain), med(rt_verified), worst(rt_verified));
}

// Against a cpmd that does not sign (an old one, or no security.signing_key):
// `cpm status` told to verify refuses its state and says it cannot be
// verified; without a public key it shows the state marked NOT VERIFIED.
TEST(ForgedState, AnUnsignedCpmdsStateIsSaidToBeUnverifiable) {
  cpm::test::TempDir kd("redteam-unsigned-key");
  const std::string pub = kd / "cpmd.pub";
  daemon::write_public_key_file(pub, daemon::public_key_of(daemon::generate_key()));
  Rig r("unsigned", {}, /*unsigned_daemon=*/true);
  r.start();
  std::vector<std::string> base{"/usr/bin/env", "-i", "HOME=" + (r.dir / "nohome"), CPM_EXE, "status",
                                "--url", r.cfg.lcm.url};
  std::vector<std::string> with_key = base;
  with_key.insert(with_key.end(), {"--daemon-key", pub});
  cpm::test::Process verified(with_key, r.dir / "status-key.log", /*stdout_log=*/true);
  EXPECT_NE(verified.wait_exit_for(10).value_or(0), 0) << verified.log();
  EXPECT_NE(verified.log().find("cannot be verified"), std::string::npos) << verified.log();
  EXPECT_EQ(verified.log().find("disabled"), std::string::npos) << "showed unverified state:\n" << verified.log();
  cpm::test::Process plain(base, r.dir / "status.log", /*stdout_log=*/true);
  EXPECT_EQ(plain.wait_exit_for(10).value_or(-1), 0) << plain.log();
  EXPECT_NE(plain.log().find("CANNOT BE VERIFIED"), std::string::npos) << plain.log();
  EXPECT_NE(plain.log().find("NOT VERIFIED"), std::string::npos) << plain.log();
}

// ---------------------------------------------------------------- the largest model

// Cycles from a stop's sending to the loop's braking that still show it did
// not wait behind other work on the LCM thread (the costly command of
// StopPath holds it > 200 cycles): 1-2 on a quiet host, the figure the tests
// print; a host loaded with other tests delays the listener's wake-up by a
// few cycles, which is scheduling, not the path under test.
constexpr std::int64_t kStopWithoutWaiting = 50;

// Enable, then a 4 s move: the machine is moving when it returns.
void start_a_four_second_move(Client& alice) {
  ASSERT_TRUE(alice.control(C::CMD_ENABLE).accepted);
  std::optional<state_t> st;
  for (int i = 0; i < 50 && !(st && st->mode == state_t::MODE_HOLDING); ++i) st = alice.state(0.2);
  ASSERT_EQ(st->mode, state_t::MODE_HOLDING);
  ASSERT_TRUE(alice.trajectory(move_to(0.40, 0.425, 0.300, 0.05)).accepted);
  for (int i = 0; i < 50 && st->mode != state_t::MODE_MOVING; ++i) st = alice.state(0.2);
  ASSERT_EQ(st->mode, state_t::MODE_MOVING);
}

// The state as a stranger reads it: the first braking cycle, and the loop's
// cycle at a moment (the newest state's cycle plus the 1 ms cycles since it
// arrived).
struct BrakingWatch {
  std::int64_t last_cycle = -1, stopping_cycle = -1;
  Clock::time_point last_at, stopping_at;
  void on(const lcm::ReceiveBuffer*, const std::string&, const state_t* m) {
    if (stopping_cycle < 0 && m->mode == state_t::MODE_STOPPING) {
      stopping_cycle = m->cycle;
      stopping_at = Clock::now();
    }
    if (stopping_cycle < 0 && m->cycle > last_cycle) last_cycle = m->cycle, last_at = Clock::now();
  }
  [[nodiscard]] std::int64_t cycle_at(Clock::time_point t) const {
    return last_cycle + static_cast<std::int64_t>(std::llround(std::chrono::duration<double>(t - last_at).count() * 1000.0));
  }
};

// A field of /proc/PID/status in kB (VmRSS, VmHWM, VmLck); -1 when unreadable.
long status_kb(pid_t pid, const std::string& key) {
  std::ifstream f("/proc/" + std::to_string(pid) + "/status");
  std::string line;
  while (std::getline(f, line))
    if (line.rfind(key + ":", 0) == 0) return std::stol(line.substr(key.size() + 1));
  return -1;
}

// The largest model files allowed (kMaxModelFileBytes): the machine's model
// padded with a comment (it loads), and one whose padding is just under
// kMaxModelNodes list items (the costliest parse; the schema refuses it).
void write_largest_models(const std::filesystem::path& dir) {
  std::ifstream f(std::string(CPM_SOURCE_DIR) + "/config/machine.yaml");
  std::stringstream ss;
  ss << f.rdbuf();
  const std::string machine = ss.str();
  const auto n = static_cast<std::size_t>(daemon::kMaxModelFileBytes);
  std::string text = machine;
  text += "#" + std::string(n - text.size() - 2, '-') + "\n";
  std::ofstream(dir / "largest.yaml") << text;
  text = machine + "notes:\n";
  const std::size_t items = static_cast<std::size_t>(daemon::kMaxModelNodes) - 1000;
  const std::size_t per = (n - text.size() - 64) / items;  // bytes per item line
  for (std::size_t i = 0; i < items; ++i) text += "  - " + std::string(per - 5, 'x') + "\n";
  text += "#" + std::string(n - text.size() - 2, '-') + "\n";
  std::ofstream(dir / "nodes.yaml") << text;
}

// cpmd locks memory (loop.lock_memory, MCL_FUTURE | MCL_ONFAULT). Loading the
// largest model files allowed while disabled: the daemon's LCM thread keeps
// answering stops at once during the parse (it runs on the loader's thread),
// and nothing of the parse stays resident or locked. Then, while moving, the
// largest load and a stranger's stop sent together: the load is refused
// unread, and the loop brakes within a few cycles of the stop's sending.
TEST(LargestModel, ParsedOffTheLcmThreadLeavesNothingLockedAndAStopBrakesAtOnce) {
  Rig r("largest-model");
  write_largest_models(r.dir / "models");
  r.start();
  const pid_t pid = r.cpmd->pid();
  Client alice(r.cfg.lcm, r.alice);
  ASSERT_TRUE(alice.control(C::CMD_PING).accepted);
  std::this_thread::sleep_for(std::chrono::milliseconds(500));
  const long rss0 = status_kb(pid, "VmRSS"), lck0 = status_kb(pid, "VmLck"), hwm0 = status_kb(pid, "VmHWM");
  std::printf("  cpmd before: VmRSS %ld kB, VmLck %ld kB, VmHWM %ld kB\n", rss0, lck0, hwm0);
  long rss_last = -1;
  int round = 0;
  for (const std::string name : {"largest.yaml", "nodes.yaml", "nodes.yaml", "nodes.yaml", "nodes.yaml"}) {
    // A stranger's stop, again and again, during the load: each one's answer time.
    std::atomic<bool> done{false};
    std::vector<double> stop_ms;
    std::thread stopper([&] {
      Stranger s(r.cfg.lcm);
      while (!done.load()) {
        C stop{};
        stop.command = C::CMD_STOP;
        const auto t0 = Clock::now();
        if (s.send(r.cfg.lcm.control_channel, stop))
          stop_ms.push_back(std::chrono::duration<double, std::milli>(Clock::now() - t0).count());
      }
    });
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
    C load{};
    load.command = C::CMD_LOAD_MODEL;
    load.model_path = name;
    const auto t0 = Clock::now();
    const ack_t a = alice.control(load, 20.0);
    const double load_ms = std::chrono::duration<double, std::milli>(Clock::now() - t0).count();
    done = true;
    stopper.join();
    std::this_thread::sleep_for(std::chrono::milliseconds(300));
    const long rss = status_kb(pid, "VmRSS"), lck = status_kb(pid, "VmLck"), hwm = status_kb(pid, "VmHWM");
    ASSERT_FALSE(stop_ms.empty());
    const double worst = *std::max_element(stop_ms.begin(), stop_ms.end());
    std::printf("  %s (%ld B): answered in %.0f ms (%s); %zu stops answered meanwhile, the slowest in %.1f ms; "
                "after: VmRSS %ld kB, VmLck %ld kB, VmHWM %ld kB\n",
                name.c_str(), static_cast<long>(std::filesystem::file_size(r.dir / ("models/" + name))), load_ms,
                a.accepted ? "loaded" : a.message.c_str(), stop_ms.size(), worst, rss, lck, hwm);
    if (name == "largest.yaml") EXPECT_TRUE(a.accepted) << a.message;
    else EXPECT_EQ(a.reason, ack_t::REASON_LOAD_FAILED) << a.message;
    EXPECT_LT(worst, 100.0) << "a stop waited for the parse";
    // The parse's heap is not locked while it lives (FutureLocksPaused) and
    // is handed back when it ends: what stays is the model and the loader's
    // stack, not the 13 MB a 19 000-node parse left resident and locked
    // before; loads again do not grow it.
    EXPECT_LT(rss - rss0, 2048) << "the parse left memory resident (locked)";
    if (++round == 5) {
      EXPECT_LT(rss - rss_last, 1024) << "loads again go on growing cpmd";
    }
    rss_last = rss;
    EXPECT_LT(hwm - hwm0, 64 * 1024) << "the parse's peak";
    // Locked is what is resident plus the loader's 1 MiB stack, never a
    // reserve: a thread's own malloc arena (64 MiB) and a default 8 MiB
    // stack once added 72 MiB here at the first load.
    EXPECT_LT(lck - lck0, (rss - rss0) + 2048) << "the load left address space locked beyond what is resident";
  }
  // Moving: the largest load and a stop together.
  start_a_four_second_move(alice);
  if (HasFatalFailure()) return;
  BrakingWatch w;
  Stranger s(r.cfg.lcm);
  s.bus.subscribe(r.cfg.lcm.state_channel, &BrakingWatch::on, &w);
  for (auto end = Clock::now() + std::chrono::milliseconds(200); Clock::now() < end;) s.bus.handleTimeout(5);
  C load{};
  load.command = C::CMD_LOAD_MODEL;
  load.model_path = "nodes.yaml";
  std::optional<ack_t> la;
  std::thread loader([&] { la = alice.control(load, 5.0); });
  C stop{};
  stop.command = C::CMD_STOP;
  stop.id = 4242;
  const auto sent = Clock::now();
  const std::int64_t sent_after = w.cycle_at(sent);
  s.publish(r.cfg.lcm.control_channel, encode(stop));
  for (auto end = Clock::now() + std::chrono::seconds(2); w.stopping_cycle < 0 && Clock::now() < end;)
    s.bus.handleTimeout(5);
  loader.join();
  ASSERT_GE(w.stopping_cycle, 0) << "no braking seen";
  const double ms = std::chrono::duration<double, std::milli>(w.stopping_at - sent).count();
  std::printf("  moving, the largest load and a stop together: braking %lld cycles after the stop was "
              "sent, seen %.2f ms after sending; the load: %s\n",
              static_cast<long long>(w.stopping_cycle - sent_after), ms, la ? la->message.c_str() : "(no answer)");
  ASSERT_TRUE(la);
  EXPECT_EQ(la->reason, ack_t::REASON_ILLEGAL_IN_MODE) << la->message;
  // Over UDP and a shared host: the state in flight, the stop's trip, the LCM
  // thread's 1 ms poll, then the loop's next cycle: 1-2 cycles on a quiet
  // host (the figure printed above). Asserted is the property, not a time:
  // the stop did not wait behind the load (kStopWithoutWaiting).
  EXPECT_LE(w.stopping_cycle - sent_after, kStopWithoutWaiting);
}

// While the LCM thread validates the longest segment allowed (a 10-minute
// circle, sampled at the loop's period), a stranger's stop: it reaches the
// loop on its own path and the loop brakes within 2 cycles of its arrival.
TEST(StopPath, BrakesWhileTheLcmThreadIsBusyWithACostlyCommand) {
  Rig r("stop-path");
  r.start();
  Client alice(r.cfg.lcm, r.alice);
  start_a_four_second_move(alice);
  if (HasFatalFailure()) return;
  BrakingWatch w;
  Stranger s(r.cfg.lcm);
  s.bus.subscribe(r.cfg.lcm.state_channel, &BrakingWatch::on, &w);
  for (auto end = Clock::now() + std::chrono::milliseconds(200); Clock::now() < end;) s.bus.handleTimeout(5);
  // The costly command first: a circle of 590 s at the end of the move,
  // validated sample by sample on the LCM thread.
  trajectory_command_t long_circle = circle(590.0);
  long_circle.radius = 0.1;
  long_circle.centre[0] = 0.50;  // starts where the move ends (angle pi: centre - radius on x)
  long_circle.start_angle = M_PI;
  long_circle.allow_velocity_step = true;
  const auto costly_sent = Clock::now();
  const std::int64_t costly = alice.send_trajectory(long_circle);
  std::this_thread::sleep_for(std::chrono::milliseconds(5));  // the LCM thread is in it
  C stop{};
  stop.command = C::CMD_STOP;
  stop.id = 4343;
  const auto sent = Clock::now();
  const std::int64_t sent_after = w.cycle_at(sent);
  s.publish(r.cfg.lcm.control_channel, encode(stop));
  for (auto end = Clock::now() + std::chrono::seconds(3); w.stopping_cycle < 0 && Clock::now() < end;)
    s.bus.handleTimeout(5);
  const ack_t ca = alice.wait_ack(costly, 30.0);
  const double costly_ms = std::chrono::duration<double, std::milli>(Clock::now() - costly_sent).count();
  ASSERT_GE(w.stopping_cycle, 0) << "no braking seen";
  const double ms = std::chrono::duration<double, std::milli>(w.stopping_at - sent).count();
  std::printf("  the LCM thread busy %.0f ms with a 590 s circle (%s): braking %lld cycles after the stop was "
              "sent, seen %.2f ms after sending\n",
              costly_ms, ca.accepted ? "accepted" : ca.message.c_str(),
              static_cast<long long>(w.stopping_cycle - sent_after), ms);
  // The loop's cycle numbers say when it braked; the state saying so is
  // published by the LCM thread once the costly command is done.
  // 1-2 cycles on a quiet host (printed above); asserted is that the stop did
  // not wait for the costly command (> 200 ms, below), whatever else the host
  // is doing: a shared CI host stalls a thread for several ms.
  EXPECT_LE(w.stopping_cycle - sent_after, kStopWithoutWaiting) << "the stop waited for the costly command";
  EXPECT_GT(costly_ms, 200.0) << "the costly command was not costly: the test proves nothing";
}

// ---------------------------------------------------------------- replay across a restart

// An operator's acquire recorded off the bus (as lcm-logger would), cpmd
// restarted, the recording played back at once (well within the 30 s
// acquire window): refused, no session; the operator acquires at once.
TEST(Replay, ARecordedAcquireIsRefusedAfterARestart) {
  Rig r("replay-restart");
  r.start();
  struct Recorder {
    std::vector<Bytes> acquires;
    void on(const lcm::ReceiveBuffer* rb, const std::string&) {
      const auto* d = static_cast<const std::uint8_t*>(rb->data);
      if (daemon::is_acquire(d, rb->data_size)) acquires.emplace_back(d, d + rb->data_size);
    }
  } rec;
  Stranger s(r.cfg.lcm);
  s.bus.subscribe(r.cfg.lcm.control_channel, &Recorder::on, &rec);
  std::int64_t boot_before = 0;
  {
    Client alice(r.cfg.lcm, r.alice);
    ASSERT_TRUE(alice.control(C::CMD_PING).accepted);  // acquires first
    boot_before = alice.state(2.0)->boot_id;
  }
  for (auto end = Clock::now() + std::chrono::milliseconds(300); Clock::now() < end;) s.bus.handleTimeout(10);
  ASSERT_EQ(rec.acquires.size(), 1u);
  ASSERT_EQ(r.cpmd->terminate(), 0) << r.cpmd->log();
  r.start();
  const std::optional<state_t> st = r.state();
  ASSERT_TRUE(st);
  EXPECT_NE(st->boot_id, boot_before);
  C recorded{};
  ASSERT_EQ(recorded.decode(rec.acquires[0].data(), 0, static_cast<int>(rec.acquires[0].size())),
            static_cast<int>(rec.acquires[0].size()));
  s.acks.clear();
  s.publish(r.cfg.lcm.control_channel, rec.acquires[0]);
  const auto a = s.wait(recorded.id);
  ASSERT_TRUE(a) << "no answer to the replayed acquire";
  EXPECT_FALSE(a->accepted);
  EXPECT_EQ(a->reason, ack_t::REASON_NOT_AUTHORIZED) << a->message;
  EXPECT_EQ(a->session, 0);
  const auto sec = r.security();
  ASSERT_TRUE(sec);
  EXPECT_EQ(sec->refused_bad_mac, 1);
  Client alice(r.cfg.lcm, r.alice);
  EXPECT_TRUE(alice.control(C::CMD_PING).accepted) << "the operator could not acquire after the replay";
  std::printf("  boot %lld -> %lld; the recorded acquire: %s\n", static_cast<long long>(boot_before),
              static_cast<long long>(st->boot_id), a->message.c_str());
}

// ---------------------------------------------------------------- flood

// 20 000 hostile messages in 10 s (2 kHz, twice the loop rate) while the
// machine runs a circle: no cycle missed for the flood (the daemon's own
// overrun counter), no growth of its resident memory, the operator still
// served, the messages counted. As deployed (loop.cpu): the loop alone on
// the last CPU (cpmd keeps its other threads off it), the network's kernel
// work on another (here: the flood is sent from CPU 0).
//
// A shared or virtual host stalls a 1 kHz loop now and then with no flood
// at all (0.1 to 0.7 overruns a second measured on the 2-core CI machine
// under other work: a vCPU descheduled for a millisecond), and more when
// the virtual machine as a whole is busier: sending 2 000 datagrams a
// second costs the host too, whoever receives them (measured here: 42
// overruns in 10 quiet seconds against 159 in the flood's, with cpmd's
// loop alone on its CPU under SCHED_FIFO). So the windows the flood is
// compared with are not quiet: for 5 s just before and 5 s just after, the
// same messages at the same rate go from the same CPU to another port, one
// cpmd does not listen on. All that differs between the windows is cpmd
// receiving and refusing them. Of the n overruns in all 20 s, the flood's
// share is binomial (n, 1/2) when that costs nothing, and a share that
// chance gives less than once in a thousand fails (a flood that cost even
// one cycle a second fails whenever the host is reasonably quiet).
double share_at_least(std::int64_t k, std::int64_t n, double p) {
  double tail = 0.0;
  for (std::int64_t i = k; i <= n; ++i)
    tail += std::exp(std::lgamma(n + 1.0) - std::lgamma(i + 1.0) - std::lgamma(n - i + 1.0) + i * std::log(p) +
                     (n - i) * std::log1p(-p));
  return std::min(1.0, tail);
}

TEST(Flood, TwentyThousandMessagesInTenSecondsMissNoCycleAndGrowNoMemory) {
  // CPM_FLOOD_UNSIGNED=1: against a cpmd without a signing key, to compare (docs/security.md).
  Rig r("flood", {}, std::getenv("CPM_FLOOD_UNSIGNED") != nullptr);
  const long cpus = ::sysconf(_SC_NPROCESSORS_ONLN);
  r.start(cpus >= 2 ? std::vector<std::string>{"--loop-cpu", std::to_string(cpus - 1)} : std::vector<std::string>{});
  if (cpus >= 2) {
    // This process (the operator, the senders) stays off the loop's CPU, as
    // everything else does on a machine where loop.cpu is set.
    cpu_set_t set;
    CPU_ZERO(&set);
    for (long c = 0; c + 1 < cpus; ++c) CPU_SET(static_cast<int>(c), &set);
    ::pthread_setaffinity_np(::pthread_self(), sizeof set, &set);
  }
  Client alice(r.cfg.lcm, r.alice);
  ASSERT_TRUE(alice.control(C::CMD_ENABLE).accepted);
  std::optional<state_t> st;
  for (int i = 0; i < 50 && !(st && st->mode == state_t::MODE_HOLDING); ++i) st = alice.state(0.2);
  const char* scale_env0 = std::getenv("CPM_FLOOD_SCALE");
  const double motion = 14.0 + 10.0 * (scale_env0 ? std::max(1, std::atoi(scale_env0)) : 1);
  ASSERT_TRUE(alice.trajectory(circle(motion)).accepted);  // 1 s settling, 5 s decoy, the flood, 5 s decoy
  alice.handle(1.0);                                     // settle, then measure

  // What the stranger sends, by message number modulo 10.
  Credentials mallory = r.alice;
  mallory.key = daemon::generate_key();
  const Credentials eve{"eve", daemon::generate_key()};
  C recorded{};
  recorded.command = C::CMD_PING, recorded.session = alice.session(), recorded.seq = 1;
  daemon::sign(recorded, r.alice);  // alice's, already used: a replay
  const Bytes replay = encode(recorded);
  trajectory_command_t big = circle(4.0);
  const std::int64_t session = alice.session();
  // CPM_FLOOD_SCALE=6: the same rate for a minute (by hand; CI runs 10 s).
  const char* scale_env = std::getenv("CPM_FLOOD_SCALE");
  const int scale = scale_env ? std::max(1, std::atoi(scale_env)) : 1;
  const int kMessages = 20000 * scale;
  const double kSeconds = 10.0 * scale;
  constexpr double kRate = 2000.0;  // messages per second, twice the loop rate
  // `n` messages at kRate to `url`, from CPU 0 (loopback does the receiving
  // side's kernel work, softirq that no thread preempts, on the sender's CPU:
  // keep it off the loop's, as a machine steers its network interrupts away
  // from loop.cpu, docs/security.md).
  auto send = [&](const std::string& url, int n, std::atomic<int>& sent) {
    if (cpus >= 2) {
      cpu_set_t set;
      CPU_ZERO(&set);
      CPU_SET(0, &set);
      ::pthread_setaffinity_np(::pthread_self(), sizeof set, &set);
    }
    lcm::LCM bus(url);
    std::uint64_t x = 12345;
    const auto t0 = Clock::now();
    for (int i = 0; i < n; ++i) {
      std::this_thread::sleep_until(t0 + std::chrono::duration<double>(i / kRate));
      C m{};
      m.id = i;
      m.command = static_cast<std::int8_t>((1 + i % 9) == C::CMD_STOP ? C::CMD_ENABLE : 1 + i % 9);  // all but stop
      m.session = session;
      m.seq = 1000000 + i;
      Bytes b;
      std::string ch = r.cfg.lcm.control_channel;
      switch (i % 10) {
        case 0: b = encode(m); break;
        case 1: daemon::sign(m, mallory), b = encode(m); break;
        case 2: daemon::sign(m, eve), b = encode(m); break;
        case 3: {
          trajectory_command_t t = big;
          t.id = i, b = encode(t), ch = r.cfg.lcm.trajectory_channel;
          break;
        }
        case 4: {
          trajectory_command_t t = big;
          t.id = i, daemon::sign(t, mallory), b = encode(t), ch = r.cfg.lcm.trajectory_channel;
          break;
        }
        case 5: b = replay; break;
        case 6: m.command = C::CMD_ACQUIRE, m.session = i, b = encode(m); break;
        case 7:
          b.resize(1 + (x = x * 6364136223846793005ull + 1) % 1024);
          for (auto& c : b) c = static_cast<std::uint8_t>((x = x * 6364136223846793005ull + 1) >> 56);
          break;
        case 8: b = encode(big), b.resize(b.size() / 2), ch = r.cfg.lcm.trajectory_channel; break;
        default: b.assign(60000, 0x5a); break;  // a datagram's worth of nothing
      }
      bus.publish(ch, b.data(), static_cast<unsigned>(b.size()));
      sent.fetch_add(1);
    }
  };
  // The decoy: the same group, a port nobody in this test listens on.
  std::string decoy_url = r.cfg.lcm.url;
  const std::string port = ":" + std::to_string(cpm::test::lcm_port());
  ASSERT_NE(decoy_url.find(port), std::string::npos) << decoy_url;
  decoy_url.replace(decoy_url.find(port), port.size(), ":" + std::to_string(cpm::test::lcm_port() + 1));
  ASSERT_NE(decoy_url, r.cfg.lcm.url);
  const int kDecoy = static_cast<int>(kRate * 5.0);  // each decoy window: 5 s
  auto decoy = [&](double seconds) {
    std::atomic<int> decoy_sent{0};
    std::thread t([&] { send(decoy_url, kDecoy, decoy_sent); });
    alice.handle(seconds);
    t.join();
    return decoy_sent.load();
  };

  const auto q0 = alice.state(1.0);
  ASSERT_TRUE(q0);
  const int decoy_before = decoy(5.0);  // the control window before
  const auto s0 = alice.state(1.0);
  ASSERT_TRUE(s0);
  const long rss0 = cpm::test::rss_kb(r.cpmd->pid());
  std::atomic<int> sent{0};
  std::thread flood([&] { send(r.cfg.lcm.url, kMessages, sent); });
  // Meanwhile the operator is served.
  const auto t_flood = Clock::now();
  alice.handle(1.0);
  const long rss_warm = cpm::test::rss_kb(r.cpmd->pid());  // every path of the refusals has run once
  alice.handle(4.0);
  const long rss_mid = cpm::test::rss_kb(r.cpmd->pid());
  const ack_t ping = alice.control(C::CMD_PING, 2.0);
  std::string rss_series = std::to_string(rss_mid);
  for (auto next = Clock::now() + std::chrono::seconds(5); sent.load() < kMessages;) {
    alice.handle(0.1);  // and keeps her session alive
    if (Clock::now() > next) {
      rss_series += " " + std::to_string(cpm::test::rss_kb(r.cpmd->pid()));
      next += std::chrono::seconds(5);
    }
  }
  std::printf("flood: VmRSS every 5 s from the 5th: %s kB\n", rss_series.c_str());
  flood.join();
  const double flood_s = std::chrono::duration<double>(Clock::now() - t_flood).count();
  const auto s1 = alice.state(2.0);
  ASSERT_TRUE(s1) << "no state after the flood; cpmd " << (r.cpmd->running() ? "runs" : "is gone") << ":\n"
                  << r.cpmd->log();
  const int decoy_after = decoy(5.0);  // the control window after
  const auto q1 = alice.state(2.0);
  ASSERT_TRUE(q1) << "no state 5 s after the flood; cpmd " << (r.cpmd->running() ? "runs" : "is gone") << ":\n"
                  << r.cpmd->log();
  const long rss1 = cpm::test::rss_kb(r.cpmd->pid());
  const auto sec = r.security();
  ASSERT_TRUE(sec);
  const long long refused = sec->refused_no_operator + sec->refused_bad_mac + sec->refused_replay + sec->undecodable;
  const std::int64_t quiet = (s0->overruns - q0->overruns) + (q1->overruns - s1->overruns),
                     flooded = s1->overruns - s0->overruns;
  std::printf("flood: decoy 5 s before and 5 s after (%d + %d messages to a port cpmd does not read): %lld overruns, "
              "%lld skipped slots\n",
              decoy_before, decoy_after, static_cast<long long>(quiet),
              static_cast<long long>((s0->skipped - q0->skipped) + (q1->skipped - s1->skipped)));
  std::printf("flood: %d messages in %.1f s; overruns %lld -> %lld, skipped slots %lld -> %lld, cycles %lld -> %lld; "
              "VmRSS %ld -> %ld kB (after 1 s %ld, 5 s %ld); counted %lld (no operator %lld, wrong MAC %lld, replay %lld, undecodable "
              "%lld), %lld refusals unanswered; mode %s, faults %d\n",
              sent.load(), flood_s, static_cast<long long>(s0->overruns), static_cast<long long>(s1->overruns),
              static_cast<long long>(s0->skipped), static_cast<long long>(s1->skipped),
              static_cast<long long>(s0->cycles), static_cast<long long>(s1->cycles), rss0, rss1, rss_warm, rss_mid, refused,
              static_cast<long long>(sec->refused_no_operator), static_cast<long long>(sec->refused_bad_mac),
              static_cast<long long>(sec->refused_replay), static_cast<long long>(sec->undecodable),
              static_cast<long long>(sec->refusals_unanswered), daemon::mode_text(s1->mode), s1->faults);
  EXPECT_EQ(sent.load(), kMessages);
  EXPECT_EQ(decoy_before + decoy_after, 2 * kDecoy);
  if (quiet == 0 && flooded == 0) std::printf("flood: 0 missed cycles, with and without the flood\n");
  const double chance = share_at_least(flooded, flooded + quiet, scale / (scale + 1.0));
  std::printf("flood: the chance of a share this large without any cost of the flood: %.3g\n", chance);
  EXPECT_GE(chance, 1e-3) << flooded << " overruns during the flood's " << kSeconds << " s, " << quiet
                          << " in the decoy's 10 s around it";
  EXPECT_EQ(s1->faults, 0);
  EXPECT_TRUE(ping.accepted) << "the operator was not served during the flood: " << ping.message;
  // UDP may drop datagrams when the host is busy (the kernel's receive
  // buffer, 208 kB by default, fills); the test counts only if most arrived.
  EXPECT_GE(refused, kMessages * 3 / 4) << "most of the flood never reached the daemon";
  // No growth. Memory is locked as it is first touched, so the flood's
  // first seconds fault in what its paths use (LCM's receive buffers, the
  // heap's high-water mark, the seals' buffers). How long that takes varies
  // with the host's load: the rise after the first second was 20-424 kB in
  // four runs (the same with signing off), while a 60 s flood
  // (CPM_FLOOD_SCALE=6) levels off by its 5th second (+56 kB over the last
  // 55 s and 118 000 messages). So growth is judged from the 5th second on:
  // a leak of 25 bytes a message over the 10 000 messages after it would
  // pass 256 kB.
  EXPECT_LE(rss1 - rss_mid, 256) << "VmRSS grew from " << rss_mid << " kB (5th second) to " << rss1
                                 << " kB under the flood (after 1 s: " << rss_warm << " kB)";
  EXPECT_LE(rss1 - rss0, 1024) << "the flood cost " << rss1 - rss0 << " kB of resident memory";
}

// ---------------------------------------------------------------- two daemons

TEST(TwoDaemons, TheSecondRefusesToStartAndTheFirstGoesOn) {
  Rig r("two");
  r.start();
  const auto second = cpm::test::start_cpmd(r.config, r.dir / "second.log");
  const auto rc = second->wait_exit_for(15);
  ASSERT_TRUE(rc) << "the second cpmd is still running";
  EXPECT_EQ(*rc, 1);
  EXPECT_NE(second->log().find("another cpmd is already publishing"), std::string::npos) << second->log();
  EXPECT_TRUE(r.cpmd->running());
  Client alice(r.cfg.lcm, r.alice);
  Stranger listener(r.cfg.lcm);
  const ack_t a = alice.control(C::CMD_ENABLE);
  EXPECT_TRUE(a.accepted) << a.message;
  // One answer per command: one daemon took it.
  for (int i = 0; i < 25; ++i) listener.bus.handleTimeout(20);
  EXPECT_EQ(std::count_if(listener.acks.begin(), listener.acks.end(), [&](const ack_t& x) { return x.id == a.id; }), 1);
}

// ---------------------------------------------------------------- bad files

struct StartCase {
  std::string what;
  std::string expect;  // in cpmd's stderr
};

// cpmd with `args`: exits 1 within 15 s (no hang), says `expect`, and
// never publishes a state.
void expect_no_start(const Rig& r, const std::vector<std::string>& argv, const StartCase& c) {
  Client watcher(r.cfg.lcm);
  cpm::test::Process p(argv, r.dir / "bad.log");
  const auto rc = p.wait_exit_for(15);
  ASSERT_TRUE(rc) << c.what << ": cpmd did not exit (a hang)";
  EXPECT_EQ(*rc, 1) << c.what << ": " << p.log();
  EXPECT_NE(p.log().find(c.expect), std::string::npos) << c.what << ": " << p.log();
  EXPECT_FALSE(watcher.state(0.2)) << c.what << ": a state was published";
  std::printf("  %-34s -> %s", c.what.c_str(), p.log().c_str());
}

TEST(BadFilesAtStart, ConfigsAreRefusedBeforeAnythingRuns) {
  Rig r("badconfig");
  const std::string good = r.config;
  std::ofstream(r.dir / "notyaml.yaml") << "model_file: [unclosed\n";
  {
    std::ofstream f(r.dir / "huge.yaml");
    f << std::string(2 << 20, '#');
  }
  std::filesystem::create_directories(r.dir / "dir.yaml");
  ASSERT_EQ(::mkfifo((r.dir / "fifo.yaml").c_str(), 0600), 0);
  std::filesystem::copy_file(good, r.dir / "locked.yaml");
  ::chmod((r.dir / "locked.yaml").c_str(), 0);
  for (auto [file, c] : std::vector<std::pair<std::string, StartCase>>{
           {"notyaml.yaml", {"a config that is no YAML", "notyaml.yaml:"}},
           {"huge.yaml", {"a 2 MiB config", "more than the"}},
           {"dir.yaml", {"a directory as the config", "is a directory"}},
           {"fifo.yaml", {"a FIFO as the config", "not a regular file"}},
           {"missing.yaml", {"a missing config", "No such file"}}})
    expect_no_start(r, {CPMD_EXE, "--config", r.dir / file}, c);
  // Unreadable: as root every file is readable, so cpmd runs as nobody.
  std::vector<std::string> as_other;
  if (::geteuid() == 0) as_other = {"/usr/bin/setpriv", "--reuid=65534", "--regid=65534", "--clear-groups"};
  as_other.insert(as_other.end(), {CPMD_EXE, "--config", r.dir / "locked.yaml"});
  ::chmod(r.dir.path().c_str(), 0755);
  expect_no_start(r, as_other, {"an unreadable config", "Permission denied"});
}

TEST(BadFilesAtStart, ModelsAreRefusedBeforeAnythingRuns) {
  Rig r("badmodel");
  std::ofstream(r.dir / "models/bad.yaml") << "cpmd_model: 1\ngeometry: {L: fast}\n";
  {
    const int fd = ::open((r.dir / "models/huge.yaml").c_str(), O_WRONLY | O_CREAT, 0644);
    ASSERT_EQ(::ftruncate(fd, daemon::kMaxModelFileBytes + 1), 0);
    ::close(fd);
  }
  std::filesystem::create_directories(r.dir / "models/dir.yaml");
  ASSERT_EQ(::mkfifo((r.dir / "models/fifo.yaml").c_str(), 0600), 0);
  for (auto [file, c] : std::vector<std::pair<std::string, StartCase>>{
           {"bad.yaml", {"a model that is no model", "bad.yaml:"}},
           {"huge.yaml", {"a 1 MiB + 1 byte model", "more than the"}},
           {"dir.yaml", {"a directory as the model", "is a directory"}},
           {"fifo.yaml", {"a FIFO as the model", "not a regular file"}}}) {
    const std::string cfg = cpm::test::sim_config(r.dir.path(), "m.yaml", r.ops.path(),
                                                  {{"model_file: [^ \\n]+", "model_file: " + (r.dir / "models/" + file)}});
    expect_no_start(r, {CPMD_EXE, "--config", cfg}, c);
  }
}

// ---------------------------------------------------------------- rotation

bool commands(const Rig& r, const Credentials& who) {
  try {
    Client c(r.cfg.lcm, who);
    const bool ok = c.control(C::CMD_PING, 1.0).accepted;
    c.release();  // before the next client of the same operator asks
    return ok;
  } catch (const Error&) {
    return false;  // refused at the acquire
  }
}
bool eventually(const std::function<bool()>& f, double s = 5.0) {
  for (const auto end = Clock::now() + std::chrono::duration<double>(s); Clock::now() < end;
       std::this_thread::sleep_for(std::chrono::milliseconds(100)))
    if (f()) return true;
  return false;
}

TEST(Rotation, KeysChangeOnSighupOrWhenTheDirectoryChangesWithoutARestart) {
  Rig r("rotation");
  r.start();
  const pid_t pid = r.cpmd->pid();
  const Credentials old_alice = r.alice;
  ASSERT_TRUE(commands(r, old_alice));
  const auto s0 = r.state();
  // Rotate alice's key and tell cpmd.
  const Credentials new_alice = r.ops.add("alice", Role::engineer);
  r.cpmd->signal(SIGHUP);
  EXPECT_TRUE(eventually([&] { return commands(r, new_alice); })) << r.cpmd->log();
  EXPECT_FALSE(commands(r, old_alice)) << "the old key still works";
  // Without a signal: the directory changed. A new operator, then a revocation.
  const Credentials carol = r.ops.add("carol", Role::operator_);
  EXPECT_TRUE(eventually([&] { return commands(r, carol); })) << r.cpmd->log();
  std::filesystem::remove(r.ops.key_path("bob"));
  EXPECT_TRUE(eventually([&] { return !commands(r, r.bob); })) << "bob's key outlived its file";
  // A key left readable by others is refused, and the journal says why.
  const Credentials dave = r.ops.add("dave", Role::operator_);
  ::chmod(r.ops.key_path("dave").c_str(), 0644);
  r.cpmd->signal(SIGHUP);
  EXPECT_TRUE(eventually([&] { return r.cpmd->log().find("dave.key: permissions 0644 are too open") != std::string::npos; }))
      << r.cpmd->log();
  EXPECT_FALSE(commands(r, dave));
  // roles.yaml others may write: the reload is refused, the table in use stays.
  ::chmod((r.ops.path() + "/roles.yaml").c_str(), 0666);
  r.cpmd->signal(SIGHUP);
  EXPECT_TRUE(eventually([&] { return r.cpmd->log().find("the operators loaded before stay") != std::string::npos; }));
  EXPECT_TRUE(commands(r, carol));
  // All without a restart.
  EXPECT_EQ(r.cpmd->pid(), pid);
  EXPECT_TRUE(r.cpmd->running());
  const auto s1 = r.state();
  ASSERT_TRUE(s0 && s1);
  EXPECT_GT(s1->cycles, s0->cycles);
  const auto sec = r.security();
  ASSERT_TRUE(sec);
  EXPECT_GE(sec->reloads, 3);
  EXPECT_GE(sec->reload_failures, 1);
}

// ---------------------------------------------------------------- packets

// Junk on every channel, up to 4 MiB a message: the daemon and a client
// listening on the same channels live on, and both still work.
TEST(Packets, MalformedAndOversizedOnEveryChannel) {
  Rig r("packets");
  r.start();
  Client alice(r.cfg.lcm, r.alice);
  ASSERT_TRUE(alice.control(C::CMD_ENABLE).accepted);
  const long rss0 = cpm::test::rss_kb(r.cpmd->pid());
  Stranger s(r.cfg.lcm);
  int sent = 0;
  for (const std::string& ch : {r.cfg.lcm.control_channel, r.cfg.lcm.trajectory_channel, r.cfg.lcm.state_channel,
                                r.cfg.lcm.stats_channel, r.cfg.lcm.ack_channel, r.cfg.lcm.security_channel}) {
    for (std::size_t n : {std::size_t{0}, std::size_t{1}, std::size_t{7}, std::size_t{40}, std::size_t{200},
                          std::size_t{5000}, std::size_t{65000}, std::size_t{1} << 20, std::size_t{4} << 20}) {
      Bytes b(n, 0xFF);
      for (std::size_t i = 0; i < n; i += 97) b[i] = static_cast<std::uint8_t>(i);
      s.publish(ch, b);
      ++sent;
      alice.handle(0.02);  // the client hears it too
    }
    // A message of the right type with string lengths that lie (ack_t's message).
    cpm_msgs::ack_t fake{};
    fake.message = "x";
    Bytes b = encode(fake);
    b[29] = 0xFF, b[30] = 0xFF, b[31] = 0xFF, b[32] = 0xF0;
    s.publish(ch, b);
    ++sent;
  }
  // LCM fragments that announce huge messages (up to LCM's 256 MB) and never
  // finish: LCM reserves the whole message at the first fragment.
  {
    const int fd = ::socket(AF_INET, SOCK_DGRAM, 0);
    const unsigned char ttl = 0;
    ::setsockopt(fd, IPPROTO_IP, IP_MULTICAST_TTL, &ttl, sizeof ttl);
    sockaddr_in to{};
    to.sin_family = AF_INET;
    to.sin_port = htons(static_cast<std::uint16_t>(cpm::test::lcm_port()));
    ::inet_pton(AF_INET, "239.255.76.67", &to.sin_addr);
    std::uint32_t seqno = 1;
    for (const std::string& ch : {r.cfg.lcm.control_channel, r.cfg.lcm.trajectory_channel})
      for (std::uint32_t size : {200u << 20, (1u << 28) - 1, 1u << 28}) {
        Bytes d(20);
        auto put32 = [&](std::size_t at, std::uint32_t v) {
          for (int i = 0; i < 4; ++i) d[at + i] = static_cast<std::uint8_t>(v >> (24 - 8 * i));
        };
        put32(0, 0x4c433033);  // "LC03": a fragment
        put32(4, seqno++);
        put32(8, size);
        put32(12, 0);
        d[16] = 0, d[17] = 0, d[18] = 0x10, d[19] = 0;  // fragment 0 of 4096
        d.insert(d.end(), ch.begin(), ch.end());
        d.push_back(0);
        d.resize(d.size() + 64, 0x42);
        ::sendto(fd, d.data(), d.size(), 0, reinterpret_cast<const sockaddr*>(&to), sizeof to);
        ++sent;
      }
    ::close(fd);
  }
  alice.handle(1.0);
  EXPECT_TRUE(r.cpmd->running()) << r.cpmd->log();
  EXPECT_TRUE(alice.state(1.0).has_value());
  const ack_t a = alice.control(C::CMD_PING);
  EXPECT_TRUE(a.accepted) << a.message;
  const long rss1 = cpm::test::rss_kb(r.cpmd->pid());
  std::printf("packets: %d malformed or oversized messages on 6 channels; cpmd VmRSS %ld -> %ld kB\n", sent, rss0, rss1);
  EXPECT_LE(rss1 - rss0, 512) << "an oversized message left memory behind";
}

// ---------------------------------------------------------------- files

// A model file rewritten into a full file system, and into a read-only one:
// the write fails with a reason and the old file is whole, byte for byte,
// with no temporary file left. cpm's writers and cpmd's --stats-json.
TEST(Files, AFullOrReadOnlyFileSystemLeavesTheOldFileWhole) {
  if (::geteuid() != 0) GTEST_SKIP() << "needs root for a private tmpfs (mount namespace)";
  ASSERT_EQ(::unshare(CLONE_NEWNS), 0);
  ASSERT_EQ(::mount(nullptr, "/", nullptr, MS_REC | MS_PRIVATE, nullptr), 0);
  Rig r("files");
  const std::string fs = r.dir / "fs";
  std::filesystem::create_directories(fs);
  ASSERT_EQ(::mount("tmpfs", fs.c_str(), "tmpfs", 0, "size=1m"), 0) << std::strerror(errno);
  const std::string model = fs + "/model.yaml", stats = fs + "/stats.json";
  io::ModelFile mf;
  const std::string old_text = io::render_model_file(mf);
  io::write_file_atomically(model, old_text);
  // A first stats file, then fill the file system.
  {
    const auto d = cpm::test::start_cpmd(r.config, r.dir / "stats1.log", {"--duration", "0.5", "--stats-json", stats});
    ASSERT_EQ(d->wait_exit(), 0) << d->log();
  }
  const std::string old_stats = [&] {
    std::ifstream f(stats);
    std::stringstream ss;
    ss << f.rdbuf();
    return ss.str();
  }();
  ASSERT_FALSE(old_stats.empty());
  {
    const int fd = ::open((fs + "/filler").c_str(), O_WRONLY | O_CREAT, 0600);
    const std::string block(4096, 'f');
    while (::write(fd, block.data(), block.size()) > 0) {
    }
    ::close(fd);
  }
  auto expect_whole = [&](const std::string& what) {
    std::ifstream f(model);
    std::stringstream ss;
    ss << f.rdbuf();
    EXPECT_EQ(ss.str(), old_text) << what << ": the old model file is not whole";
    std::ifstream g(stats);
    std::stringstream st;
    st << g.rdbuf();
    EXPECT_EQ(st.str(), old_stats) << what << ": the old stats file is not whole";
    for (const auto& e : std::filesystem::directory_iterator(fs)) {
      const std::string n = e.path().filename().string();
      EXPECT_TRUE(n == "model.yaml" || n == "stats.json" || n == "filler") << what << ": left behind: " << n;
    }
  };
  const std::string new_text = old_text + std::string(8192, '#') + "\n";
  // Both writers into the file system as it is now: each fails, says why, and leaves the old file.
  auto rewrite = [&](const std::string& how, int run) {
    try {
      io::write_file_atomically(model, new_text);
      ADD_FAILURE() << "a write into a " << how << " file system succeeded";
    } catch (const Error& e) {
      std::printf("  %s file system: %s\n", how.c_str(), e.what());
    }
    const auto d = cpm::test::start_cpmd(r.config, r.dir / ("stats" + std::to_string(run) + ".log"),
                                         {"--duration", "0.5", "--stats-json", stats});
    EXPECT_EQ(d->wait_exit(), 0);
    EXPECT_NE(d->log().find("cannot write"), std::string::npos) << d->log();
    expect_whole(how);
  };
  rewrite("full", 2);
  ::unlink((fs + "/filler").c_str());  // room again, but read-only (expect_whole allows the filler's absence)
  ASSERT_EQ(::mount(nullptr, fs.c_str(), nullptr, MS_REMOUNT | MS_RDONLY, nullptr), 0) << std::strerror(errno);
  rewrite("read-only", 3);
  ::umount2(fs.c_str(), MNT_DETACH);
}

}  // namespace
}  // namespace cpm::redteam
