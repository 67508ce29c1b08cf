// SPDX-License-Identifier: Apache-2.0
// The loop's owners (loop_state.hpp) on their own: each transition against
// a closed form or a planted value, without a loop around it.
#include <gtest/gtest.h>

#include <cmath>
#include <string>

#include <cpm_msgs/ack_t.hpp>

#include "cpm/daemon/loop_state.hpp"
#include "cpm/daemon/server.hpp"

namespace cpm::daemon {
namespace {

TEST(FaultLatch, KeepsTheFirstFaultsParticularsAndEveryBit) {
  FaultLatch f;
  EXPECT_FALSE(f.active());
  f.set(kFaultFollowingError, 2, 0.004, 0.002, 17, "first");
  f.set(kFaultEstop, -1, 1.0, 0.0, 18, "second");
  EXPECT_TRUE(f.active());
  EXPECT_EQ(f.bits(), kFaultFollowingError | kFaultEstop);
  EXPECT_EQ(f.first(), kFaultFollowingError);
  EXPECT_EQ(f.axis(), 2);
  EXPECT_EQ(f.value(), 0.004);
  EXPECT_EQ(f.limit(), 0.002);
  EXPECT_EQ(f.cycle(), 17);
  EXPECT_STREQ(f.text(), "first");
  f.clear();
  EXPECT_FALSE(f.active());
  EXPECT_EQ(f.first(), 0u);
  EXPECT_EQ(f.axis(), -1);
  EXPECT_EQ(f.cycle(), -1);
  EXPECT_STREQ(f.text(), "");
}

TEST(FaultLatch, TruncatesLongWordsToTheStatesField) {
  FaultLatch f;
  const std::string words(200, 'w');
  f.set(kFaultDrive, 0, 0, 0, 1, words.c_str());
  EXPECT_EQ(std::string(f.text()).size(), FaultLatch::kTextBytes - 1);
}

TEST(StopProfile, BrakesToRestAtTheClosedFormDistanceAndTime) {
  // From 0.1 m/s along (3, 4, 0)/5 at 0.5 m/s^2: T = 0.2 s, distance
  // v^2 / 2a = 10 mm, at 1 kHz.
  StopProfile s;
  const Vec3 p0(0.1, 0.2, 0.3), v0 = Vec3(0.06, 0.08, 0.0);
  s.start(p0, v0, 0.5, 100, 0.0);
  EXPECT_NEAR(s.duration(), 0.2, 1e-15);
  const double dt = 1e-3;
  bool at_rest = true;
  const ctl::TrajectorySample half = s.sample(200, dt, 0.0, at_rest);  // t = 0.1 s
  EXPECT_FALSE(at_rest);
  EXPECT_NEAR((half.p - p0).norm(), 0.1 * 0.1 - 0.25 * 0.01, 1e-15);
  EXPECT_NEAR(half.v.norm(), 0.05, 1e-15);
  EXPECT_NEAR(half.a.norm(), 0.5, 1e-15);
  EXPECT_NEAR(half.v.normalized().dot(v0.normalized()), 1.0, 1e-12);
  const ctl::TrajectorySample end = s.sample(301, dt, 0.0, at_rest);
  EXPECT_TRUE(at_rest);
  EXPECT_NEAR((end.p - p0).norm(), 0.01, 1e-15);
  EXPECT_NEAR(end.v.norm(), 0.0, 1e-15);
  EXPECT_EQ(end.a, Vec3::Zero());
  // Ahead: the same profile later, and a start with time already behind it.
  const ctl::TrajectorySample ahead = s.sample(200, dt, 0.05, at_rest);
  EXPECT_EQ(ahead.p, s.sample(250, dt, 0.0, at_rest).p);
  StopProfile late;
  late.start(p0, v0, 0.5, 150, 0.05);
  EXPECT_NEAR((late.sample(200, dt, 0.0, at_rest).p - half.p).norm(), 0.0, 1e-15);
}

TEST(StopProfile, FromRestIsAtRestAtOnce) {
  StopProfile s;
  s.start(Vec3(1, 2, 3), Vec3::Zero(), 0.5, 0, 0.0);
  bool at_rest = false;
  const ctl::TrajectorySample r = s.sample(0, 1e-3, 0.0, at_rest);
  EXPECT_TRUE(at_rest);
  EXPECT_EQ(r.p, Vec3(1, 2, 3));
  EXPECT_EQ(r.v, Vec3::Zero());
}

Segment move(const Vec3& a, const Vec3& b) {
  Segment s;
  s.start = a;
  s.end = b;
  ctl::MotionLimits lim;
  lim.velocity = 0.1;
  s.traj.emplace<ctl::PointToPoint>(a, b, lim);
  return s;
}

TEST(SegmentQueue, PushPopFlushKeepOrderAndTheEnd) {
  RetiredPlans retired;
  SegmentQueue q(retired);
  EXPECT_FALSE(q.start(0));  // nothing to play
  const Vec3 a(0, 0, 0), b(0.01, 0, 0), c(0.01, 0.01, 0);
  q.push(move(a, b), 7);
  q.push(move(b, c), 8);
  EXPECT_EQ(q.count(), 2);
  EXPECT_EQ(q.end(), c);
  EXPECT_EQ(q.end_velocity(), Vec3::Zero());  // moves end at rest
  EXPECT_TRUE(q.start(5));
  EXPECT_TRUE(q.playing());
  EXPECT_EQ(q.start_cycle(), 5);
  EXPECT_EQ(q.at(0).id, 7);
  EXPECT_EQ(q.at(1).id, 8);
  q.pop();
  EXPECT_FALSE(q.playing());
  EXPECT_EQ(q.count(), 1);
  EXPECT_EQ(q.at(0).id, 8);
  // Around the ring's end: the order holds.
  for (int i = 0; i < 3 * SegmentQueue::kCapacity; ++i) {
    q.push(move(c, c), 100 + i);
    EXPECT_EQ(q.at(0).id, i == 0 ? 8 : 100 + i - 1);
    q.pop();
  }
  q.flush();
  EXPECT_EQ(q.count(), 0);
  EXPECT_FALSE(q.playing());
  EXPECT_EQ(q.end(), c);  // a flushed queue ends where it ended, at rest
  q.end_at_rest(a);
  EXPECT_EQ(q.end(), a);
  EXPECT_EQ(retired.size(), 0u);  // no plans: nothing to hand back
}

TEST(SegmentTracking, RmsAndMaxOfThePlayedSegment) {
  SegmentTracking t;
  t.begin();
  for (const double e : {3e-6, 4e-6, 0.0, 5e-6}) t.add(e);
  t.finish(42);
  EXPECT_EQ(t.last_id(), 42);
  EXPECT_EQ(t.last_cycles(), 4);
  EXPECT_NEAR(t.last_rmse(), std::sqrt((9.0 + 16.0 + 25.0) / 4.0) * 1e-6, 1e-18);
  EXPECT_EQ(t.last_max(), 5e-6);
  t.begin();
  t.finish(43);  // no cycle played
  EXPECT_EQ(t.last_rmse(), 0.0);
}

TEST(HomingSequence, FollowsTheConfiguredOrderFilteredByTheMask) {
  HomingConfig cfg;  // order z, x, y; all incremental
  for (auto& a : cfg.axes) a.method = HomingMethod::switch_;
  HomingSequence h(cfg);
  EXPECT_FALSE(h.all_homed());
  h.homed = {true, true, true};
  EXPECT_EQ(h.plan(cfg, 0b011), 2);  // x and y, in the order: x then y
  EXPECT_FALSE(h.homed[0]);
  EXPECT_FALSE(h.homed[1]);
  EXPECT_TRUE(h.homed[2]);
  EXPECT_EQ(h.begin_next(), 0);
  EXPECT_TRUE(h.more());
  EXPECT_EQ(h.begin_next(), 1);
  EXPECT_FALSE(h.more());
  h.end(true);
  EXPECT_EQ(h.axis(), -1);
  EXPECT_EQ(h.plan(cfg, 0), 3);
  EXPECT_EQ(h.begin_next(), 2);  // z first
}

TEST(HomingSequence, AbsoluteActuatorsAreHomedFromTheStart) {
  HomingConfig cfg;
  for (auto& a : cfg.axes) a.method = HomingMethod::absolute;
  cfg.order_count = 0;
  HomingSequence h(cfg);
  EXPECT_TRUE(h.all_homed());
  EXPECT_EQ(h.plan(cfg, 0), 0);  // nothing to home
  EXPECT_TRUE(h.all_homed());
}

TEST(Transfer, FadesTheDifferenceOutLinearly) {
  Transfer t;
  const double dt = 1e-3, T = 0.5;
  t.off(false);
  EXPECT_FALSE(t.fade(0, Vec3::Zero(), Vec3::Zero(), dt, T));
  t.law(true);  // the law changes: a transfer is due
  const Vec3 written(10, -4, 2), law(6, -4, 0);
  ASSERT_TRUE(t.fade(100, written, law, dt, T));
  EXPECT_EQ(t.now(), written - law);
  ASSERT_TRUE(t.fade(350, written, law, dt, T));  // half-way
  EXPECT_NEAR((t.now() - 0.5 * (written - law)).norm(), 0.0, 1e-12);
  ASSERT_TRUE(t.fade(600, written, law, dt, T));  // the end: weight 0
  EXPECT_EQ(t.now(), Vec3::Zero());
  EXPECT_FALSE(t.fade(601, written, law, dt, T));
  t.law(true);  // the same law again: nothing due
  EXPECT_FALSE(t.fade(602, written, law, dt, T));
}

TEST(OverrunCount, ARunOfMaxBecomesOneFault) {
  OverrunCount o;
  o.record(true, 3);
  o.record(true, 3);
  o.record(false, 3);  // the run breaks
  o.record(true, 3);
  o.record(true, 3);
  EXPECT_FALSE(o.take());
  o.record(true, 3);
  EXPECT_EQ(o.consecutive(), 3);
  EXPECT_TRUE(o.take());
  EXPECT_FALSE(o.take());  // once
  o.clear();
  EXPECT_EQ(o.consecutive(), 0);
}

TEST(LoopRequests, EachStopIsTakenOnce) {
  LoopRequests r;
  EXPECT_FALSE(r.take_stop());
  r.stop();
  r.stop();
  EXPECT_TRUE(r.take_stop());  // both, at once
  EXPECT_FALSE(r.take_stop());
  EXPECT_FALSE(r.shutdown_requested());
  r.shutdown();
  EXPECT_TRUE(r.shutdown_requested());
}

TEST(Jog, TheDeadmanDropsTheTargetAtTheDeadline) {
  Jog j;
  j.take(1, Vec3(0.01, 0, 0), 250);
  j.deadman(249);
  EXPECT_EQ(j.target, Vec3(0.01, 0, 0));
  j.deadman(250);
  EXPECT_EQ(j.target, Vec3::Zero());
}

TEST(CycleStatistics, EachPhaseItsOwnSampleAndTheWholeCycleTheSum) {
  CycleStatistics st(1000.0);
  EXPECT_EQ(st.sums().rate_hz, 1000.0);
  // Phases of 1, 2, ..., 8 us after a start at 10 us: the cycle lasts 36 us.
  PhaseTimes t{};
  t[0] = 10000;
  for (int s = kSeriesRead; s <= kSeriesPublish; ++s) t[s] = t[s - 1] + 1000 * s;
  st.cycle(t);
  EXPECT_EQ(st.cycles_done(), 0);  // not yet handed on
  st.completed();
  EXPECT_EQ(st.cycles_done(), 1);
  for (int s = kSeriesRead; s <= kSeriesPublish; ++s) {
    EXPECT_EQ(st.sums().count[s], 1) << s;
    EXPECT_EQ(st.sums().min_ns[s], 1000 * s);
    EXPECT_EQ(st.sums().max_ns[s], 1000 * s);
    EXPECT_EQ(st.sums().histogram[s][s], 1);  // [s, s + 1) us
  }
  EXPECT_EQ(st.sums().max_ns[kSeriesCycle], 36000);
  EXPECT_EQ(st.sums().count[kSeriesLatency], 0);
}

TEST(CycleStatistics, LatencyInBothHistogramsAndExtremesOverSamples) {
  CycleStatistics st(1000.0);
  for (const std::int64_t ns : {std::int64_t{700}, std::int64_t{250'000}, std::int64_t{-5}, std::int64_t{3'000'000}})
    st.latency(ns);
  const cpm_msgs::loop_stats_t& s = st.sums();
  EXPECT_EQ(s.count[kSeriesLatency], 4);
  EXPECT_EQ(s.min_ns[kSeriesLatency], 0);  // a negative latency counts as none
  EXPECT_EQ(s.max_ns[kSeriesLatency], 3'000'000);
  EXPECT_DOUBLE_EQ(s.sum_ns[kSeriesLatency], 700.0 + 250'000.0 + 3'000'000.0);
  EXPECT_EQ(s.histogram[kSeriesLatency][0], 2);
  EXPECT_EQ(s.histogram[kSeriesLatency][201], 1);  // 250 us: the 50 us bin [250, 300)
  EXPECT_EQ(s.histogram[kSeriesLatency][kBins - 1], 1);
  EXPECT_EQ(st.fine_latency()[0], 2);
  EXPECT_EQ(st.fine_latency()[250], 1);
  EXPECT_EQ(st.fine_latency()[kFineLatencyBins - 1], 1);
  st.schedule(true, 2);
  st.schedule(false, 0);
  st.schedule(true, 1);
  EXPECT_EQ(st.sums().overruns, 2);
  EXPECT_EQ(st.sums().skipped, 3);
}

TEST(ModeState, PublishesEveryModeItEnters) {
  ModeState m;
  EXPECT_EQ(m.now(), Mode::init);
  EXPECT_EQ(m.published(), Mode::init);
  for (const Mode x : {Mode::disabled, Mode::enabling, Mode::holding, Mode::fault}) {
    m.enter(x);
    EXPECT_EQ(m.now(), x);
    EXPECT_EQ(m.published(), x);
  }
}

TEST(ModeState, AStopEndsDisabledOnlyWhenADisableAskedForItOnce) {
  ModeState m;
  m.enter(Mode::stopping);
  EXPECT_EQ(m.after_stop(), Mode::holding);
  m.disable_after_stop();
  EXPECT_EQ(m.after_stop(), Mode::disabled);
  m.enter(Mode::stopping);  // still stopping: the request stays
  EXPECT_EQ(m.after_stop(), Mode::disabled);
  m.enter(m.after_stop());
  EXPECT_EQ(m.now(), Mode::disabled);
  m.enter(Mode::stopping);  // the next stop: spent
  EXPECT_EQ(m.after_stop(), Mode::holding);
  // A fault during the stop spends it as well.
  m.disable_after_stop();
  m.enter(Mode::fault);
  m.enter(Mode::stopping);
  EXPECT_EQ(m.after_stop(), Mode::holding);
}

TEST(ModeState, TheDrivesAreOnInTheSixModesThatPowerThem) {
  ModeState m;
  int on = 0;
  for (int i = 0; i <= static_cast<int>(Mode::jogging); ++i) {
    m.enter(static_cast<Mode>(i));
    on += m.drives_on() ? 1 : 0;
  }
  EXPECT_EQ(on, 6);
  for (const Mode off : {Mode::init, Mode::disabled, Mode::fault}) {
    m.enter(off);
    EXPECT_FALSE(m.drives_on()) << mode_name(off);
  }
}

TEST(ModeState, EnablingTimeCountsCyclesFromItsStart) {
  ModeState m;
  m.enter(Mode::enabling);
  m.enabling_from(100);
  EXPECT_DOUBLE_EQ(m.enabling_time(100, 1e-3), 0.0);
  EXPECT_DOUBLE_EQ(m.enabling_time(350, 1e-3), 0.25);
}

TEST(ActiveModel, SelectKeepsTheModelAndLoadSwapsBothAndHandsTheOldBack) {
  const ctl::Machine a{ctl::MachineModel::elkady()}, b{ctl::MachineModel::elkady()};
  using ctl::ControlLaw;
  ActiveModel m(a, ctl::Controller(a, ControlLaw::pd, ctl::table3_gains(ControlLaw::pd)));
  EXPECT_EQ(&m.machine(), &a);
  m.select(ctl::Controller(a, ControlLaw::computed_torque, ctl::table3_gains(ControlLaw::computed_torque)));
  EXPECT_EQ(&m.machine(), &a);
  EXPECT_EQ(m.controller().law(), ControlLaw::computed_torque);
  const ctl::Machine* old =
      m.load(b, ctl::Controller(b, ControlLaw::pd_gravity, ctl::table3_gains(ControlLaw::pd_gravity)));
  EXPECT_EQ(old, &a);
  EXPECT_EQ(&m.machine(), &b);
  EXPECT_EQ(&m.controller().model(), &b);
  EXPECT_EQ(m.controller().law(), ControlLaw::pd_gravity);
}

TEST(ActiveModel, KeepsWhatTheDrivesWereGivenUntilRestarted) {
  const ctl::Machine a{ctl::MachineModel::elkady()};
  ActiveModel m(a, ctl::Controller(a, ctl::ControlLaw::pd, ctl::table3_gains(ctl::ControlLaw::pd)));
  m.sent().push(0.001, Vec3(1, 2, 3));
  m.sent().push(0.002, Vec3(4, 5, 6));
  m.sent().amend_last(Vec3(7, 8, 9));
  ASSERT_EQ(m.sent().size(), 2);
  EXPECT_EQ(m.sent().force(0), Vec3(7, 8, 9));
  EXPECT_EQ(m.sent().force(1), Vec3(1, 2, 3));
  m.restart();
  EXPECT_EQ(m.sent().size(), 0);
}

TEST(Refusal, EachMapsToItsOwnAckReason) {
  using cpm_msgs::ack_t;
  EXPECT_EQ(ack_reason(Refusal::none), ack_t::REASON_NONE);
  EXPECT_EQ(ack_reason(Refusal::illegal_in_mode), ack_t::REASON_ILLEGAL_IN_MODE);
  EXPECT_EQ(ack_reason(Refusal::fault_active), ack_t::REASON_FAULT_ACTIVE);
  EXPECT_EQ(ack_reason(Refusal::not_homed), ack_t::REASON_NOT_HOMED);
  EXPECT_EQ(ack_reason(Refusal::queue_full), ack_t::REASON_QUEUE_FULL);
  EXPECT_EQ(ack_reason(Refusal::not_continuous), ack_t::REASON_NOT_CONTINUOUS);
  EXPECT_EQ(ack_reason(Refusal::limit), ack_t::REASON_LIMIT);
  EXPECT_EQ(ack_reason(Refusal::workspace), ack_t::REASON_WORKSPACE);
}

}  // namespace
}  // namespace cpm::daemon
