// SPDX-License-Identifier: Apache-2.0
#include "cpm/hal/sdo_client.hpp"

#include <cstring>

#include "cpm/hal/canopen.hpp"

namespace cpm::hal {

using namespace canopen;

const char* sdo_state_name(SdoClient::State s) noexcept {
  switch (s) {
    case SdoClient::State::idle: return "idle";
    case SdoClient::State::busy: return "busy";
    case SdoClient::State::done: return "done";
    case SdoClient::State::aborted: return "aborted";
    case SdoClient::State::timed_out: return "timed out";
  }
  return "invalid";
}

void SdoClient::send(CanBus& bus, const CanFrame& f, std::int64_t now_ns) noexcept {
  tx_ = f;
  tx_pending_ = !bus.send(f).ok();  // retried by poll()
  deadline_ = now_ns + timeout_ns_;
}

void SdoClient::fail_local(CanBus& bus, std::uint32_t code) noexcept {
  (void)bus.send(make_sdo_abort(kSdoRxBase + node_, index_, sub_, code));
  state_ = State::aborted;
  phase_ = Phase::none;
  abort_code_ = code;
  by_server_ = false;
  tx_pending_ = false;
}

void SdoClient::abort(CanBus& bus, std::uint32_t code) noexcept {
  if (state_ == State::busy) fail_local(bus, code);
}

bool SdoClient::start_download(CanBus& bus, std::uint16_t index, std::uint8_t sub,
                               std::span<const std::uint8_t> data, std::int64_t now_ns,
                               bool force_segmented) noexcept {
  if (state_ == State::busy || data.size() > kMaxBytes || data.empty()) return false;
  index_ = index;
  sub_ = sub;
  std::memcpy(buf_.data(), data.data(), data.size());
  size_ = data.size();
  offset_ = 0;
  toggle_ = false;
  abort_code_ = 0;
  by_server_ = false;
  state_ = State::busy;
  CanFrame f;
  f.id = kSdoRxBase + node_;
  f.len = 8;
  put_u16(&f.data[1], index);
  f.data[3] = sub;
  segmented_ = force_segmented || size_ > 4;
  if (!segmented_) {
    // ccs=1, n = 4 - size, e = 1, s = 1
    f.data[0] = static_cast<std::uint8_t>((kCcsInitiateDownload << 5) | ((4 - size_) << 2) | 0x03);
    std::memcpy(&f.data[4], buf_.data(), size_);
  } else {
    f.data[0] = static_cast<std::uint8_t>((kCcsInitiateDownload << 5) | 0x01);  // size indicated
    put_u32(&f.data[4], static_cast<std::uint32_t>(size_));
  }
  phase_ = Phase::download_initiate;
  send(bus, f, now_ns);
  return true;
}

bool SdoClient::start_upload(CanBus& bus, std::uint16_t index, std::uint8_t sub, std::int64_t now_ns) noexcept {
  if (state_ == State::busy) return false;
  index_ = index;
  sub_ = sub;
  size_ = 0;
  expected_ = 0;
  toggle_ = false;
  segmented_ = false;
  abort_code_ = 0;
  by_server_ = false;
  state_ = State::busy;
  CanFrame f;
  f.id = kSdoRxBase + node_;
  f.len = 8;
  f.data[0] = kCcsInitiateUpload << 5;
  put_u16(&f.data[1], index);
  f.data[3] = sub;
  phase_ = Phase::upload_initiate;
  send(bus, f, now_ns);
  return true;
}

void SdoClient::send_download_segment(CanBus& bus, std::int64_t now_ns) noexcept {
  const std::size_t n = size_ - offset_ < 7 ? size_ - offset_ : 7;
  const bool last = offset_ + n == size_;
  CanFrame f;
  f.id = kSdoRxBase + node_;
  f.len = 8;
  // ccs=0, t, n = 7 - bytes, c = last
  f.data[0] = static_cast<std::uint8_t>((toggle_ ? 0x10 : 0) | ((7 - n) << 1) | (last ? 1 : 0));
  std::memcpy(&f.data[1], buf_.data() + offset_, n);
  offset_ += n;
  phase_ = Phase::download_segment;
  send(bus, f, now_ns);
}

// Long (about 90 lines) on purpose: one switch over the transfer phases,
// each answering the server's frame as CiA 301 §7.2.4.3 orders it; split,
// the protocol's order would be spread over several functions.
bool SdoClient::on_frame(CanBus& bus, const CanFrame& f, std::int64_t now_ns) noexcept {
  if (f.is_error() || f.is_rtr() || f.cob_id() != kSdoTxBase + node_) return false;
  if (state_ != State::busy) return true;  // late or stray answer: ignore
  if (f.len != 8) {
    fail_local(bus, kAbortCommand);
    return true;
  }
  const std::uint8_t cmd = f.data[0];
  const std::uint8_t scs = cmd >> 5;
  if (scs == kCsAbort) {
    state_ = State::aborted;
    phase_ = Phase::none;
    abort_code_ = get_u32(&f.data[4]);
    by_server_ = true;
    tx_pending_ = false;
    return true;
  }
  const bool mux_ok = get_u16(&f.data[1]) == index_ && f.data[3] == sub_;
  switch (phase_) {
    case Phase::download_initiate:
      if (scs != kScsInitiateDownload || !mux_ok) return fail_local(bus, kAbortCommand), true;
      if (!segmented_) {
        state_ = State::done;
        phase_ = Phase::none;
      } else {
        send_download_segment(bus, now_ns);
      }
      return true;
    case Phase::download_segment: {
      if (scs != kScsDownloadSegment) return fail_local(bus, kAbortCommand), true;
      if (((cmd & 0x10) != 0) != toggle_) return fail_local(bus, kAbortToggle), true;
      toggle_ = !toggle_;
      if (offset_ == size_) {
        state_ = State::done;
        phase_ = Phase::none;
      } else {
        send_download_segment(bus, now_ns);
      }
      return true;
    }
    case Phase::upload_initiate: {
      if (scs != kScsInitiateUpload || !mux_ok) return fail_local(bus, kAbortCommand), true;
      const bool e = cmd & 0x02, s = cmd & 0x01;
      if (e) {
        const std::size_t n = s ? 4 - ((cmd >> 2) & 0x03) : 4;
        std::memcpy(buf_.data(), &f.data[4], n);
        size_ = n;
        state_ = State::done;
        phase_ = Phase::none;
        return true;
      }
      segmented_ = true;
      expected_ = s ? get_u32(&f.data[4]) : 0;
      if (expected_ > kMaxBytes) return fail_local(bus, kAbortOutOfMemory), true;
      CanFrame r;
      r.id = kSdoRxBase + node_;
      r.len = 8;
      r.data[0] = static_cast<std::uint8_t>(kCcsUploadSegment << 5);  // toggle 0
      phase_ = Phase::upload_segment;
      send(bus, r, now_ns);
      return true;
    }
    case Phase::upload_segment: {
      if (scs != kScsUploadSegment) return fail_local(bus, kAbortCommand), true;
      if (((cmd & 0x10) != 0) != toggle_) return fail_local(bus, kAbortToggle), true;
      const std::size_t n = 7 - ((cmd >> 1) & 0x07);
      const bool last = cmd & 0x01;
      if (size_ + n > kMaxBytes || (expected_ && size_ + n > expected_))
        return fail_local(bus, kAbortOutOfMemory), true;
      std::memcpy(buf_.data() + size_, &f.data[1], n);
      size_ += n;
      toggle_ = !toggle_;
      if (last) {
        if (expected_ && size_ != expected_) return fail_local(bus, kAbortTypeLength), true;
        state_ = State::done;
        phase_ = Phase::none;
        return true;
      }
      CanFrame r;
      r.id = kSdoRxBase + node_;
      r.len = 8;
      r.data[0] = static_cast<std::uint8_t>((kCcsUploadSegment << 5) | (toggle_ ? 0x10 : 0));
      send(bus, r, now_ns);
      return true;
    }
    case Phase::none:
      return true;
  }
  return true;
}

void SdoClient::poll(CanBus& bus, std::int64_t now_ns) noexcept {
  if (state_ != State::busy) return;
  if (tx_pending_) tx_pending_ = !bus.send(tx_).ok();
  if (now_ns >= deadline_) {
    (void)bus.send(make_sdo_abort(kSdoRxBase + node_, index_, sub_, kAbortTimeout));
    state_ = State::timed_out;
    phase_ = Phase::none;
    abort_code_ = kAbortTimeout;
    by_server_ = false;
    tx_pending_ = false;
  }
}

}  // namespace cpm::hal
