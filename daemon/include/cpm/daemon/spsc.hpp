// SPDX-License-Identifier: Apache-2.0
// Single-producer single-consumer ring of fixed capacity, lock-free and
// allocation-free after construction. The real-time loop and the other threads
// meet only through these (and the atomics they expose): one thread pushes,
// one pops, neither ever waits.
#pragma once

#include <array>
#include <atomic>
#include <cstddef>
#include <memory>

namespace cpm::daemon {

template <class T, std::size_t N>
class SpscRing {
  static_assert(N >= 2 && (N & (N - 1)) == 0, "capacity must be a power of two");

 public:
  // Storage on the heap (constructed once, before the loop runs): T may be large.
  SpscRing() : slots_(std::make_unique<std::array<T, N>>()) {}

  // Producer side. False when full (the element is not stored).
  bool push(const T& v) noexcept {
    const std::size_t h = head_.load(std::memory_order_relaxed);
    if (h - tail_.load(std::memory_order_acquire) == N) return false;
    (*slots_)[h & (N - 1)] = v;
    head_.store(h + 1, std::memory_order_release);
    return true;
  }
  // Producer side: a slot to fill in place, then commit(). nullptr when full.
  T* claim() noexcept {
    const std::size_t h = head_.load(std::memory_order_relaxed);
    if (h - tail_.load(std::memory_order_acquire) == N) return nullptr;
    return &(*slots_)[h & (N - 1)];
  }
  void commit() noexcept { head_.store(head_.load(std::memory_order_relaxed) + 1, std::memory_order_release); }

  // Consumer side. False when empty.
  bool pop(T& out) noexcept {
    const std::size_t t = tail_.load(std::memory_order_relaxed);
    if (head_.load(std::memory_order_acquire) == t) return false;
    out = (*slots_)[t & (N - 1)];
    tail_.store(t + 1, std::memory_order_release);
    return true;
  }
  // Consumer side: the oldest element in place (nullptr when empty), then release().
  const T* front() noexcept {
    const std::size_t t = tail_.load(std::memory_order_relaxed);
    if (head_.load(std::memory_order_acquire) == t) return nullptr;
    return &(*slots_)[t & (N - 1)];
  }
  void release() noexcept { tail_.store(tail_.load(std::memory_order_relaxed) + 1, std::memory_order_release); }

  [[nodiscard]] std::size_t size() const noexcept {
    return head_.load(std::memory_order_acquire) - tail_.load(std::memory_order_acquire);
  }
  static constexpr std::size_t capacity() noexcept { return N; }

 private:
  std::unique_ptr<std::array<T, N>> slots_;
  alignas(64) std::atomic<std::size_t> head_{0};
  alignas(64) std::atomic<std::size_t> tail_{0};
};

}  // namespace cpm::daemon
