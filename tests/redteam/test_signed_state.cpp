// Signed state and acks (docs/security.md, "Signed state"): what an attacker
// on the bus can do to a client's view of the machine with no key, and what
// the client's check (cpm::daemon::Verifier, used by Client) makes of it.
#include <gtest/gtest.h>
#include <unistd.h>

#include <filesystem>

#include "cpm/daemon/client.hpp"
#include "cpm/daemon/signing.hpp"
#include "redteam/cell.hpp"

namespace cpm::redteam {
namespace {

using daemon::Trust;
using daemon::Verifier;
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

struct SignedCell : Cell {
  std::vector<state_t> states;
  explicit SignedCell(const std::string& key) : Cell(key) {
    server->bus().subscribe(h.cfg.lcm.state_channel, &SignedCell::on_state, this);
  }
  void on_state(const lcm::ReceiveBuffer*, const std::string&, const state_t* s) { states.push_back(*s); }
};

// What cpmd publishes verifies, state and acks alike, with the public half only.
TEST(SignedState, EveryStateAndAckCpmdPublishesVerifies) {
  DaemonKey key;
  SignedCell cell(key.path);
  cell.alice_holding();
  cell.cycles(50);
  ASSERT_GE(cell.states.size(), 50u);
  ASSERT_GE(cell.acks.size(), 2u);
  Verifier v(key.pub());
  for (const auto& s : cell.states) EXPECT_EQ(v.check(s, s.boot_id, 0), Trust::ok) << "counter " << s.sign_counter;
  for (const auto& a : cell.acks) EXPECT_EQ(v.check(a, a.boot_id, 1), Trust::ok) << "ack " << a.id;
  EXPECT_EQ(v.refused_total(), 0);
  // An ack as the client library receives it (decode_ack, raw bytes) keeps its signature.
  const Bytes raw = encode(cell.acks.back());
  const auto back = daemon::decode_ack(raw.data(), raw.size());
  ASSERT_TRUE(back.has_value());
  EXPECT_TRUE(daemon::signature_valid(*back, key.pub()));
}

// The attack of issue 27: a forged "holding" state carrying the id of the
// move just sent, in every form an attacker without cpmd's key can make it.
TEST(SignedState, ForgedTamperedReplayedAndReorderedStateIsRefused) {
  DaemonKey key;
  SignedCell cell(key.path);
  const std::int64_t s = cell.alice_holding();
  const trajectory_command_t move = move_to(kP1 + Vec3(-0.1, 0, 0), 0.1);
  ASSERT_TRUE(cell.trajectory(&cell.alice, move, s, 2).accepted);
  cell.cycles(300);
  ASSERT_EQ(cell.h.mode(), daemon::Mode::moving);
  Verifier v(key.pub());
  for (const auto& st : cell.states) ASSERT_EQ(v.check(st, st.boot_id, 0), Trust::ok);
  const state_t real = cell.states.back();
  const std::int64_t move_id = real.segment_id;

  // 1. Forged from scratch: unsigned, and "signed" with the attacker's own key.
  state_t forged = real;
  forged.mode = state_t::MODE_HOLDING;
  forged.last_segment_id = move_id;
  forged.segment_id = -1;
  forged.last_segment_rmse = 1e-7;
  forged.sign_counter = real.sign_counter + 1;
  state_t unsigned_forgery = forged;
  unsigned_forgery.sign_counter = 0;
  for (auto& b : unsigned_forgery.signature) b = 0;
  daemon::Signer attacker(daemon::generate_key());
  state_t attacker_signed = forged;
  attacker.sign(attacker_signed);
  attacker_signed.sign_counter = real.sign_counter + 1;  // a plausible counter, re-signed below
  attacker.sign(attacker_signed);
  // 2. Tampered: the real message, mode changed, counter raised, signature kept.
  state_t tampered = forged;  // signature is real's
  state_t tampered_position = real;
  tampered_position.position[0] += 1e-3;
  tampered_position.sign_counter = real.sign_counter + 2;

  int sent = 0;
  for (const state_t* f : {&unsigned_forgery, &attacker_signed, &tampered, &tampered_position}) {
    const Trust t = v.check(*f, f->boot_id, 0);
    EXPECT_NE(t, Trust::ok) << "forgery " << sent;
    ++sent;
  }
  EXPECT_EQ(v.refused(Trust::unsigned_message), 1);
  EXPECT_EQ(v.refused(Trust::bad_signature), 3);

  // 3. Replayed and reordered: genuine messages, not newer than the last.
  EXPECT_EQ(v.check(real, real.boot_id, 0), Trust::stale);
  EXPECT_EQ(v.check(cell.states.front(), cell.states.front().boot_id, 0), Trust::stale);
  cell.cycles(5);
  const state_t newer = cell.states.back(), older = cell.states[cell.states.size() - 3];
  EXPECT_EQ(v.check(newer, newer.boot_id, 0), Trust::ok);
  EXPECT_EQ(v.check(older, older.boot_id, 0), Trust::stale);
  EXPECT_EQ(v.refused(Trust::stale), 3);
  // The machine was moving all along; nothing forged reached the verified view.
  EXPECT_EQ(newer.mode, state_t::MODE_MOVING);
}

// A restart (same key, another boot id) is refused and said, not trusted silently.
TEST(SignedState, StateOfAnotherBootIsRefused) {
  DaemonKey key;
  Verifier v(key.pub());
  {
    SignedCell first(key.path);
    first.cycles(5);
    for (const auto& st : first.states) ASSERT_EQ(v.check(st, st.boot_id, 0), Trust::ok);
  }
  SignedCell second(key.path);
  second.server->set_boot_id(daemon::test::kTestBoot + 1);
  second.cycles(5);
  ASSERT_FALSE(second.states.empty());
  for (const auto& st : second.states) EXPECT_EQ(v.check(st, st.boot_id, 0), Trust::other_boot);
  EXPECT_EQ(v.refused(Trust::other_boot), static_cast<std::int64_t>(second.states.size()));
}

// Forged messages refused per client: a flood of forgeries, each refused, and
// the genuine stream still verified between them.
TEST(SignedState, AFloodOfForgeriesIsRefusedAndCounted) {
  DaemonKey key;
  SignedCell cell(key.path);
  cell.cycles(200);
  Verifier v(key.pub());
  daemon::Signer attacker(daemon::generate_key());
  int ok = 0, forged = 0;
  for (const auto& st : cell.states) {
    state_t f = st;
    f.mode = state_t::MODE_DISABLED;
    attacker.sign(f);
    f.sign_counter = st.sign_counter;  // the genuine counter, the attacker's signature
    ++forged;
    EXPECT_EQ(v.check(f, f.boot_id, 0), Trust::bad_signature);
    ok += v.check(st, st.boot_id, 0) == Trust::ok;
  }
  EXPECT_EQ(ok, static_cast<int>(cell.states.size()));
  EXPECT_EQ(v.refused_total(), forged);
  std::printf("forged states refused: %lld of %d; genuine verified: %d of %zu\n",
              static_cast<long long>(v.refused_total()), forged, ok, cell.states.size());
}

}  // namespace
}  // namespace cpm::redteam
