// SPDX-License-Identifier: Apache-2.0
#include "cpm/hal/common.hpp"

#include <cerrno>
#include <cstring>
#include <ctime>

namespace cpm::hal {

const char* code_name(Code c) noexcept {
  switch (c) {
    case Code::ok: return "ok";
    case Code::would_block: return "would_block";
    case Code::bus_off: return "bus_off";
    case Code::io_error: return "io_error";
    case Code::not_finite: return "not_finite";
    case Code::saturated: return "saturated";
    case Code::not_started: return "not_started";
    case Code::bad_frame: return "bad_frame";
    case Code::timeout: return "timeout";
  }
  return "unknown";
}

std::int64_t SteadyClock::now_ns() {
  timespec ts{};
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return std::int64_t{ts.tv_sec} * 1'000'000'000 + ts.tv_nsec;
}

void SteadyClock::wait(std::int64_t ns) {
  if (ns <= 0) return;
  timespec ts{static_cast<time_t>(ns / 1'000'000'000), static_cast<long>(ns % 1'000'000'000)};
  while (nanosleep(&ts, &ts) != 0 && errno == EINTR) {
  }
}

void FakeClock::wait(std::int64_t ns) {
  while (ns > 0) {
    const std::int64_t d = ns < step_ ? ns : step_;
    now_ += d;
    ns -= d;
    if (hook_) hook_(now_);
  }
}

std::string errno_text(const std::string& what, int err) {
  return what + ": " + std::strerror(err);
}

}  // namespace cpm::hal
