// SPDX-License-Identifier: Apache-2.0
// Basic types of the hardware layer: errors, per-cycle status, clocks.
//
// hal/ knows nothing of the machine's kinematics or control: it moves frames,
// drive units and GPIO levels, scaled to SI units by configuration only.
#pragma once

#include <cstdint>
#include <functional>
#include <stdexcept>
#include <string>

namespace cpm::hal {

// Thrown by non-real-time entry points (configuration, start-up, opening a
// device). The message says what failed and where (interface, node id,
// object index:subindex, config key). Per-cycle calls never throw.
class Error : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

// Outcome of a per-cycle call. Plain data; no allocation.
enum class Code : std::uint8_t {
  ok = 0,
  would_block,       // nothing to receive / transmit queue full: try next cycle
  bus_off,           // the CAN controller is bus-off: nothing can be sent
  io_error,          // the device reported an error (errno in Status::detail)
  not_finite,        // a commanded value was NaN or infinite (replaced by 0)
  saturated,         // a commanded value was clamped to its limit
  not_started,       // the master or device has not been started
  bad_frame,         // a received frame had the wrong length or content
  timeout,           // an expected answer did not come in time
};

const char* code_name(Code c) noexcept;

struct Status {
  Code code = Code::ok;
  std::int8_t index = -1;    // drive or line index the status concerns, -1 none
  std::int32_t detail = 0;   // errno, CAN id, ... depending on code
  [[nodiscard]] bool ok() const noexcept { return code == Code::ok; }
  explicit operator bool() const noexcept { return ok(); }
};

// Monotonic time, injectable so that every protocol test is deterministic.
// Times are nanoseconds on a monotonic clock (CLOCK_MONOTONIC for the
// real one), never wall-clock time.
class Clock {
 public:
  virtual ~Clock() = default;
  [[nodiscard]] virtual std::int64_t now_ns() = 0;
  // Let time pass for up to `ns` (non-real-time start-up loops only). The
  // real clock sleeps; a fake clock advances and runs its tick hooks.
  virtual void wait(std::int64_t ns) = 0;
};

class SteadyClock final : public Clock {
 public:
  std::int64_t now_ns() override;
  void wait(std::int64_t ns) override;
};

// Time that moves only when told to. `wait` advances by the requested
// amount in steps of `step_ns` and, after each step, calls the hook (tests
// use it to run virtual drives, deliver delayed frames, ...).
class FakeClock final : public Clock {
 public:
  using Hook = std::function<void(std::int64_t now_ns)>;
  explicit FakeClock(std::int64_t start_ns = 0, std::int64_t step_ns = 100'000)
      : now_(start_ns), step_(step_ns) {}
  std::int64_t now_ns() override { return now_; }
  void wait(std::int64_t ns) override;
  void advance(std::int64_t ns) { now_ += ns; }
  void set_hook(Hook h) { hook_ = std::move(h); }

 private:
  std::int64_t now_;
  std::int64_t step_;
  Hook hook_;
};

// "what: strerror(err)" for Error messages.
std::string errno_text(const std::string& what, int err);

}  // namespace cpm::hal
