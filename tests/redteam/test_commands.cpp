// SPDX-License-Identifier: Apache-2.0
// The red team against the daemon's command side, in-process (cell.hpp):
// commands without a key, with a wrong key, from an unknown operator, with
// a stolen session, replayed, with a stale seq; roles; a stranger's stop;
// acquire floods; malformed packets on every channel; NaN, infinities and
// subnormals in every number; 10^5 setpoints; time going backwards; points
// outside the workspace. Each test asserts the outcome docs/security.md
// documents for the attack, and that a refusal changed nothing.
#include <cfloat>
#include <cmath>
#include <limits>
#include <map>

#include "redteam/cell.hpp"

namespace cpm::redteam {
namespace {

const auto* const kEchoReport = ::testing::AddGlobalTestEnvironment(new EchoReport);

// What the machine is, to show a refusal changed none of it.
struct Snapshot {
  daemon::Mode mode;
  const ctl::Machine* model;
  std::int8_t law;
  std::int64_t session;
  Vec3 ref;
  int queue;
  explicit Snapshot(Cell& c)
      : mode(c.h.mode()), model(&c.models.current()), law(c.h.state().controller), session(c.server->session()),
        ref(c.h.state().position_ref[0], c.h.state().position_ref[1], c.h.state().position_ref[2]),
        queue(c.h.state().queue_depth) {}
  void expect_same(Cell& c, const std::string& what) const {
    const Snapshot now(c);
    EXPECT_EQ(now.mode, mode) << what;
    EXPECT_EQ(now.model, model) << what << ": the model changed";
    EXPECT_EQ(now.law, law) << what << ": the control law changed";
    EXPECT_EQ(now.session, session) << what << ": the session changed";
    EXPECT_LT((now.ref - ref).norm(), 1e-12) << what << ": the setpoint moved";
    EXPECT_EQ(now.queue, queue) << what << ": something was queued";
  }
};

// Every command a stranger might send, but stop.
std::vector<std::pair<std::string, std::function<void(C&)>>> control_attacks() {
  return {
      {"enable", [](C& m) { m.command = C::CMD_ENABLE; }},
      {"disable", [](C& m) { m.command = C::CMD_DISABLE; }},
      {"reset", [](C& m) { m.command = C::CMD_RESET; }},
      {"ping", [](C& m) { m.command = C::CMD_PING; }},
      {"release", [](C& m) { m.command = C::CMD_RELEASE; }},
      {"acquire", [](C& m) { m.command = C::CMD_ACQUIRE, m.seq = daemon::test::acquire_seq(); }},
      {"select_controller",
       [](C& m) {
         m.command = C::CMD_SELECT_CONTROLLER, m.law = 0;
         for (int i = 0; i < 3; ++i) m.kp[i] = 5e4, m.kd[i] = 500;
       }},
      {"load_model", [](C& m) { m.command = C::CMD_LOAD_MODEL, m.model_path = "builtin:elkady"; }},
      {"unknown command", [](C& m) { m.command = 42; }},
  };
}
std::vector<std::pair<std::string, trajectory_command_t>> trajectory_attacks() {
  return {{"move", move_to(kP1 + Vec3(-0.05, 0, 0))}, {"circle", paper_circle()}, {"stream", stream_from(kP1)}};
}

// Sends every attack as `who` (nullptr: unsigned) over the holder's session
// with the next seq (what a stranger reads off the bus), 50 ms apart (slower
// than the refusals' rate limit), and expects each to be refused as not
// authorized, changing nothing. Returns the answers' words.
std::set<std::string> expect_all_refused(Cell& c, const Credentials* who, const std::string& how,
                                         std::int64_t session, std::int64_t& seq) {
  std::set<std::string> words;
  const Snapshot before(c);
  for (auto& [name, edit] : control_attacks()) {
    c.now += 0.05;
    const ack_t a = c.control(who, 0, session, ++seq, edit);
    EXPECT_FALSE(a.accepted) << how << ": " << name;
    EXPECT_EQ(a.reason, ack_t::REASON_NOT_AUTHORIZED) << how << ": " << name << ": " << a.message;
    words.insert(a.message);
  }
  for (auto& [name, m] : trajectory_attacks()) {
    c.now += 0.05;
    const ack_t a = c.trajectory(who, m, session, ++seq);
    EXPECT_FALSE(a.accepted) << how << ": " << name;
    EXPECT_EQ(a.reason, ack_t::REASON_NOT_AUTHORIZED) << how << ": " << name << ": " << a.message;
    words.insert(a.message);
  }
  c.cycles(50);
  before.expect_same(c, how);
  return words;
}

TEST(NoKey, NoCommandButStopIsTakenWithoutAKey) {
  Cell c;
  std::int64_t seq = 0;
  const auto words = expect_all_refused(c, nullptr, "no key, no session", 0, seq);
  EXPECT_EQ(words.size(), 1u) << "the refusals differ: they tell a stranger something";
  EXPECT_EQ(c.server->security().refused_no_operator, 12);
  // With the session and seq of the holder read off the bus: still nothing.
  const std::int64_t s = c.acquire(c.alice);
  ASSERT_NE(s, 0);
  seq = 0;
  expect_all_refused(c, nullptr, "no key, the holder's session", s, seq);
  // The holder is unaffected: her seq 1 is still unused.
  EXPECT_TRUE(c.control(&c.alice, C::CMD_ENABLE, s, 1).accepted);
  c.cycles(20);
  EXPECT_EQ(c.h.mode(), daemon::Mode::holding);
}

TEST(WrongKey, IsRefusedInTheSameWordsAsNoKey) {
  Cell c;
  std::int64_t seq = 0;
  const auto none = expect_all_refused(c, nullptr, "no key", 0, seq);
  Credentials mallory = c.alice;  // alice's name, another key
  mallory.key = daemon::generate_key();
  const std::int64_t s = c.acquire(c.alice);
  seq = 0;
  const auto wrong = expect_all_refused(c, &mallory, "alice's name, a wrong key", s, seq);
  EXPECT_EQ(none, wrong) << "a wrong key is told apart from no key";
  EXPECT_EQ(c.server->security().refused_bad_mac, 12);
  // A key of one bit off.
  Credentials near = c.alice;
  near.key[31] ^= 1;
  seq = 0;
  EXPECT_EQ(expect_all_refused(c, &near, "one bit off alice's key", s, seq), none);
}

TEST(UnknownOperator, IsRefusedInTheSameWordsAsNoKey) {
  Cell c;
  std::int64_t seq = 0;
  const auto none = expect_all_refused(c, nullptr, "no key", 0, seq);
  const Credentials eve = daemon::test::credentials("eve");  // well formed, unknown to cpmd
  seq = 0;
  EXPECT_EQ(expect_all_refused(c, &eve, "an unknown operator", 0, seq), none);
  // A name that is no name (a path, control characters): the same.
  C m{};
  m.command = C::CMD_ENABLE;
  m.id = 9;
  std::memcpy(m.operator_name, "../../etc/passwd\n\x01", 18);
  const ack_t* a = c.send_bytes(c.h.cfg.lcm.control_channel, encode(m), 9);
  ASSERT_NE(a, nullptr);
  EXPECT_EQ(a->message, *none.begin());
  // No NUL in the whole name field: no name.
  std::memset(m.operator_name, 'a', sizeof m.operator_name);
  m.id = 10;
  a = c.send_bytes(c.h.cfg.lcm.control_channel, encode(m), 10);
  ASSERT_NE(a, nullptr);
  EXPECT_EQ(a->reason, ack_t::REASON_NOT_AUTHORIZED);
}

TEST(StolenSession, AnotherOperatorCannotUseTheHoldersSession) {
  Cell c;
  const std::int64_t s = c.alice_holding();
  // Bob is a real operator; alice's session and her next seq are on the bus.
  const ack_t a = c.trajectory(&c.bob, move_to(kP1 + Vec3(-0.05, 0, 0)), s, 2);
  EXPECT_EQ(a.reason, ack_t::REASON_NOT_HOLDER) << a.message;
  EXPECT_EQ(c.control(&c.bob, C::CMD_DISABLE, s, 3).reason, ack_t::REASON_NOT_HOLDER);
  EXPECT_EQ(c.control(&c.bob, C::CMD_RELEASE, s, 4).reason, ack_t::REASON_NOT_HOLDER);
  EXPECT_EQ(c.acquire(c.bob), 0) << "bob took the session from alice";
  c.cycles(10);
  EXPECT_EQ(c.h.mode(), daemon::Mode::holding);
  EXPECT_EQ(c.server->session(), s);
  // Alice's next seq is still hers.
  EXPECT_TRUE(c.control(&c.alice, C::CMD_PING, s, 2).accepted);
}

TEST(Replay, ASignedCommandPlayedAgainFailsOnTheSequence) {
  Cell c;
  const std::int64_t s = c.alice_holding();
  trajectory_command_t m = move_to(kP1 + Vec3(-0.02, 0, 0));
  m.id = 500, m.session = s, m.seq = 2;
  const Bytes recorded = daemon::test::encode_signed(m, c.alice);
  const ack_t* first = c.send_bytes(c.h.cfg.lcm.trajectory_channel, recorded, 500);
  ASSERT_NE(first, nullptr);
  ASSERT_TRUE(first->accepted) << first->message;
  c.acks.clear();
  const ack_t* again = c.send_bytes(c.h.cfg.lcm.trajectory_channel, recorded, 500);
  ASSERT_NE(again, nullptr);
  EXPECT_FALSE(again->accepted);
  EXPECT_EQ(again->reason, ack_t::REASON_STALE_SEQ) << again->message;
  c.cycles(2000);
  EXPECT_LT((c.h.position() - (kP1 + Vec3(-0.02, 0, 0))).norm(), 1e-4) << "moved twice";
  EXPECT_EQ(c.server->security().refused_replay, 1);
  // A control command likewise.
  C d{};
  d.command = C::CMD_DISABLE, d.id = 501, d.session = s, d.seq = 3;
  const Bytes rec2 = daemon::test::encode_signed(d, c.alice);
  ASSERT_TRUE(c.send_bytes(c.h.cfg.lcm.control_channel, rec2, 501)->accepted);
  c.acks.clear();
  EXPECT_EQ(c.send_bytes(c.h.cfg.lcm.control_channel, rec2, 501)->reason, ack_t::REASON_STALE_SEQ);
}

TEST(Replay, AnOldSessionsCommandsAreRefused) {
  Cell c;
  const std::int64_t s = c.acquire(c.alice);
  C e{};
  e.command = C::CMD_ENABLE, e.id = 600, e.session = s, e.seq = 1;
  const Bytes recorded = daemon::test::encode_signed(e, c.alice);
  ASSERT_TRUE(c.send_bytes(c.h.cfg.lcm.control_channel, recorded, 600)->accepted);
  c.cycles(20);
  ASSERT_TRUE(c.control(&c.alice, C::CMD_DISABLE, s, 2).accepted);
  ASSERT_TRUE(c.control(&c.alice, C::CMD_RELEASE, s, 3).accepted);
  c.cycles(5);
  const std::int64_t t = c.acquire(c.alice, 78);
  ASSERT_NE(t, 0);
  ASSERT_NE(t, s);
  c.acks.clear();
  const ack_t* a = c.send_bytes(c.h.cfg.lcm.control_channel, recorded, 600);
  ASSERT_NE(a, nullptr);
  EXPECT_EQ(a->reason, ack_t::REASON_NOT_HOLDER) << a->message;
  c.cycles(20);
  EXPECT_EQ(c.h.mode(), daemon::Mode::disabled);
}

TEST(Replay, AReplayedOrStaleAcquireTakesNothing) {
  Cell c;
  C q{};
  q.command = C::CMD_ACQUIRE, q.id = 700, q.session = 5, q.seq = daemon::test::acquire_seq();
  const Bytes recorded = daemon::test::encode_signed(q, c.alice);
  const ack_t* a = c.send_bytes(c.h.cfg.lcm.control_channel, recorded, 700);
  ASSERT_TRUE(a && a->accepted);
  const std::int64_t s = a->session;
  ASSERT_TRUE(c.control(&c.alice, C::CMD_RELEASE, s, 1).accepted);
  // Played back once the machine is free: refused, nobody holds it.
  c.acks.clear();
  a = c.send_bytes(c.h.cfg.lcm.control_channel, recorded, 700);
  ASSERT_NE(a, nullptr);
  EXPECT_FALSE(a->accepted);
  EXPECT_EQ(a->reason, ack_t::REASON_STALE_SEQ) << a->message;
  EXPECT_EQ(c.server->session(), 0);
  // An acquire whose clock is a minute off cpmd's: refused either way.
  for (double off : {-60.0, 60.0}) {
    const ack_t r = c.control(&c.alice, C::CMD_ACQUIRE, 6,
                              static_cast<std::int64_t>((daemon::test::kWallClock + off) * 1e6));
    EXPECT_EQ(r.reason, ack_t::REASON_STALE_SEQ) << off << ": " << r.message;
  }
  EXPECT_EQ(c.server->session(), 0);
  EXPECT_NE(c.acquire(c.alice), 0);  // a fresh one works
}

// A recorded acquire played to a restarted cpmd, well within the acquire
// window and before the operator acquired again (the new start knows no
// last acquire of hers): the acquire was signed for the old start's boot id,
// so the new start refuses it as it refuses a wrong key. The same bytes to a
// start with the old boot id are taken: only the boot id differs.
TEST(Replay, ARecordedAcquireIsRefusedAfterARestart) {
  C q{};
  q.command = C::CMD_ACQUIRE, q.id = 710, q.session = 5, q.seq = daemon::test::acquire_seq();
  Bytes recorded;
  {
    Cell before;
    recorded = daemon::test::encode_signed(q, before.alice);
    const ack_t* a = before.send_bytes(before.h.cfg.lcm.control_channel, recorded, 710);
    ASSERT_TRUE(a && a->accepted);
  }
  Cell after;  // the restart: a new boot id
  after.server->set_boot_id(daemon::test::kTestBoot + 1);
  const ack_t* a = after.send_bytes(after.h.cfg.lcm.control_channel, recorded, 710);
  ASSERT_NE(a, nullptr);
  EXPECT_FALSE(a->accepted);
  EXPECT_EQ(a->reason, ack_t::REASON_NOT_AUTHORIZED) << a->message;
  EXPECT_EQ(after.server->session(), 0);
  EXPECT_EQ(after.server->security().refused_bad_mac, 1);
  // Alice, signing for the new boot id, acquires at once.
  Credentials alice = after.alice;
  alice.boot = after.server->boot_id();
  EXPECT_NE(after.acquire(alice), 0);
  // Control: a start with the recording's boot id takes the same bytes.
  Cell same_boot;
  const ack_t* b = same_boot.send_bytes(same_boot.h.cfg.lcm.control_channel, recorded, 710);
  ASSERT_TRUE(b && b->accepted) << (b ? b->message : "no answer");
}

TEST(StaleSeq, AnOlderOrEqualSeqIsRefused) {
  Cell c;
  const std::int64_t s = c.acquire(c.alice);
  EXPECT_TRUE(c.control(&c.alice, C::CMD_PING, s, 10).accepted);
  for (std::int64_t seq : {10L, 9L, 1L, 0L, -1L, std::numeric_limits<std::int64_t>::min()}) {
    const ack_t a = c.control(&c.alice, C::CMD_ENABLE, s, seq);
    EXPECT_EQ(a.reason, ack_t::REASON_STALE_SEQ) << seq;
  }
  c.cycles(20);
  EXPECT_EQ(c.h.mode(), daemon::Mode::disabled);
  EXPECT_TRUE(c.control(&c.alice, C::CMD_ENABLE, s, 11).accepted);
}

TEST(Roles, AnOperatorMovesButCannotLoadModelsOrChangeGains) {
  Cell c;
  const std::int64_t s = c.acquire(c.bob);
  ASSERT_NE(s, 0);
  const Snapshot before(c);
  const ack_t g = c.control(&c.bob, C::CMD_SELECT_CONTROLLER, s, 1, [](C& m) {
    m.law = 0;
    for (int i = 0; i < 3; ++i) m.kp[i] = 5e4, m.kd[i] = 500;
  });
  EXPECT_EQ(g.reason, ack_t::REASON_NOT_AUTHORIZED);
  EXPECT_NE(g.message.find("engineer"), std::string::npos) << g.message;  // bob proved who he is: he is told why
  const ack_t l = c.control(&c.bob, C::CMD_LOAD_MODEL, s, 2, [](C& m) { m.model_path = "builtin:elkady"; });
  EXPECT_EQ(l.reason, ack_t::REASON_NOT_AUTHORIZED);
  c.cycles(10);
  before.expect_same(c, "bob's gains and model");
  EXPECT_EQ(c.server->security().refused_role, 2);
  // Motion is his to command.
  EXPECT_TRUE(c.control(&c.bob, C::CMD_ENABLE, s, 3).accepted);
  c.cycles(20);
  EXPECT_TRUE(c.trajectory(&c.bob, move_to(kP1 + Vec3(-0.01, 0, 0)), s, 4).accepted);
  // Alice, an engineer, may change the gains.
  c.cycles(1500);
  EXPECT_TRUE(c.control(&c.bob, C::CMD_RELEASE, s, 5).accepted);
  const std::int64_t t = c.acquire(c.alice);
  const ack_t ga = c.control(&c.alice, C::CMD_SELECT_CONTROLLER, t, 1, [](C& m) { m.law = 3, m.use_table3_gains = true; });
  EXPECT_TRUE(ga.accepted) << ga.message;
}

TEST(Roles, AnObserversKeyCommandsNothing) {
  Cell c;
  std::int64_t seq = 0;
  const Snapshot before(c);
  for (auto& [name, edit] : control_attacks()) {
    const ack_t a = c.control(&c.olga, 0, 0, ++seq, edit);
    EXPECT_EQ(a.reason, ack_t::REASON_NOT_AUTHORIZED) << name;
  }
  for (auto& [name, m] : trajectory_attacks())
    EXPECT_EQ(c.trajectory(&c.olga, m, 0, ++seq).reason, ack_t::REASON_NOT_AUTHORIZED) << name;
  c.cycles(20);
  before.expect_same(c, "olga");
}

TEST(Stop, AStrangerStopsAMovingMachine) {
  Cell c;
  const std::int64_t s = c.alice_holding();
  ASSERT_TRUE(c.trajectory(&c.alice, move_to(kP1 + Vec3(-0.1, 0, 0), 0.1), s, 2).accepted);
  c.cycles(300);
  ASSERT_EQ(c.h.mode(), daemon::Mode::moving);
  // Unsigned, no session: what anyone on the bus can send.
  const ack_t st = c.control(nullptr, C::CMD_STOP, 0, 0);
  EXPECT_TRUE(st.accepted) << st.message;
  c.cycles(1000);
  EXPECT_EQ(c.h.mode(), daemon::Mode::holding);
  EXPECT_GT((c.h.position() - (kP1 + Vec3(-0.1, 0, 0))).norm(), 0.01) << "it did not stop short of the target";
  EXPECT_EQ(c.server->session(), s) << "a stop took the session";
  EXPECT_EQ(c.server->security().stops_from_anyone, 1);
  // With a wrong key too: a stop is a stop.
  ASSERT_TRUE(c.trajectory(&c.alice, move_to(kP1, 0.1), s, 3).accepted);
  c.cycles(300);
  Credentials mallory = c.alice;
  mallory.key = daemon::generate_key();
  EXPECT_TRUE(c.control(&mallory, C::CMD_STOP, 0, 0).accepted);
  c.cycles(1000);
  EXPECT_EQ(c.h.mode(), daemon::Mode::holding);
}

// The stop's own path (Server::start_stop_listener rings the loop): with
// the command queue full ahead of it (16 commands, 4 taken a cycle), the
// loop still brakes in the first cycle after the stop arrives; through the
// queue alone it would wait its turn.
TEST(Stop, TheStopPathBrakesBeforeAFullCommandQueue) {
  Cell c;
  const std::int64_t s = c.alice_holding();
  ASSERT_TRUE(c.trajectory(&c.alice, move_to(kP1 + Vec3(-0.1, 0, 0), 0.1), s, 2).accepted);
  c.cycles(300);
  ASSERT_EQ(c.h.mode(), daemon::Mode::moving);
  daemon::Command ping;
  ping.kind = daemon::CommandKind::ping;
  int queued = 0;
  while (c.h.loop->commands().push(ping)) ++queued;
  ASSERT_EQ(queued, 16);
  c.h.loop->request_stop();
  c.h.loop->cycle(c.h.k++, 0);
  EXPECT_EQ(c.h.mode(), daemon::Mode::stopping) << "the stop waited behind the queue";
  // Compare: through the queue alone, behind 16 commands.
  c.cycles(2000);
  ASSERT_EQ(c.h.mode(), daemon::Mode::holding);
  ASSERT_TRUE(c.trajectory(&c.alice, move_to(kP1, 0.1), s, 3).accepted);
  c.cycles(300);
  ASSERT_EQ(c.h.mode(), daemon::Mode::moving);
  queued = 0;
  while (c.h.loop->commands().size() + 1 < c.h.loop->commands().capacity() && c.h.loop->commands().push(ping)) ++queued;
  daemon::Command stop;
  stop.kind = daemon::CommandKind::stop;
  ASSERT_TRUE(c.h.loop->commands().push(stop));
  int cycles = 0;
  while (c.h.mode() == daemon::Mode::moving && cycles < 100) {
    c.h.loop->cycle(c.h.k++, 0);
    ++cycles;
  }
  std::printf("  the stop path: braking in 1 cycle; through the queue behind %d commands: %d cycles\n", queued, cycles);
  EXPECT_GT(cycles, 1);
}

TEST(AcquireFlood, StrangersGetNoSessionAndFewAnswers) {
  Cell c;
  const double rate = c.h.cfg.security.refusal_acks_per_second;
  const auto t0 = c.now;
  int sent = 0;
  // 10 000 acquires in one instant, then 100 per 10 ms for 1 s: unsigned,
  // wrong-keyed and from unknown operators, each with a new nonce.
  Credentials mallory = c.alice;
  mallory.key = daemon::generate_key();
  const Credentials eve = daemon::test::credentials("eve");
  auto burst = [&](int n) {
    for (int i = 0; i < n; ++i, ++sent) {
      C m{};
      m.command = C::CMD_ACQUIRE, m.id = 100000 + sent, m.session = sent + 1, m.seq = daemon::test::acquire_seq();
      const Credentials* who = i % 3 == 0 ? nullptr : i % 3 == 1 ? &mallory : &eve;
      c.publish(c.h.cfg.lcm.control_channel, c.sign(m, who));
    }
  };
  burst(10000);
  for (int k = 0; k < 100; ++k) {
    c.now += 0.01;
    burst(100);
    c.cycles(1);
  }
  const double elapsed = c.now - t0;
  int answered = 0;
  for (const auto& a : c.acks) {
    EXPECT_FALSE(a.accepted);
    answered += a.id >= 100000;
  }
  const auto sec = c.server->security();
  std::printf("acquire flood: %d acquires in %.2f s, %d answered, %lld counted unanswered\n", sent, elapsed, answered,
              static_cast<long long>(sec.refusals_unanswered));
  EXPECT_EQ(c.server->session(), 0) << "a stranger got the session";
  EXPECT_LE(answered, static_cast<int>(rate * (1.0 + elapsed)) + 1) << "the refusals were not rate-limited";
  EXPECT_GT(answered, 0) << "a refusal should still be answered at the bounded rate";
  EXPECT_EQ(sec.refused_no_operator + sec.refused_bad_mac, sent);
  EXPECT_EQ(sec.refusals_unanswered, sent - answered);
  // An operator gets in at once.
  EXPECT_NE(c.acquire(c.alice), 0);
}

// Bytes that are no command on every channel: dropped and counted, never
// answered, never an exception, and the daemon goes on.
TEST(Malformed, TruncatedOversizedAndGarbledPacketsOnEveryChannel) {
  Cell c;
  const std::int64_t s = c.alice_holding();
  C ping{};
  ping.command = C::CMD_PING, ping.id = 1, ping.session = s, ping.seq = 2;
  ping.model_path = "builtin:elkady";
  const Bytes good_c = daemon::test::encode_signed(ping, c.alice);
  trajectory_command_t mv = move_to(kP1 + Vec3(-0.01, 0, 0));
  mv.id = 2, mv.session = s, mv.seq = 3;
  const Bytes good_t = daemon::test::encode_signed(mv, c.alice);
  std::vector<Bytes> bad;
  for (const Bytes* g : {&good_c, &good_t}) {
    for (std::size_t n = 0; n < g->size(); n += (g->size() > 1000 ? 37 : 1)) bad.emplace_back(g->begin(), g->begin() + n);
    Bytes longer = *g;
    longer.push_back(0);
    bad.push_back(longer);  // one byte more: the MAC is no longer the last 32 bytes
    longer.resize(g->size() + 65536, 0xA5);
    bad.push_back(longer);
    Bytes hash = *g;
    hash[2] ^= 0x10;
    bad.push_back(hash);
  }
  // model_path's length prefix: 0, -1, INT32_MIN, huge, one off either way.
  const std::size_t at = cpm::daemon::kControlModelPathOffset;
  const std::int32_t len = (good_c[at] << 24) | (good_c[at + 1] << 16) | (good_c[at + 2] << 8) | good_c[at + 3];
  for (std::uint32_t v : {0u, 0xFFFFFFFFu, 0x80000000u, 0x7FFFFFFFu, static_cast<std::uint32_t>(len - 1),
                          static_cast<std::uint32_t>(len + 1)}) {
    Bytes b = good_c;
    for (int i = 0; i < 4; ++i) b[at + i] = static_cast<std::uint8_t>(v >> (24 - 8 * i));
    bad.push_back(b);
  }
  bad.push_back(Bytes(1 << 20, 0));  // 1 MiB of zeros
  Bytes noise(1 << 20);
  std::uint64_t x = 0x9E3779B97F4A7C15ull;
  for (auto& b : noise) b = static_cast<std::uint8_t>((x = x * 6364136223846793005ull + 1442695040888963407ull) >> 56);
  bad.push_back(noise);

  const std::int64_t undecodable = c.server->undecodable();
  const std::size_t acks = c.acks.size();
  const Snapshot before(c);
  int sent = 0;
  for (const auto& b : bad) {
    c.publish(c.h.cfg.lcm.control_channel, b);
    c.publish(c.h.cfg.lcm.trajectory_channel, b);
    sent += 2;
  }
  // A well-formed message on the other type's channel.
  c.publish(c.h.cfg.lcm.control_channel, good_t);
  c.publish(c.h.cfg.lcm.trajectory_channel, good_c);
  sent += 2;
  // The channels cpmd only publishes on: nothing of it reaches the daemon.
  for (const std::string& ch : {c.h.cfg.lcm.state_channel, c.h.cfg.lcm.stats_channel, c.h.cfg.lcm.ack_channel,
                                c.h.cfg.lcm.security_channel})
    for (const auto& b : {bad.front(), bad.back(), good_c, good_t}) c.publish(ch, b);
  c.cycles(20);
  EXPECT_EQ(c.server->undecodable() - undecodable, sent);
  EXPECT_EQ(c.acks.size(), acks) << "undecodable bytes were answered";
  before.expect_same(c, "malformed packets");
  std::printf("malformed: %d packets on the command channels dropped and counted (up to %zu bytes)\n", sent,
              bad.back().size());
  // The daemon goes on: the same seq is still unused.
  EXPECT_TRUE(c.send_bytes(c.h.cfg.lcm.control_channel, good_c, 1)->accepted);
}

const double kBadNumbers[] = {std::numeric_limits<double>::quiet_NaN(), INFINITY, -INFINITY,
                              std::numeric_limits<double>::denorm_min(), -2.2e-310};

TEST(Numbers, NonFiniteAndSubnormalInEveryTrajectoryField) {
  Cell c;
  const std::int64_t s = c.alice_holding();
  std::int64_t seq = 1;
  // The bases are accepted as they are (so each refusal below is the number's).
  for (auto base : {move_to(kP1 + Vec3(-0.01, 0, 0)), stream_from(kP1 + Vec3(-0.01, 0, 0))}) {
    const ack_t ok = c.trajectory(&c.alice, base, s, ++seq);
    ASSERT_TRUE(ok.accepted) << ok.message;
    c.cycles(1500);
  }
  const Vec3 at = c.h.position();
  struct Field {
    std::string name;
    std::function<double&(trajectory_command_t&)> ref;
  };
  std::vector<Field> fields;
  auto scalar = [&](const char* n, double trajectory_command_t::*p) {
    fields.push_back({n, [p](trajectory_command_t& m) -> double& { return m.*p; }});
  };
  scalar("max_velocity", &trajectory_command_t::max_velocity);
  scalar("max_acceleration", &trajectory_command_t::max_acceleration);
  scalar("max_jerk", &trajectory_command_t::max_jerk);
  scalar("radius", &trajectory_command_t::radius);
  scalar("angular_speed", &trajectory_command_t::angular_speed);
  scalar("start_angle", &trajectory_command_t::start_angle);
  scalar("cruise_time", &trajectory_command_t::cruise_time);
  scalar("ramp_time", &trajectory_command_t::ramp_time);
  for (int i = 0; i < 3; ++i) {
    fields.push_back({"target[" + std::to_string(i) + "]", [i](trajectory_command_t& m) -> double& { return m.target[i]; }});
    fields.push_back({"centre[" + std::to_string(i) + "]", [i](trajectory_command_t& m) -> double& { return m.centre[i]; }});
  }
  for (int k : {0, 50, 99}) {
    fields.push_back({"time[" + std::to_string(k) + "]", [k](trajectory_command_t& m) -> double& { return m.time[k]; }});
    for (int j = 0; j < 3; ++j) {
      const std::string ij = "[" + std::to_string(k) + "][" + std::to_string(j) + "]";
      fields.push_back({"position" + ij, [k, j](trajectory_command_t& m) -> double& { return m.position[k][j]; }});
      fields.push_back({"velocity" + ij, [k, j](trajectory_command_t& m) -> double& { return m.velocity[k][j]; }});
    }
  }
  int refused = 0;
  for (const auto& f : fields)
    for (double v : kBadNumbers)
      for (auto base : {move_to(at + Vec3(-0.01, 0, 0)), stream_from(at)}) {
        f.ref(base) = v;
        const ack_t a = c.trajectory(&c.alice, base, s, ++seq);
        EXPECT_FALSE(a.accepted) << f.name << " = " << v;
        EXPECT_EQ(a.reason, ack_t::REASON_INVALID) << f.name << " = " << v << ": " << a.message;
        EXPECT_NE(a.message.find(f.name), std::string::npos) << a.message;
        refused += !a.accepted;
      }
  // Huge but finite: refused by the limits, never sampled for ever.
  for (auto [name, edit] : std::vector<std::pair<const char*, std::function<void(trajectory_command_t&)>>>{
           {"target 1e308", [](trajectory_command_t& m) { m.target[0] = 1e308; }},
           {"max_velocity 1e308", [](trajectory_command_t& m) { m.max_velocity = 1e308; }},
           {"max_jerk DBL_MIN", [](trajectory_command_t& m) { m.max_jerk = DBL_MIN; }}}) {
    trajectory_command_t m = move_to(at + Vec3(-0.01, 0, 0));
    edit(m);
    const ack_t a = c.trajectory(&c.alice, m, s, ++seq);
    EXPECT_FALSE(a.accepted) << name;
    EXPECT_NE(a.reason, ack_t::REASON_NONE) << name;
  }
  trajectory_command_t huge = paper_circle();
  huge.centre[0] = at.x() - huge.radius;
  huge.centre[1] = at.y();
  huge.cruise_time = 1e300;
  EXPECT_EQ(c.trajectory(&c.alice, huge, s, ++seq).reason, ack_t::REASON_LIMIT);
  c.cycles(100);
  EXPECT_EQ(c.h.state().queue_depth, 0);
  EXPECT_EQ(c.h.state().faults, 0);
  EXPECT_LT((c.h.position() - at).norm(), 1e-6);
  std::printf("numbers: %d trajectories with NaN, inf or a subnormal refused (%zu fields x 5 values x 2 kinds)\n",
              refused, fields.size());
}

TEST(Numbers, NonFiniteAndSubnormalInEveryControlField) {
  Cell c;
  const std::int64_t s = c.acquire(c.alice);
  std::int64_t seq = 0;
  const std::int8_t law = c.h.state().controller;
  for (int i = 0; i < 3; ++i)
    for (double v : kBadNumbers)
      for (bool kp : {true, false})
        for (std::int8_t cmd : {C::CMD_SELECT_CONTROLLER, C::CMD_PING}) {
          const ack_t a = c.control(&c.alice, cmd, s, ++seq, [&](C& m) {
            m.law = 0;
            for (int j = 0; j < 3; ++j) m.kp[j] = 5e4, m.kd[j] = 500;
            (kp ? m.kp : m.kd)[i] = v;
          });
          EXPECT_EQ(a.reason, ack_t::REASON_INVALID) << (kp ? "kp[" : "kd[") << i << "] = " << v;
        }
  c.cycles(5);
  EXPECT_EQ(c.h.state().controller, law);
}

// 10^5 setpoints cannot come in one message (count <= 100); as 1011 chunks
// they play in order, the queue never holds more than its 32 segments, every
// chunk is answered once, and the flow control is the answers (busy, queue full).
TEST(Trajectories, TenToTheFifthSetpointsPlayInBoundedChunks) {
  Cell c;
  const std::int64_t s = c.alice_holding();
  std::int64_t seq = 1;
  for (int count : {32767, -32768, -1, 0, 1, 101}) {
    trajectory_command_t m = stream_from(kP1);
    m.count = static_cast<std::int16_t>(count);
    const ack_t a = c.trajectory(&c.alice, m, s, ++seq);
    EXPECT_EQ(a.reason, ack_t::REASON_INVALID) << "count " << count << ": " << a.message;
  }
  constexpr int N = 100000;
  const double dt = 1e-3, A = 0.01, w = 2 * M_PI / 10.0;  // x = x1 - A (1 - cos wt), at rest at 0 and 100 s
  auto point = [&](int i, trajectory_command_t& m, int k) {
    const double t = i * dt;
    m.position[k][0] = kP1.x() - A * (1 - std::cos(w * t));
    m.position[k][1] = kP1.y();
    m.position[k][2] = kP1.z();
    m.velocity[k][0] = -A * w * std::sin(w * t);
  };
  int chunks = 0, accepted = 0, busy = 0, full = 0, max_depth = 0;
  for (int first = 0; first < N - 1; first += 99) {
    trajectory_command_t m{};
    m.kind = trajectory_command_t::KIND_STREAM;
    const int n = std::min(100, N - first);
    m.count = static_cast<std::int16_t>(n);
    for (int k = 0; k < n; ++k) {
      m.time[k] = k * dt;
      point(first + k, m, k);
    }
    m.velocity[n - 1][0] = first + n == N ? 0.0 : m.velocity[n - 1][0];
    ++chunks;
    for (;;) {
      const ack_t a = c.trajectory(&c.alice, m, s, ++seq);
      max_depth = std::max<int>(max_depth, c.h.state().queue_depth);
      if (a.accepted) {
        ++accepted;
        break;
      }
      ASSERT_TRUE(a.reason == ack_t::REASON_QUEUE_FULL || a.reason == ack_t::REASON_BUSY)
          << "chunk " << chunks << ": " << a.message;
      (a.reason == ack_t::REASON_BUSY ? busy : full)++;
      c.cycles(20);  // the queue drains as the machine moves
    }
  }
  for (int i = 0; i < 120000 && c.h.mode() == daemon::Mode::moving; ++i) c.cycles(1);
  std::printf("10^5 setpoints: %d chunks accepted, %d refused as the queue was full, %d busy; deepest queue %d\n",
              accepted, full, busy, max_depth);
  EXPECT_EQ(accepted, chunks);
  EXPECT_LE(max_depth, daemon::ControlLoop::kQueueCapacity);
  EXPECT_GT(full, 0) << "the queue never filled: the bound was not reached";
  EXPECT_EQ(c.h.mode(), daemon::Mode::holding);
  EXPECT_EQ(c.h.state().faults, 0) << daemon::fault_bit_name(static_cast<std::uint32_t>(c.h.state().first_fault));
  EXPECT_LT((c.h.position() - kP1).norm(), 1e-5);
}

TEST(Trajectories, TimeGoingBackwardsIsRefused) {
  Cell c;
  const std::int64_t s = c.alice_holding();
  std::int64_t seq = 1;
  const Snapshot before(c);
  std::vector<std::pair<std::string, trajectory_command_t>> cases;
  trajectory_command_t m = stream_from(kP1);
  std::swap(m.time[49], m.time[50]);
  cases.push_back({"two points swapped in time", m});
  m = stream_from(kP1);
  m.time[99] = m.time[98];
  cases.push_back({"two points at the same time", m});
  m = stream_from(kP1);
  for (int i = 0; i < 100; ++i) m.time[i] = -m.time[i];
  cases.push_back({"all of time backwards", m});
  m = stream_from(kP1);
  for (int i = 0; i < 100; ++i) m.time[i] += 0.5;
  cases.push_back({"not starting at 0", m});
  for (const auto& [what, cmd] : cases) {
    const ack_t a = c.trajectory(&c.alice, cmd, s, ++seq);
    EXPECT_EQ(a.reason, ack_t::REASON_INVALID) << what << ": " << a.message;
  }
  c.cycles(50);
  before.expect_same(c, "time backwards");
}

TEST(Trajectories, PointsOutsideTheWorkspaceAreRefused) {
  Cell c;
  const std::int64_t s = c.alice_holding();
  std::int64_t seq = 1;
  const Snapshot before(c);
  const auto& L = c.h.cfg.limits;
  for (int axis = 0; axis < 3; ++axis)
    for (bool high : {false, true}) {
      Vec3 p = kP1;
      p[axis] = high ? L.workspace_max[axis] + 0.01 : L.workspace_min[axis] - 0.01;
      const ack_t a = c.trajectory(&c.alice, move_to(p), s, ++seq);
      EXPECT_EQ(a.reason, ack_t::REASON_WORKSPACE) << "xyz"[axis] << (high ? " high" : " low") << ": " << a.message;
    }
  trajectory_command_t st = stream_from(kP1, 100, 2.0, -0.5);  // half a metre along -x: out at the far end
  EXPECT_EQ(c.trajectory(&c.alice, st, s, ++seq).reason, ack_t::REASON_WORKSPACE);
  trajectory_command_t big = paper_circle();
  big.radius = 0.3, big.angular_speed = 0.1, big.cruise_time = 70.0;  // a whole turn: x reaches 0
  big.centre[0] = kP1.x() - big.radius;
  EXPECT_EQ(c.trajectory(&c.alice, big, s, ++seq).reason, ack_t::REASON_WORKSPACE);
  c.cycles(50);
  before.expect_same(c, "outside the workspace");
}

}  // namespace
}  // namespace cpm::redteam
