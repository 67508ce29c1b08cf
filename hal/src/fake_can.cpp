// SPDX-License-Identifier: Apache-2.0
#include "cpm/hal/fake_can.hpp"

#include <linux/can/error.h>

#include "cpm/hal/bus_load.hpp"

namespace cpm::hal {

// ---------------------------------------------------------------- port

FakeCanPort::FakeCanPort(FakeCanNetwork& net, std::string name, std::size_t capacity)
    : net_(net), name_(std::move(name)), ring_(capacity) {}

Status FakeCanPort::send(const CanFrame& f) noexcept {
  if (bus_off_) return {Code::bus_off, -1, 0};
  if (f.len > 8 || f.is_error()) return {Code::bad_frame, -1, static_cast<std::int32_t>(f.id)};
  ++stats_.tx_frames;
  return net_.transmit(*this, f);
}

Status FakeCanPort::receive(CanFrame& f) noexcept {
  net_.deliver_due();
  if (count_ == 0) return {Code::would_block, -1, 0};
  f = ring_[head_];
  head_ = (head_ + 1) % ring_.size();
  --count_;
  if (f.is_error()) ++stats_.error_frames;
  else ++stats_.rx_frames;
  return {};
}

void FakeCanPort::set_filters(std::span<const CanFilter> filters, bool error_frames) {
  if (filters.size() > filters_.size())
    throw Error("fake CAN port " + name_ + ": " + std::to_string(filters.size()) +
                " filters, at most " + std::to_string(filters_.size()));
  filter_count_ = 0;
  for (const auto& fl : filters) filters_[filter_count_++] = fl;
  error_frames_ = error_frames;
}

bool FakeCanPort::wait_receivable(std::int64_t) {
  net_.deliver_due();
  return count_ > 0;
}

bool FakeCanPort::accepts(const CanFrame& f) const noexcept {
  if (f.is_error()) return error_frames_;
  if (filter_count_ == 0) return true;
  for (std::size_t i = 0; i < filter_count_; ++i)
    if ((f.id & filters_[i].mask) == (filters_[i].id & filters_[i].mask)) return true;
  return false;
}

void FakeCanPort::push(const CanFrame& f) noexcept {
  if (!accepts(f)) return;
  if (count_ == ring_.size()) {  // as a kernel socket queue: the newest is lost
    ++stats_.rx_dropped;
    return;
  }
  ring_[(head_ + count_) % ring_.size()] = f;
  ++count_;
}

// ---------------------------------------------------------------- network

FakeCanNetwork::FakeCanNetwork(Clock& clock, std::int64_t latency_ns, std::size_t queue_capacity)
    : clock_(clock), latency_ns_(latency_ns), capacity_(queue_capacity) {
  rules_.reserve(64);
  pending_.reserve(queue_capacity);
}

FakeCanNetwork::~FakeCanNetwork() = default;

FakeCanPort& FakeCanNetwork::add_port(const std::string& name) {
  ports_.push_back(std::unique_ptr<FakeCanPort>(new FakeCanPort(*this, name, capacity_)));
  return *ports_.back();
}

void FakeCanNetwork::drop(std::uint32_t match, std::uint32_t mask, int count) {
  rules_.push_back(Rule{match, mask, count, 0, 0, Corruption::crc});
}
void FakeCanNetwork::drop_randomly(double p, std::uint64_t seed) {
  drop_p_ = p;
  rng_.seed(seed);
}
void FakeCanNetwork::delay(std::uint32_t match, std::uint32_t mask, std::int64_t delay_ns, int count) {
  rules_.push_back(Rule{match, mask, count, 1, delay_ns, Corruption::crc});
}
void FakeCanNetwork::corrupt(std::uint32_t match, std::uint32_t mask, Corruption how, int count) {
  rules_.push_back(Rule{match, mask, count, 2, 0, how});
}
void FakeCanNetwork::clear_faults() {
  rules_.clear();
  drop_p_ = 0.0;
}

void FakeCanNetwork::set_bus_off(bool off) {
  if (off == bus_off_) return;
  bus_off_ = off;
  for (auto& p : ports_) p->bus_off_ = off;
  inject_error_frame(off ? make_error_frame(CAN_ERR_BUSOFF, 0, 0, 255, 0)
                         : make_error_frame(CAN_ERR_RESTARTED | CAN_ERR_CRTL, CAN_ERR_CRTL_ACTIVE));
}

void FakeCanNetwork::inject_error_frame(const CanFrame& f) {
  CanFrame e = f;
  e.timestamp_ns = clock_.now_ns();
  for (auto& p : ports_) p->push(e);
}

Status FakeCanNetwork::transmit(const FakeCanPort& from, const CanFrame& f) noexcept {
  std::int64_t delay = latency_ns_;
  CanFrame out = f;
  for (auto& r : rules_) {
    if (r.remaining == 0 || (f.id & r.mask) != (r.match & r.mask)) continue;
    if (r.remaining > 0) --r.remaining;
    if (r.kind == 0) return {};  // lost: the sender believes it went out
    if (r.kind == 1) delay += r.delay_ns;
    if (r.kind == 2) {
      switch (r.how) {
        case Corruption::crc:
          // Every node flags the CRC error; the sender retransmits.
          ++wire_frames_;
          wire_bits_ += static_cast<std::uint64_t>(can_frame_bits_worst(f.len, f.is_extended()));
          inject_error_frame(make_error_frame(CAN_ERR_PROT, 0, CAN_ERR_PROT_FORM, 8, 8));
          break;
        case Corruption::data_bit:
          if (out.len > 0) out.data[0] ^= 0x01;
          else out.len = 1;
          break;
        case Corruption::length:
          out.len = out.len > 0 ? static_cast<std::uint8_t>(out.len - 1) : 1;
          break;
      }
    }
  }
  if (drop_p_ > 0.0 && std::uniform_real_distribution<double>(0.0, 1.0)(rng_) < drop_p_) return {};
  ++wire_frames_;
  wire_bits_ += static_cast<std::uint64_t>(can_frame_bits_worst(out.len, out.is_extended()));
  const std::int64_t now = clock_.now_ns();
  if (delay <= 0 && pending_.empty()) {
    out.timestamp_ns = now;
    deliver(&from, out);
    return {};
  }
  if (pending_.size() == pending_.capacity()) return {Code::would_block, -1, 0};
  pending_.push_back(Pending{out, &from, now + delay, seq_++});
  deliver_due();
  return {};
}

void FakeCanNetwork::deliver(const FakeCanPort* from, const CanFrame& f) noexcept {
  for (auto& p : ports_)
    if (p.get() != from) p->push(f);
}

void FakeCanNetwork::deliver_due() noexcept {
  if (pending_.empty()) return;
  const std::int64_t now = clock_.now_ns();
  // Deliver due frames in (due time, send order); small lists, so a scan.
  for (;;) {
    std::size_t best = pending_.size();
    for (std::size_t i = 0; i < pending_.size(); ++i) {
      if (pending_[i].due_ns > now) continue;
      if (best == pending_.size() || pending_[i].due_ns < pending_[best].due_ns ||
          (pending_[i].due_ns == pending_[best].due_ns && pending_[i].seq < pending_[best].seq))
        best = i;
    }
    if (best == pending_.size()) return;
    Pending p = pending_[best];
    pending_.erase(pending_.begin() + static_cast<std::ptrdiff_t>(best));
    p.frame.timestamp_ns = p.due_ns;
    deliver(p.sender, p.frame);
  }
}

}  // namespace cpm::hal
