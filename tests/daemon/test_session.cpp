// SPDX-License-Identifier: Apache-2.0
// Who may command the machine: the session cpmd grants to one commander at
// a time and the sequence numbers its commands carry (docs/daemon.md). The
// server runs on memq:// (in-process LCM) with the loop on the simulator
// backend, cycle by cycle; the session clock is a variable the test moves,
// so expiry is tested without waiting. Every command here is signed by an
// operator (tests/redteam tests the ones that are not).
#include <gtest/gtest.h>

#include <lcm/lcm-cpp.hpp>
#include <vector>

#include "server_fixture.hpp"

namespace cpm::daemon {
namespace {

using cpm_msgs::ack_t;
using cpm_msgs::control_command_t;
using cpm_msgs::state_t;
using cpm_msgs::trajectory_command_t;
using C = control_command_t;

using Cell = test::ServerCell;

TEST(Session, CommandsWithoutASessionAreRefusedButAStopIsTaken) {
  Cell c;
  const ack_t a = c.control(C::CMD_ENABLE, 0, 1);
  EXPECT_FALSE(a.accepted);
  EXPECT_EQ(a.reason, ack_t::REASON_NOT_HOLDER);
  EXPECT_NE(a.message.find("CMD_ACQUIRE"), std::string::npos) << a.message;
  c.cycles(20);
  EXPECT_EQ(c.h.mode(), Mode::disabled);
  // Stop from anyone: the loop answers it (illegal while disabled is the
  // loop's reason, not the session's).
  const ack_t s = c.control(C::CMD_STOP, 0, 0);
  EXPECT_NE(s.reason, ack_t::REASON_NOT_HOLDER) << s.message;
}

TEST(Session, ASecondCommanderIsRefusedWhileTheFirstHoldsTheSession) {
  Cell c;
  const std::int64_t first = c.acquire(111);
  ASSERT_NE(first, 0);
  // Another nonce is another commander.
  const ack_t refused = c.control(C::CMD_ACQUIRE, 222, test::acquire_seq());
  EXPECT_FALSE(refused.accepted);
  EXPECT_EQ(refused.reason, ack_t::REASON_NOT_HOLDER);
  EXPECT_NE(refused.message.find("another commander holds the machine"), std::string::npos) << refused.message;
  // Its commands, with a made-up session, are refused and do nothing.
  const ack_t e2 = c.control(C::CMD_ENABLE, first + 1, 1);
  EXPECT_EQ(e2.reason, ack_t::REASON_NOT_HOLDER);
  c.cycles(20);
  EXPECT_EQ(c.h.mode(), Mode::disabled);
  // The holder commands; its repeated acquire (a lost ack) keeps the session.
  EXPECT_EQ(c.acquire(111), first);
  EXPECT_TRUE(c.control(C::CMD_ENABLE, first, 1).accepted);
  c.cycles(20);
  EXPECT_EQ(c.h.mode(), Mode::holding);
  // The other commander's release does not free the machine; the holder's does.
  EXPECT_EQ(c.control(C::CMD_RELEASE, 0, 5).reason, ack_t::REASON_NOT_HOLDER);
  EXPECT_EQ(c.acquire(222), 0);
  EXPECT_TRUE(c.control(C::CMD_RELEASE, first, 2).accepted);
  const std::int64_t second = c.acquire(222);
  EXPECT_NE(second, 0);
  EXPECT_NE(second, first);
  // The old holder's session is gone.
  EXPECT_EQ(c.control(C::CMD_DISABLE, first, 3).reason, ack_t::REASON_NOT_HOLDER);
  EXPECT_EQ(c.h.mode(), Mode::holding);
}

TEST(Session, AReplayedCommandIsRefusedNotPlayedTwice) {
  Cell c;
  const std::int64_t s = c.acquire(7);
  ASSERT_TRUE(c.control(C::CMD_ENABLE, s, 1).accepted);
  c.cycles(20);
  ASSERT_EQ(c.h.mode(), Mode::holding);
  const Vec3 p0 = c.h.position();
  const trajectory_command_t m = c.move_by(Vec3(-0.02, 0, 0), s, 2);
  ASSERT_TRUE(c.send(c.h.cfg.lcm.trajectory_channel, m).accepted);
  // The same bytes again (a duplicated datagram, or a recorded one replayed).
  const ack_t r = c.send(c.h.cfg.lcm.trajectory_channel, m);
  EXPECT_FALSE(r.accepted);
  EXPECT_EQ(r.reason, ack_t::REASON_STALE_SEQ);
  EXPECT_NE(r.message.find("seq 2"), std::string::npos) << r.message;
  c.cycles(2000);
  EXPECT_EQ(c.segments_accepted(), 1);
  // One segment queued and played: the platform ends where the move goes.
  EXPECT_NEAR((c.h.position() - (p0 + Vec3(-0.02, 0, 0))).norm(), 0.0, 1e-4);
  EXPECT_EQ(c.h.state().last_segment_id, m.id);
}

TEST(Session, AStaleOrRepeatedSequenceNumberIsRefused) {
  Cell c;
  const std::int64_t s = c.acquire(9);
  EXPECT_TRUE(c.control(C::CMD_PING, s, 10).accepted);
  EXPECT_EQ(c.control(C::CMD_ENABLE, s, 10).reason, ack_t::REASON_STALE_SEQ);  // repeated
  EXPECT_EQ(c.control(C::CMD_ENABLE, s, 3).reason, ack_t::REASON_STALE_SEQ);   // older
  c.cycles(20);
  EXPECT_EQ(c.h.mode(), Mode::disabled);
  // Control and trajectory commands share the counter.
  EXPECT_TRUE(c.control(C::CMD_ENABLE, s, 11).accepted);
  c.cycles(20);
  ASSERT_EQ(c.h.mode(), Mode::holding);
  const ack_t t = c.send(c.h.cfg.lcm.trajectory_channel, c.move_by(Vec3(0, 0.01, 0), s, 11));
  EXPECT_EQ(t.reason, ack_t::REASON_STALE_SEQ);
  EXPECT_TRUE(c.send(c.h.cfg.lcm.trajectory_channel, c.move_by(Vec3(0, 0.01, 0), s, 12)).accepted);
}

TEST(Session, ASilentHolderExpiresAndANewCommanderGetsIn) {
  Cell c;
  const std::int64_t s = c.acquire(1);
  ASSERT_NE(s, 0);
  c.now += 1.9;  // inside the timeout: still held
  EXPECT_EQ(c.acquire(2), 0);
  EXPECT_TRUE(c.control(C::CMD_PING, s, 1).accepted);  // a sign of life renews it
  c.now += 1.9;
  EXPECT_EQ(c.acquire(2), 0);
  EXPECT_EQ(c.server->session(), s);
  c.now += 2.1;  // silent for longer than lcm.session_timeout
  EXPECT_EQ(c.server->session(), 0);
  const std::int64_t t = c.acquire(2);
  ASSERT_NE(t, 0);
  EXPECT_NE(t, s);
  // The stale tool coming back is refused, and told why.
  const ack_t late = c.control(C::CMD_ENABLE, s, 2);
  EXPECT_EQ(late.reason, ack_t::REASON_NOT_HOLDER);
  EXPECT_TRUE(c.control(C::CMD_ENABLE, t, 1).accepted);
}

TEST(Session, StateIsOpenToANonHolderAndAStopFromAnyoneIsTaken) {
  Cell c;
  const std::int64_t s = c.acquire(5);
  ASSERT_TRUE(c.control(C::CMD_ENABLE, s, 1).accepted);
  c.cycles(20);
  ASSERT_EQ(c.h.mode(), Mode::holding);
  const int before = c.states;
  c.cycles(10);
  // The state subscriber never acquired anything and hears every cycle.
  EXPECT_EQ(c.states - before, 10);
  ASSERT_TRUE(c.send(c.h.cfg.lcm.trajectory_channel, c.move_by(Vec3(-0.05, 0, 0), s, 2)).accepted);
  c.cycles(200);
  ASSERT_EQ(c.h.mode(), Mode::moving);
  // A bystander without a session presses stop: the machine stops.
  const ack_t st = c.control(C::CMD_STOP, 0, 0);
  EXPECT_TRUE(st.accepted) << st.message;
  c.cycles(1000);
  EXPECT_EQ(c.h.mode(), Mode::holding);
  // The session stays with its holder.
  EXPECT_EQ(c.server->session(), s);
  EXPECT_TRUE(c.control(C::CMD_DISABLE, s, 3).accepted);
}

}  // namespace
}  // namespace cpm::daemon
