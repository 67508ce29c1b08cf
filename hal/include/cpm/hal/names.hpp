// SPDX-License-Identifier: Apache-2.0
// One table of names per enum (CiA 402 states, NMT states): a row per value,
// the last row the unknown value's, found by value.
#pragma once

#include <array>
#include <cstddef>

namespace cpm::hal {

// `key` for JSON and logs, `brief` for a narrow column, `full` for a sentence.
template <typename E>
struct Names {
  E value;
  const char* key;
  const char* brief;
  const char* full;
};

// The row of `v`; the table's last row (its unknown value) for a value the
// table lacks (a code off the bus).
template <typename E, std::size_t N>
constexpr const Names<E>& find_names(const std::array<Names<E>, N>& table, E v) noexcept {
  for (const Names<E>& n : table)
    if (n.value == v) return n;
  return table.back();
}

}  // namespace cpm::hal
