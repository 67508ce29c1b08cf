// SPDX-License-Identifier: Apache-2.0
// Counts heap allocations made by this thread while a guard is alive. The
// global operator new is replaced in allocation_counter.cpp of the test
// binary that includes this (link it into that suite only).
#pragma once

#include <cstddef>

namespace cpm::test {

std::size_t allocations_on_this_thread() noexcept;

class CountAllocations {
 public:
  CountAllocations() noexcept : start_(allocations_on_this_thread()) {}
  [[nodiscard]] std::size_t count() const noexcept { return allocations_on_this_thread() - start_; }

 private:
  std::size_t start_;
};

}  // namespace cpm::test
