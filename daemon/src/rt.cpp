// SPDX-License-Identifier: Apache-2.0
#include "cpm/daemon/rt.hpp"

#include <pthread.h>
#include <sched.h>
#include <sys/mman.h>
#include <time.h>
#include <unistd.h>

#include <atomic>
#include <cerrno>
#include <cstdint>
#include <mutex>
#include <vector>
#include <cmath>
#include <cstring>

namespace cpm::daemon {
namespace {

// Whether lock_memory locked with MCL_ONFAULT; one FutureLocksPaused at a time.
std::atomic<bool> locked_on_fault{false};
std::mutex pause_mu;
std::uintptr_t heap_mark = 0;  // under pause_mu

std::size_t page_size() { return static_cast<std::size_t>(sysconf(_SC_PAGESIZE)); }
std::uintptr_t page_up(std::uintptr_t a) {
  const std::uintptr_t p = page_size();
  return (a + p - 1) / p * p;
}

constexpr std::int64_t kNs = 1000000000;

std::int64_t to_ns(const timespec& t) { return std::int64_t{t.tv_sec} * kNs + t.tv_nsec; }
timespec from_ns(std::int64_t ns) {
  timespec t{};
  t.tv_sec = static_cast<time_t>(ns / kNs);
  t.tv_nsec = static_cast<long>(ns % kNs);
  return t;
}
std::int64_t mono_ns() {
  timespec t{};
  clock_gettime(CLOCK_MONOTONIC, &t);
  return to_ns(t);
}

// Touch the stack so its pages are resident before the first cycle.
__attribute__((noinline)) void prefault_stack(std::size_t bytes) {
  volatile char* buf = static_cast<volatile char*>(__builtin_alloca(bytes));
  for (std::size_t i = 0; i < bytes; i += 4096) buf[i] = 0;
}

}  // namespace

bool lock_memory(std::vector<std::string>& warnings, std::size_t stack_bytes) {
  // What is mapped now is locked and resident; what is mapped later is locked
  // as it is touched (MCL_ONFAULT), not when it is mapped. Without ONFAULT a
  // stranger's single LCM fragment announcing a 256 MB message made the LCM
  // thread's reassembly buffer resident and locked at once (docs/security.md);
  // everything the loop uses is built, and so touched, before it runs.
  int rc = mlockall(MCL_CURRENT | MCL_FUTURE | MCL_ONFAULT);
  if (rc == 0) locked_on_fault.store(true);
  if (rc != 0 && errno == EINVAL) rc = mlockall(MCL_CURRENT | MCL_FUTURE);  // a kernel before 4.4
  if (rc != 0) {
    warnings.push_back(std::string("mlockall failed (") + std::strerror(errno) +
                       "): memory may be paged out; raise LimitMEMLOCK / ulimit -l");
    return false;
  }
  prefault_stack(stack_bytes);
  return true;
}

// The heap (one arena, brk: main.cpp) below the mark, all that was
// allocated before the first pause, stays locked throughout. Above it, while
// paused, nothing is locked: malloc_trim then hands back every free page
// there (it cannot hand back locked ones, and MCL_FUTURE locks the heap as it
// grows). At the end, what is resident above the mark (the model built, what
// other threads allocated meanwhile) is locked page by page, so that only
// what is resident counts as locked; the heap grown later is locked as
// touched again (MCL_FUTURE).
FutureLocksPaused::FutureLocksPaused() {
  if (!locked_on_fault.load()) return;
  pause_mu.lock();
  if (heap_mark == 0) heap_mark = page_up(reinterpret_cast<std::uintptr_t>(sbrk(0)));
  // MCL_CURRENT keeps every mapping locked (as touched); without MCL_FUTURE
  // what is mapped from now on is not.
  if (mlockall(MCL_CURRENT | MCL_ONFAULT) != 0) {
    pause_mu.unlock();
    return;
  }
  const std::uintptr_t top = page_up(reinterpret_cast<std::uintptr_t>(sbrk(0)));
  if (top > heap_mark) (void)munlock(reinterpret_cast<void*>(heap_mark), top - heap_mark);
  paused_ = true;
}

FutureLocksPaused::~FutureLocksPaused() {
  if (!paused_) return;
  (void)mlockall(MCL_FUTURE | MCL_ONFAULT);  // the mappings as they are, what comes locked as touched
  const std::uintptr_t top = page_up(reinterpret_cast<std::uintptr_t>(sbrk(0)));
  const std::size_t page = page_size();
  std::vector<unsigned char> resident;
  if (top > heap_mark) {
    resident.resize((top - heap_mark) / page);
    if (mincore(reinterpret_cast<void*>(heap_mark), top - heap_mark, resident.data()) == 0) {
      for (std::size_t i = 0; i < resident.size();) {
        if (!(resident[i] & 1)) {
          ++i;
          continue;
        }
        std::size_t j = i;
        while (j < resident.size() && (resident[j] & 1)) ++j;
        (void)mlock(reinterpret_cast<void*>(heap_mark + i * page), (j - i) * page);
        i = j;
      }
    } else {
      (void)mlock2(reinterpret_cast<void*>(heap_mark), top - heap_mark, MLOCK_ONFAULT);
    }
  }
  pause_mu.unlock();
}

RtThread::RtThread(ControlLoop& loop, const LoopConfig& cfg) : loop_(loop), cfg_(cfg) {}

RtThread::~RtThread() {
  request_stop();
  join();
}

void RtThread::join() {
  if (thread_.joinable()) thread_.join();
}

void RtThread::start(std::int64_t max_cycles) {
  stop_.store(false);
  thread_ = std::thread([this, max_cycles] { run(max_cycles); });
  while (!ready_.load(std::memory_order_acquire)) std::this_thread::yield();
}

void RtThread::run(std::int64_t max_cycles) {
  // Set-up, before the first cycle (may allocate: the warnings).
  if (cfg_.lock_memory) setup_.memory_locked = lock_memory(setup_.warnings);
  else prefault_stack(256 * 1024);
  if (cfg_.cpu >= 0) {
    cpu_set_t set;
    CPU_ZERO(&set);
    CPU_SET(cfg_.cpu, &set);
    const int rc = pthread_setaffinity_np(pthread_self(), sizeof set, &set);
    setup_.pinned = rc == 0;
    if (rc != 0)
      setup_.warnings.push_back("cannot pin the loop to CPU " + std::to_string(cfg_.cpu) + " (" +
                                std::strerror(rc) + "); it runs on any CPU");
  }
  if (cfg_.priority > 0) {
    sched_param sp{};
    sp.sched_priority = cfg_.priority;
    const int rc = pthread_setschedparam(pthread_self(), SCHED_FIFO, &sp);
    setup_.realtime = rc == 0;
    if (rc != 0)
      setup_.warnings.push_back("cannot use SCHED_FIFO priority " + std::to_string(cfg_.priority) + " (" +
                                std::strerror(rc) +
                                "): the loop runs with normal scheduling; run as root or with "
                                "LimitRTPRIO / CAP_SYS_NICE");
  }
  pthread_setname_np(pthread_self(), "cpmd-rt");
  loop_.set_scheduling_info(setup_.realtime, setup_.memory_locked);
  running_.store(true, std::memory_order_release);
  ready_.store(true, std::memory_order_release);

  const auto period = static_cast<std::int64_t>(std::llround(1e9 / cfg_.rate_hz));
  const std::int64_t t0 = mono_ns() + period;
  std::int64_t k = 0;
  while (!stop_.load(std::memory_order_acquire) && (max_cycles < 0 || k < max_cycles)) {
    const std::int64_t deadline = t0 + k * period;
    const timespec ts = from_ns(deadline);
    while (clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &ts, nullptr) == EINTR) {
    }
    std::int64_t woke = mono_ns();
    if (woke - deadline >= period && cfg_.skip_late_slots) {
      // Woke after the whole slot: skip to the slot that is running now.
      const std::int64_t now_slot = (woke - t0) / period;
      loop_.record_schedule(true, now_slot - k);
      k = now_slot;
      // The statistics keep how late the thread woke after the time it asked
      // for (loop_stats_t, as cyclictest measures it), not its offset into
      // the slot it skipped to: a stall of several periods shows as one.
      loop_.cycle(k, woke - deadline);
    } else {
      loop_.cycle(k, woke - deadline);
    }
    const std::int64_t deadline_k = t0 + k * period;
    const std::int64_t end = mono_ns();
    // The next slot is k + 1; when we are already past it, skip to the
    // first slot that has not begun (never run a slot twice or late).
    const std::int64_t next = cfg_.skip_late_slots ? (end - t0) / period + 1 : k + 1;
    const bool overrun = end > deadline_k + period;
    const std::int64_t skipped = std::max<std::int64_t>(0, next - (k + 1));
    loop_.record_schedule(overrun, skipped);
    k = std::max(k + 1, next);
  }
  running_.store(false, std::memory_order_release);
}

}  // namespace cpm::daemon
