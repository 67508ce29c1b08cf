// SPDX-License-Identifier: Apache-2.0
// Signed state (docs/security.md, "Signed state"): what an attacker on the
// bus can do to a client's view of the machine with no key, and what the
// client's check (cpm::daemon::Verifier, used by Client) makes of it. cpmd
// lists every message's digest in a seal_t and signs the seal; a message is
// trusted once a verified seal lists it.
#include <gtest/gtest.h>
#include <unistd.h>

#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <map>
#include <mutex>

#include "cpm/daemon/client.hpp"
#include <cpm_msgs/ack_t.hpp>
#include "cpm/daemon/signing.hpp"
#include "redteam/cell.hpp"

namespace cpm::redteam {
namespace {

using daemon::Stream;
using daemon::Trust;
using daemon::Verifier;
using cpm_msgs::seal_t;
using cpm_msgs::state_t;

struct DaemonKey {
  std::string path = testing::TempDir() + "cpmd-sign-" + std::to_string(::getpid()) + ".key";
  daemon::Key seed = daemon::generate_key();
  DaemonKey() {
    std::filesystem::remove(path);
    daemon::write_key_file(path, seed);
  }
  ~DaemonKey() { std::filesystem::remove(path); }
  [[nodiscard]] daemon::PublicKey pub() const { return daemon::public_key_of(seed); }
};

// One message as it went over the bus: its kind (nullopt: a seal) and bytes.
struct Heard {
  std::optional<Stream> stream;
  Bytes bytes;
};

// Everything a signing cpmd publishes, in the order it went out (memq:// keeps it).
struct SignedCell : Cell {
  std::vector<Heard> heard;
  std::map<std::string, std::optional<Stream>> kinds;
  explicit SignedCell(const std::string& key) : Cell(key) {
    const auto& l = h.cfg.lcm;
    kinds = {{l.state_channel, Stream::state},       {l.ack_channel, Stream::ack},
             {l.drives_channel, Stream::drives},     {l.stats_channel, Stream::stats},
             {l.params_channel, Stream::params},     {l.security_channel, Stream::security},
             {l.seal_channel, std::nullopt}};
    for (const auto& k : kinds) server->bus().subscribe(k.first, &SignedCell::on_raw, this);
  }
  void on_raw(const lcm::ReceiveBuffer* rb, const std::string& channel) {
    const auto* p = static_cast<const std::uint8_t*>(rb->data);
    heard.push_back({kinds.at(channel), Bytes(p, p + rb->data_size)});
  }
  // The states heard so far, decoded, with their index in `heard`.
  [[nodiscard]] std::vector<std::pair<std::size_t, state_t>> states() const {
    std::vector<std::pair<std::size_t, state_t>> out;
    for (std::size_t i = 0; i < heard.size(); ++i)
      if (heard[i].stream == Stream::state) {
        state_t s;
        s.decode(heard[i].bytes.data(), 0, static_cast<int>(heard[i].bytes.size()));
        out.emplace_back(i, s);
      }
    return out;
  }
};

// A client's verifier fed messages and seals; what it released, by ticket.
struct Reader {
  Verifier v;
  std::vector<std::uint64_t> released;       // tickets, in the order released
  std::vector<Verifier::Verdict> refused;    // by a seal's decision
  std::vector<Trust> seal_verdicts;
  std::uint64_t ticket = 0;
  explicit Reader(const daemon::PublicKey& pk) : v(pk) {}
  // Returns the ticket the message got (its verdict at once, if any, in `now`).
  std::uint64_t message(Stream s, const Bytes& b, Trust* now = nullptr) {
    const Trust t = v.offer(s, b.data(), b.size(), ++ticket);
    if (t == Trust::ok) released.push_back(ticket);
    if (now) *now = t;
    return ticket;
  }
  Trust seal(const Bytes& b) {
    std::vector<Verifier::Verdict> d;
    const Trust t = v.seal(b.data(), b.size(), d);
    seal_verdicts.push_back(t);
    for (const auto& x : d) (x.trust == Trust::ok ? released.push_back(x.ticket) : refused.push_back(x));
    return t;
  }
  void feed(const Heard& h) { h.stream ? (void)message(*h.stream, h.bytes) : (void)seal(h.bytes); }
  [[nodiscard]] bool was_released(std::uint64_t t) const {
    return std::find(released.begin(), released.end(), t) != released.end();
  }
  [[nodiscard]] Trust verdict_of(std::uint64_t t) const {
    if (was_released(t)) return Trust::ok;
    for (const auto& x : refused)
      if (x.ticket == t) return x.trust;
    return Trust::pending;
  }
};

Bytes with_mode(const state_t& s, std::int8_t mode) {
  state_t f = s;
  f.mode = mode;
  return encode(f);
}

// What cpmd publishes verifies, every kind, with the public half only; each
// is released once its seal verifies, and not before.
TEST(SignedState, EveryMessageCpmdPublishesIsSealedAndVerifies) {
  DaemonKey key;
  SignedCell cell(key.path);
  cell.alice_holding();
  cell.cycles(1100);  // drives at 10 Hz, statistics at 1 Hz
  cell.server->seal();
  cell.pump();
  Reader r(key.pub());
  std::array<int, daemon::kStreams> sent{};
  int seals = 0;
  std::size_t max_held = 0;
  for (const auto& h : cell.heard) {
    if (h.stream) {
      ++sent[static_cast<int>(*h.stream)];
      Trust now{};
      r.message(*h.stream, h.bytes, &now);
      EXPECT_EQ(now, Trust::pending) << "trusted before a seal listed it";
    } else {
      ++seals;
      EXPECT_EQ(r.seal(h.bytes), Trust::ok);
    }
    max_held = std::max(max_held, r.v.waiting());
  }
  EXPECT_EQ(r.released.size(), r.ticket) << "every message released";
  EXPECT_EQ(r.v.refused_total(), 0);
  EXPECT_EQ(r.v.waiting(), 0u);
  for (int s = 0; s < daemon::kStreams; ++s) EXPECT_GT(sent[s], 0) << "stream " << s << " never published";
  // A seal lists at most 32 messages: never more than 32 wait at a time.
  EXPECT_LE(max_held, daemon::kSealEvery);
  EXPECT_GE(seals, static_cast<int>(r.ticket / daemon::kSealEvery));
  std::printf("%llu messages (states %d, acks %d, drives %d, stats %d, params %d, security %d) in %d seals\n",
              static_cast<unsigned long long>(r.ticket), sent[0], sent[1], sent[2], sent[3], sent[4], sent[5], seals);
}

// Released in the order cpmd published them, however they arrive within a
// window; a genuine message that arrives after its seal is taken at once.
// The sealing thread (docs/security.md, "The sealing thread"): seals are
// signed off the publishing thread and handed over without a lock. 900
// messages (under a seal's 1 024 digests), every third an ack, each due for
// its seal at once, published back to back: the sealing thread falls behind,
// its 8 slots fill, and the publisher lists on without waiting. Every message
// is listed by exactly one verified seal, the seals follow each other without
// a gap, a client releases all 900 in the order published, and none was
// signed on the publishing thread.
TEST(SignedState, TheSealingThreadSealsEveryMessageInOrderWithoutALock) {
  const daemon::Key seed = daemon::generate_key();
  daemon::Signer signer(seed, 0x5EA1ED);
  std::mutex mu;
  std::vector<Bytes> seals;
  signer.start_thread([&](const std::uint8_t* d, std::size_t n) {
    const std::lock_guard<std::mutex> lock(mu);
    seals.emplace_back(d, d + n);
  });
  std::vector<std::pair<Stream, Bytes>> published;
  state_t st{};
  cpm_msgs::ack_t ack{};
  int acks_due_at_once = 0;
  for (int i = 0; i < 900; ++i) {
    const double now = 1e-5 * i;
    if (i % 3 == 2) {
      ++ack.id;
      published.emplace_back(Stream::ack, signer.add(ack, now, /*ack=*/true));
      acks_due_at_once += signer.due(now) ? 1 : 0;
    } else {
      ++st.cycle;
      published.emplace_back(Stream::state, signer.add(st, now));
    }
    if (signer.due(now)) {
      EXPECT_TRUE(signer.seal(i).empty()) << "signed on the publishing thread";
    }
  }
  const std::uint64_t waiting = signer.seals_waiting();
  (void)signer.seal(900);
  const std::size_t listed_after = signer.unsealed();
  signer.stop_thread();
  // What the thread was too far behind to be handed: sealed here, published last.
  if (const Bytes rest = signer.seal(901); !rest.empty()) seals.push_back(rest);
  EXPECT_EQ(acks_due_at_once, 300);
  EXPECT_EQ(signer.sealed_here(), 0);
  EXPECT_EQ(signer.seals_waiting(), 0u);
  EXPECT_EQ(signer.unsealed(), 0u);
  Reader r(daemon::public_key_of(seed));
  std::int64_t next = 1;
  for (const Bytes& b : seals) {
    const auto s = daemon::decode_seal(b.data(), b.size());
    ASSERT_TRUE(s);
    ASSERT_EQ(s->first, next) << "a gap or an overlap between seals";
    const auto n = static_cast<std::int64_t>(s->digests.size() / sizeof(daemon::Digest));
    for (std::int64_t c = s->first; c < s->first + n; ++c)
      r.message(published[static_cast<std::size_t>(c - 1)].first, published[static_cast<std::size_t>(c - 1)].second);
    EXPECT_EQ(r.seal(b), Trust::ok);
    next += n;
  }
  EXPECT_EQ(next, 901);
  ASSERT_EQ(r.released.size(), 900u);
  for (std::size_t i = 0; i < r.released.size(); ++i) ASSERT_EQ(r.released[i], i + 1) << "released out of order";
  EXPECT_EQ(r.v.refused_total(), 0);
  std::printf("sealing thread: 900 messages (300 acks due at once) in %zu seals; at the end %llu seals waiting for "
              "it, %zu messages listed and not handed over\n",
              seals.size(), static_cast<unsigned long long>(waiting), listed_after);
}

TEST(SignedState, AWindowArrivingOutOfOrderIsReleasedInOrder) {
  DaemonKey key;
  SignedCell cell(key.path);
  cell.cycles(40);
  cell.server->seal();
  cell.pump();
  Reader r(key.pub());
  // The first window (32 states), backwards, then its seal.
  std::vector<const Heard*> window;
  std::size_t i = 0;
  for (; i < cell.heard.size() && cell.heard[i].stream; ++i) window.push_back(&cell.heard[i]);
  ASSERT_LT(i, cell.heard.size());
  ASSERT_GE(window.size(), 2u);
  std::vector<std::uint64_t> tickets;
  for (auto it = window.rbegin(); it != window.rend(); ++it) tickets.push_back(r.message(*(*it)->stream, (*it)->bytes));
  ASSERT_EQ(r.seal(cell.heard[i].bytes), Trust::ok);
  // Published order = the reverse of the arrival order.
  ASSERT_EQ(r.released.size(), window.size());
  EXPECT_TRUE(std::equal(r.released.begin(), r.released.end(), tickets.rbegin()));
  // The next window's seal first, then its messages: each taken on arrival.
  std::size_t j = i + 1;
  std::vector<const Heard*> next;
  for (; j < cell.heard.size() && cell.heard[j].stream; ++j) next.push_back(&cell.heard[j]);
  ASSERT_LT(j, cell.heard.size());
  ASSERT_EQ(r.seal(cell.heard[j].bytes), Trust::ok);
  for (const Heard* h : next) {
    Trust now{};
    r.message(*h->stream, h->bytes, &now);
    EXPECT_EQ(now, Trust::ok);
  }
  EXPECT_EQ(r.v.refused_total(), 0);
}

// The attack of issue 27: a forged "holding" state carrying the id of the
// move just sent, in every form an attacker without cpmd's key can make it,
// slipped into a signed window; and tampered, replayed and reordered
// genuine state.
TEST(SignedState, ForgedTamperedReplayedAndReorderedStateIsRefused) {
  DaemonKey key;
  SignedCell cell(key.path);
  const std::int64_t s = cell.alice_holding();
  const trajectory_command_t move = move_to(kP1 + Vec3(-0.1, 0, 0), 0.1);
  ASSERT_TRUE(cell.trajectory(&cell.alice, move, s, 2).accepted);
  cell.cycles(300);
  ASSERT_EQ(cell.h.mode(), daemon::Mode::moving);
  cell.heard.clear();
  cell.cycles(100);  // three windows and a bit
  cell.server->seal();
  cell.pump();
  const auto states = cell.states();
  ASSERT_GE(states.size(), 96u);
  const state_t real = states[5].second;
  ASSERT_EQ(real.mode, state_t::MODE_MOVING);

  // Forgeries: "holding" with the move's id as finished; the genuine one
  // with its position changed; one claiming the genuine counter (a fork of
  // the sequence), and one claiming the next counter.
  state_t holding = real;
  holding.mode = state_t::MODE_HOLDING;
  holding.last_segment_id = real.segment_id;
  holding.segment_id = -1;
  holding.last_segment_rmse = 1e-7;
  state_t moved = real;
  moved.position[0] += 1e-3;
  state_t next_counter = holding;
  next_counter.sign_counter = real.sign_counter + 1;
  const std::vector<Bytes> forgeries = {encode(holding), encode(moved), encode(next_counter),
                                        with_mode(real, state_t::MODE_DISABLED)};

  Reader r(key.pub());
  std::vector<std::uint64_t> forged_tickets, genuine_tickets;
  for (std::size_t i = 0; i < cell.heard.size(); ++i) {
    const Heard& h = cell.heard[i];
    if (h.stream == Stream::state) genuine_tickets.push_back(r.message(Stream::state, h.bytes));
    else r.feed(h);
    if (i == states[5].first)  // inside the first signed window, right after the genuine one
      for (const Bytes& f : forgeries) forged_tickets.push_back(r.message(Stream::state, f));
  }
  for (const auto t : genuine_tickets) EXPECT_EQ(r.verdict_of(t), Trust::ok) << "genuine ticket " << t;
  for (const auto t : forged_tickets) EXPECT_EQ(r.verdict_of(t), Trust::unsealed) << "forged ticket " << t;
  EXPECT_EQ(r.v.refused(Trust::unsealed), static_cast<std::int64_t>(forgeries.size()));

  // Replayed: a genuine state again, just after its seal (it is still
  // remembered) and after the others (reordered behind newer ones).
  Trust now{};
  r.message(Stream::state, cell.heard[states.back().first].bytes, &now);
  EXPECT_EQ(now, Trust::stale);
  r.message(Stream::state, cell.heard[states[states.size() - 3].first].bytes, &now);
  EXPECT_EQ(now, Trust::stale);
  // One older than the seals remembered: waits, and no seal ever lists it again.
  const Bytes first_state = cell.heard[states[0].first].bytes;
  cell.heard.clear();
  cell.cycles(5 * static_cast<int>(daemon::kSealEvery));
  for (const auto& h : cell.heard) r.feed(h);
  const std::uint64_t old = r.message(Stream::state, first_state);
  cell.heard.clear();
  cell.cycles(4 * static_cast<int>(daemon::kSealEvery));
  for (const auto& h : cell.heard) r.feed(h);
  EXPECT_EQ(r.verdict_of(old), Trust::unsealed);
  EXPECT_EQ(r.v.refused(Trust::stale), 2);
  for (Trust t : r.seal_verdicts) EXPECT_EQ(t, Trust::ok);
}

// A seal the attacker signs with a key of his own, listing his forgeries,
// and a genuine seal replayed: refused; what only they list is never taken.
TEST(SignedState, ForgedAndReplayedSealsAreRefused) {
  DaemonKey key;
  SignedCell cell(key.path);
  cell.cycles(5 * static_cast<int>(daemon::kSealEvery));  // more seals than a forgery waits for
  const auto states = cell.states();
  Reader r(key.pub());
  // The attacker's own cpmd: same boot id, his key, forged "moving" states.
  daemon::Signer attacker(daemon::generate_key(), states[0].second.boot_id);
  std::vector<std::uint64_t> forged;
  for (int i = 0; i < 3; ++i) {
    state_t f = states[static_cast<std::size_t>(i)].second;
    f.mode = state_t::MODE_MOVING;
    const Bytes b = attacker.add(f, 0.0);
    forged.push_back(r.message(Stream::state, b));
  }
  const Bytes forged_seal = attacker.seal(1);
  EXPECT_EQ(r.seal(forged_seal), Trust::bad_signature);
  // The same seal with the digests of the forgeries, the signature of a genuine seal.
  const Heard* genuine_seal = nullptr;
  for (const auto& h : cell.heard)
    if (!h.stream) {
      genuine_seal = &h;
      break;
    }
  ASSERT_NE(genuine_seal, nullptr);
  auto spliced = daemon::decode_seal(forged_seal.data(), forged_seal.size());
  const auto real_seal = daemon::decode_seal(genuine_seal->bytes.data(), genuine_seal->bytes.size());
  ASSERT_TRUE(spliced && real_seal);
  std::copy(std::begin(real_seal->signature), std::end(real_seal->signature), spliced->signature);
  EXPECT_EQ(r.seal(encode(*spliced)), Trust::bad_signature);
  // A genuine seal's digest changed by one bit.
  auto flipped = *real_seal;
  flipped.digests[5] ^= 1;
  EXPECT_EQ(r.seal(encode(flipped)), Trust::bad_signature);
  // Junk on the seal channel: noise, every truncation of a genuine seal, one
  // byte more, and lying digest counts (a negative one, one past the end).
  EXPECT_EQ(r.seal(Bytes(200, 0x5a)), Trust::unsigned_message);
  const Bytes& g = genuine_seal->bytes;
  for (std::size_t n = 0; n < g.size(); ++n) EXPECT_EQ(r.seal(Bytes(g.begin(), g.begin() + static_cast<std::ptrdiff_t>(n))), Trust::unsigned_message) << n;
  Bytes longer = g;
  longer.push_back(0);
  EXPECT_EQ(r.seal(longer), Trust::unsigned_message);
  for (const std::uint32_t n : {0xFFFFFFE0u, 0x80000000u, static_cast<std::uint32_t>(g.size())}) {
    Bytes lie = g;
    for (int k = 0; k < 4; ++k) lie[32 + static_cast<std::size_t>(k)] = static_cast<std::uint8_t>(n >> (24 - 8 * k));
    EXPECT_EQ(r.seal(lie), Trust::unsigned_message) << n;
  }
  // The genuine stream, then its first seal replayed.
  for (const auto& h : cell.heard) r.feed(h);
  EXPECT_EQ(r.seal(genuine_seal->bytes), Trust::stale);
  for (const auto t : forged) EXPECT_EQ(r.verdict_of(t), Trust::unsealed);
  EXPECT_EQ(r.v.refused(Trust::bad_signature), 3);
  EXPECT_EQ(r.v.refused(Trust::stale), 1);
  EXPECT_EQ(r.v.refused(Trust::unsigned_message), static_cast<std::int64_t>(g.size()) + 5);
  EXPECT_GE(r.released.size(), 64u);
}

// A seal lost on the way (or withheld by someone who can drop packets): the
// messages it covered are never trusted; those of the next seals are.
TEST(SignedState, ADroppedSealLeavesItsWindowUntrustedAndTheNextVerified) {
  DaemonKey key;
  SignedCell cell(key.path);
  cell.cycles(5 * static_cast<int>(daemon::kSealEvery));
  Reader r(key.pub());
  int seal_no = 0;
  std::vector<std::uint64_t> in_dropped, after;
  for (const auto& h : cell.heard) {
    if (!h.stream) {
      if (++seal_no == 2) continue;  // the second seal never arrives
      r.seal(h.bytes);
      continue;
    }
    const std::uint64_t t = r.message(*h.stream, h.bytes);
    (seal_no == 1 ? in_dropped : after).push_back(t);  // between the first and the second seal
  }
  ASSERT_GE(seal_no, 4);
  ASSERT_FALSE(in_dropped.empty());
  for (const auto t : in_dropped) EXPECT_EQ(r.verdict_of(t), Trust::unsealed);
  std::size_t ok = 0;
  for (const auto t : after) ok += r.verdict_of(t) == Trust::ok;
  EXPECT_GE(ok, 2 * daemon::kSealEvery);  // the third and fourth windows at least
  EXPECT_EQ(r.v.refused(Trust::unsealed), static_cast<std::int64_t>(in_dropped.size()));
}

// A restart (same key, another boot id) is refused and said, not trusted silently.
TEST(SignedState, StateOfAnotherBootIsRefused) {
  DaemonKey key;
  Reader r(key.pub());
  {
    SignedCell first(key.path);
    first.cycles(40);
    for (const auto& h : first.heard) r.feed(h);
    ASSERT_GE(r.released.size(), 32u);
  }
  const std::size_t before = r.released.size();
  SignedCell second(key.path);
  second.server->set_boot_id(daemon::test::kTestBoot + 1);
  second.cycles(4 * static_cast<int>(daemon::kSealEvery));
  int seals = 0;
  for (const auto& h : second.heard) {
    if (!h.stream) {
      ++seals;
      EXPECT_EQ(r.seal(h.bytes), Trust::other_boot);
    } else {
      r.message(*h.stream, h.bytes);
    }
  }
  EXPECT_EQ(r.released.size(), before) << "a message of the other boot was taken";
  EXPECT_EQ(r.v.refused(Trust::other_boot), seals);
  EXPECT_EQ(r.v.boot(), daemon::test::kTestBoot);
}

// Forged messages refused per client: a flood of forgeries, one beside every
// genuine state, each refused, and the genuine stream still verified.
TEST(SignedState, AFloodOfForgeriesIsRefusedAndCounted) {
  DaemonKey key;
  SignedCell cell(key.path);
  cell.cycles(200);
  cell.server->seal();
  cell.pump();
  Reader r(key.pub());
  std::vector<std::uint64_t> genuine, forged;
  for (const auto& h : cell.heard) {
    if (h.stream != Stream::state) {
      r.feed(h);
      continue;
    }
    state_t f;
    f.decode(h.bytes.data(), 0, static_cast<int>(h.bytes.size()));
    ASSERT_EQ(f.mode, state_t::MODE_DISABLED);
    forged.push_back(r.message(Stream::state, with_mode(f, state_t::MODE_HOLDING)));
    genuine.push_back(r.message(Stream::state, h.bytes));
  }
  cell.heard.clear();
  cell.cycles(4 * static_cast<int>(daemon::kSealEvery));  // the last forgeries' deadline
  for (const auto& h : cell.heard) r.feed(h);
  int ok = 0, refused = 0;
  for (const auto t : genuine) ok += r.verdict_of(t) == Trust::ok;
  for (const auto t : forged) refused += r.verdict_of(t) == Trust::unsealed;
  EXPECT_EQ(ok, static_cast<int>(genuine.size()));
  EXPECT_EQ(refused, static_cast<int>(forged.size()));
  EXPECT_EQ(r.v.refused_total(), static_cast<std::int64_t>(forged.size()));
  std::printf("forged states refused: %d of %zu; genuine verified: %d of %zu; at most %zu waiting\n", refused,
              forged.size(), ok, genuine.size(), r.v.waiting());
}

// A flood of forgeries with no seal to end their wait: the client holds a
// bounded number, refusing the oldest.
TEST(SignedState, WaitingMessagesAreBounded) {
  DaemonKey key;
  SignedCell cell(key.path);
  cell.cycles(2);
  const auto states = cell.states();
  ASSERT_FALSE(states.empty());
  Reader r(key.pub());
  state_t f = states[0].second;
  const std::size_t n = Verifier::kMaxWaiting + 500;
  for (std::size_t i = 0; i < n; ++i) {
    f.cycle = static_cast<std::int64_t>(i);
    r.message(Stream::state, encode(f));
  }
  EXPECT_EQ(r.v.waiting(), Verifier::kMaxWaiting);
  EXPECT_EQ(r.v.refused(Trust::unsealed), 500);
  EXPECT_TRUE(r.released.empty());
}

}  // namespace
}  // namespace cpm::redteam
