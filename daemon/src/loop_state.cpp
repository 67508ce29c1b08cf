// SPDX-License-Identifier: Apache-2.0
#include "cpm/daemon/loop_state.hpp"

#include <algorithm>
#include <cmath>
#include <cstring>

#include "cpm/path/program.hpp"

namespace cpm::daemon {

const ctl::Trajectory* Segment::get() const noexcept {
  if (auto* c = std::get_if<ctl::CircleTrajectory>(&traj)) return c;
  if (auto* p = std::get_if<ctl::PointToPoint>(&traj)) return p;
  if (auto* s = std::get_if<StreamTrajectory>(&traj)) return s;
  if (auto* p = std::get_if<const path::Plan*>(&traj)) return *p;
  return nullptr;
}

int histogram_bin(std::int64_t ns) noexcept {
  if (ns < 0) ns = 0;
  const std::int64_t us = ns / 1000;
  if (us < 200) return static_cast<int>(us);
  if (us < 2000) return 200 + static_cast<int>((us - 200) / 50);
  return kBins - 1;
}

std::int64_t histogram_bin_floor(int k) noexcept {
  if (k < 200) return std::int64_t{k} * 1000;
  return (200 + std::int64_t{k - 200} * 50) * 1000;
}

CycleStatistics::CycleStatistics(double rate_hz) noexcept {
  sums_.rate_hz = rate_hz;
  for (int s = 0; s < kSeries; ++s) sums_.min_ns[s] = 0;
}

void CycleStatistics::add(int s, std::int64_t ns) noexcept {
  if (ns < 0) ns = 0;
  const auto v = static_cast<std::int32_t>(std::min<std::int64_t>(ns, INT32_MAX));
  if (sums_.count[s] == 0 || v < sums_.min_ns[s]) sums_.min_ns[s] = v;
  if (v > sums_.max_ns[s]) sums_.max_ns[s] = v;
  sums_.count[s]++;
  sums_.sum_ns[s] += static_cast<double>(v);
  sums_.histogram[s][histogram_bin(ns)]++;
}

void CycleStatistics::latency(std::int64_t ns) noexcept {
  add(kSeriesLatency, ns);
  latency_us_[static_cast<std::size_t>(std::clamp<std::int64_t>(ns / 1000, 0, kFineLatencyBins - 1))]++;
}

void CycleStatistics::schedule(bool overrun, std::int64_t skipped) noexcept {
  sums_.skipped += skipped;
  if (overrun) sums_.overruns++;
}

void CycleStatistics::scheduling(bool realtime, bool memory_locked) noexcept {
  sums_.realtime = realtime ? 1 : 0;
  sums_.memory_locked = memory_locked ? 1 : 0;
}

void CycleStatistics::cycle(const PhaseTimes& t) noexcept {
  for (int s = kSeriesRead; s <= kSeriesPublish; ++s) add(s, t[s] - t[s - 1]);
  add(kSeriesCycle, t[kSeriesPublish] - t[0]);
  sums_.cycles++;
}

void segment_end_motion(const Segment& s, Vec3& velocity, Vec3& acceleration) noexcept {
  const ctl::Trajectory* tr = s.get();
  const auto* stream = std::get_if<StreamTrajectory>(&s.traj);
  if (!tr || !stream) {
    // Moves and circles end at rest (a circle's ramp, or Elkady's abrupt
    // stop, which the hold then takes as a step: the loop plays what it was
    // given, and the next segment starts from rest).
    velocity.setZero();
    acceleration.setZero();
    return;
  }
  velocity = stream->end_velocity();
  acceleration = tr->sample(tr->duration()).a;
}

void FaultLatch::set(std::uint32_t bit, int axis, double value, double limit, std::int64_t cycle,
                     const char* text) noexcept {
  if (bits_ == 0) {
    first_ = bit;
    axis_ = axis;
    value_ = value;
    limit_ = limit;
    cycle_ = cycle;
    std::strncpy(text_, text, sizeof text_ - 1);
    text_[sizeof text_ - 1] = '\0';
  }
  bits_ |= bit;
}

void StopProfile::start(const Vec3& p0, const Vec3& v0, double deceleration, std::int64_t k, double elapsed) noexcept {
  const double v = v0.norm();
  p0_ = p0;
  v0_ = v;
  dir_ = v > 1e-12 ? Vec3(v0 / v) : Vec3::Zero();
  a_ = deceleration;
  duration_ = v / deceleration;
  start_cycle_ = k;
  t0_ = elapsed;
}

ctl::TrajectorySample StopProfile::sample(std::int64_t k, double dt, double ahead, bool& at_rest) const noexcept {
  const double elapsed = static_cast<double>(k - start_cycle_) * dt + t0_ + ahead;
  const double t = std::min(elapsed, duration_);
  ctl::TrajectorySample r;
  r.p = p0_ + dir_ * (v0_ * t - 0.5 * a_ * t * t);
  r.v = dir_ * (v0_ - a_ * t);
  r.a = t < duration_ ? Vec3(-a_ * dir_) : Vec3::Zero();
  at_rest = elapsed >= duration_;
  return r;
}

SegmentQueue::SegmentQueue(RetiredPlans& retired)
    : retired_(&retired), ring_(std::make_unique<std::array<Segment, kCapacity>>()) {}

void SegmentQueue::clear_slot(Segment& s) noexcept {
  // The ring holds twice the queue: a push cannot fail while the server drains it.
  if (auto* p = std::get_if<const path::Plan*>(&s.traj)) (void)retired_->push(*p);
  s.traj = std::monostate{};
}

void SegmentQueue::push(const Segment& s, std::int64_t id) noexcept {
  Segment& slot = (*ring_)[(head_ + count_) % kCapacity];
  slot = s;
  slot.id = id;
  count_++;
  end_ = s.end;
  segment_end_motion(slot, end_v_, end_a_);
}

bool SegmentQueue::start(std::int64_t k) noexcept {
  if (count_ == 0) return false;
  playing_ = true;
  start_cycle_ = k;
  return true;
}

void SegmentQueue::pop() noexcept {
  clear_slot((*ring_)[head_]);
  head_ = (head_ + 1) % kCapacity;
  count_--;
  playing_ = false;
}

void SegmentQueue::flush() noexcept {
  for (int i = 0; i < count_; ++i) clear_slot((*ring_)[(head_ + i) % kCapacity]);
  head_ = 0;
  count_ = 0;
  playing_ = false;
  end_v_.setZero();
  end_a_.setZero();
}

void SegmentQueue::end_at_rest(const Vec3& p) noexcept {
  end_ = p;
  end_v_.setZero();
  end_a_.setZero();
}

void SegmentTracking::add(double error) noexcept {
  sum_e2_ += error * error;
  max_ = std::max(max_, error);
  n_++;
}

void SegmentTracking::finish(std::int64_t id) noexcept {
  last_id_ = id;
  last_n_ = n_;
  last_rmse_ = n_ > 0 ? std::sqrt(sum_e2_ / n_) : 0.0;
  last_max_ = max_;
}

HomingSequence::HomingSequence(const HomingConfig& cfg) noexcept {
  for (std::size_t i = 0; i < 3; ++i) homed[i] = cfg.axes[i].method == HomingMethod::absolute;
}

int HomingSequence::plan(const HomingConfig& cfg, std::uint8_t mask) noexcept {
  count_ = 0;
  for (int n = 0; n < cfg.order_count; ++n) {
    const int i = cfg.order[static_cast<std::size_t>(n)];
    if (mask == 0 || (mask & (1u << i))) queue_[static_cast<std::size_t>(count_++)] = i;
  }
  for (int n = 0; n < count_; ++n) homed[static_cast<std::size_t>(queue_[static_cast<std::size_t>(n)])] = false;
  next_ = 0;
  return count_;
}

int HomingSequence::begin_next() noexcept {
  axis_ = queue_[static_cast<std::size_t>(next_++)];
  return axis_;
}

void HomingSequence::end(bool completed) noexcept {
  if (!completed) axis_homing.abort();
  axis_ = -1;
  count_ = next_ = 0;
  request = {};
}

void Transfer::off(bool actuator) noexcept {
  actuator_law_ = actuator;
  pending_ = false;
  force_.setZero();
  now_.setZero();
}

bool Transfer::fade(std::int64_t k, const Vec3& written, const Vec3& law_force, double dt,
                    double transfer_time) noexcept {
  if (pending_) {
    pending_ = false;
    force_ = written - law_force;
    start_ = k;
  }
  if (force_.isZero(0.0)) {
    now_.setZero();
    return false;
  }
  const double w = std::max(0.0, 1.0 - static_cast<double>(k - start_) * dt / transfer_time);
  now_ = w * force_;
  if (w == 0.0) force_.setZero();
  return true;
}

}  // namespace cpm::daemon
