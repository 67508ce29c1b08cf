// SPDX-License-Identifier: Apache-2.0
// SDO client (CiA 301 §7.2.4): expedited and segmented upload and download,
// aborts in both directions, a timeout per expected answer. Non-blocking:
// start a transfer, feed it the server's frames and call poll() for time;
// the master wraps it in blocking calls for start-up. Allocation-free.
#pragma once

#include <array>
#include <cstdint>
#include <span>

#include "cpm/hal/can.hpp"

namespace cpm::hal {

class SdoClient {
 public:
  static constexpr std::size_t kMaxBytes = 1024;  // largest object transferred

  enum class State : std::uint8_t {
    idle,       // nothing started
    busy,       // waiting for the server
    done,       // finished; data() holds an upload's bytes
    aborted,    // the server aborted, or we did (see abort_code(), aborted_by_server())
    timed_out,  // no answer within the timeout (we sent abort 0x05040000)
  };

  SdoClient(std::uint8_t node, std::int64_t timeout_ns) noexcept : node_(node), timeout_ns_(timeout_ns) {}

  // Start a transfer; false when one is busy or the data are too long.
  // `force_segmented` sends even 1-4 byte values segmented (tests, and
  // servers that refuse expedited transfers).
  bool start_download(CanBus& bus, std::uint16_t index, std::uint8_t sub,
                      std::span<const std::uint8_t> data, std::int64_t now_ns,
                      bool force_segmented = false) noexcept;
  bool start_upload(CanBus& bus, std::uint16_t index, std::uint8_t sub, std::int64_t now_ns) noexcept;
  // Feed a frame from the server (COB-ID 0x580 + node); others are ignored.
  // Returns true when the frame was for this client.
  bool on_frame(CanBus& bus, const CanFrame& f, std::int64_t now_ns) noexcept;
  // Time passes: resend a frame that could not be queued, or time out.
  void poll(CanBus& bus, std::int64_t now_ns) noexcept;
  // Give up the current transfer (sends abort with `code` when busy).
  void abort(CanBus& bus, std::uint32_t code) noexcept;

  [[nodiscard]] State state() const noexcept { return state_; }
  [[nodiscard]] std::uint32_t abort_code() const noexcept { return abort_code_; }
  [[nodiscard]] bool aborted_by_server() const noexcept { return by_server_; }
  [[nodiscard]] std::span<const std::uint8_t> data() const noexcept { return {buf_.data(), size_}; }
  [[nodiscard]] std::uint16_t index() const noexcept { return index_; }
  [[nodiscard]] std::uint8_t subindex() const noexcept { return sub_; }
  [[nodiscard]] std::uint8_t node() const noexcept { return node_; }
  [[nodiscard]] bool was_segmented() const noexcept { return segmented_; }
  void set_timeout(std::int64_t ns) noexcept { timeout_ns_ = ns; }

 private:
  enum class Phase : std::uint8_t { none, download_initiate, download_segment, upload_initiate, upload_segment };
  void send(CanBus& bus, const CanFrame& f, std::int64_t now_ns) noexcept;
  void fail_local(CanBus& bus, std::uint32_t code) noexcept;
  void send_download_segment(CanBus& bus, std::int64_t now_ns) noexcept;

  std::uint8_t node_;
  std::int64_t timeout_ns_;
  State state_ = State::idle;
  Phase phase_ = Phase::none;
  std::uint16_t index_ = 0;
  std::uint8_t sub_ = 0;
  std::array<std::uint8_t, kMaxBytes> buf_{};
  std::size_t size_ = 0;       // download: bytes to send; upload: bytes received
  std::size_t offset_ = 0;     // download: bytes sent so far
  std::size_t expected_ = 0;   // upload: size announced by the server (0 unknown)
  bool toggle_ = false;
  bool segmented_ = false;
  std::int64_t deadline_ = 0;
  bool tx_pending_ = false;
  CanFrame tx_{};
  std::uint32_t abort_code_ = 0;
  bool by_server_ = false;
};

const char* sdo_state_name(SdoClient::State s) noexcept;

}  // namespace cpm::hal
