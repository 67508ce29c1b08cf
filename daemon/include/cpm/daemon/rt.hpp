// SPDX-License-Identifier: Apache-2.0
// The real-time thread: runs ControlLoop::cycle on an absolute schedule.
//
// The thread sleeps with clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME) until
// the start of its slot k (t0 + k * period), so errors never accumulate.
// When a cycle ends after the next slot began, that is an overrun; if the
// thread wakes later than a whole slot, the slots it missed are skipped (the
// cycle index jumps, nothing runs twice). The loop turns a configured number
// of consecutive overruns into a fault.
//
// Before the first cycle: mlockall(MCL_CURRENT | MCL_FUTURE) and a pre-faulted
// stack, SCHED_FIFO at the configured priority and the configured CPU. Each
// of these that the process may not do is reported as a warning (and the
// loop runs with normal scheduling) rather than refused.
#pragma once

#include <atomic>
#include <string>
#include <thread>
#include <vector>

#include "cpm/daemon/loop.hpp"

namespace cpm::daemon {

struct RtSetup {
  bool memory_locked = false;
  bool realtime = false;
  bool pinned = false;
  std::vector<std::string> warnings;
};

// Lock memory (process-wide) and pre-fault `stack_bytes` of the calling thread's stack.
bool lock_memory(std::vector<std::string>& warnings, std::size_t stack_bytes = 512 * 1024);

// While one lives, the heap above what was allocated before the first one
// and whatever is mapped meanwhile are not locked, so that a passing burst of
// allocation off the loop (a model file's parse) can be handed back with
// malloc_trim: locked pages cannot be. Its end locks what is resident there
// then (the model built), page by page, and locks what is mapped later as
// touched again. Only when lock_memory locked with MCL_ONFAULT; otherwise it
// does nothing. One at a time (a second waits); never on the loop's thread.
class FutureLocksPaused {
 public:
  FutureLocksPaused();
  ~FutureLocksPaused();
  FutureLocksPaused(const FutureLocksPaused&) = delete;
  FutureLocksPaused& operator=(const FutureLocksPaused&) = delete;

 private:
  bool paused_ = false;
};

class RtThread {
 public:
  explicit RtThread(ControlLoop& loop, const LoopConfig& cfg);
  ~RtThread();
  // Starts the thread; returns once it has set itself up (see setup()).
  void start(std::int64_t max_cycles = -1);
  void request_stop() noexcept { stop_.store(true, std::memory_order_release); }
  void join();
  [[nodiscard]] const RtSetup& setup() const noexcept { return setup_; }
  [[nodiscard]] bool running() const noexcept { return running_.load(std::memory_order_acquire); }

 private:
  void run(std::int64_t max_cycles);
  ControlLoop& loop_;
  LoopConfig cfg_;
  std::thread thread_;
  std::atomic<bool> stop_{false};
  std::atomic<bool> ready_{false};
  std::atomic<bool> running_{false};
  RtSetup setup_;
};

}  // namespace cpm::daemon
