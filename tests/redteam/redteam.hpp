// SPDX-License-Identifier: Apache-2.0
// The red-team suite's common parts (docs/security.md, "Attacks and outcomes").
//
// Echo: no answer to a refused input may carry more than kMaxEcho bytes of
// that input. echoed() measures the longest run of bytes an answer shares
// with the input (longest common substring) and keeps the largest seen, which
// the suite prints at its end ("longest echo").
#pragma once

#include <gtest/gtest.h>

#include <algorithm>
#include <cstdio>
#include <string>
#include <vector>

#include <cpm_msgs/ack_t.hpp>
#include <cpm_msgs/control_command_t.hpp>
#include <cpm_msgs/state_t.hpp>
#include <cpm_msgs/trajectory_command_t.hpp>

#include "cpm/daemon/auth.hpp"

namespace cpm::redteam {

using cpm_msgs::ack_t;
using cpm_msgs::control_command_t;
using cpm_msgs::state_t;
using cpm_msgs::trajectory_command_t;
using daemon::Credentials;
using Bytes = std::vector<std::uint8_t>;
using C = control_command_t;

// A message's bytes as it goes on the bus.
template <class M>
Bytes encode(const M& m) {
  Bytes b(static_cast<std::size_t>(m.getEncodedSize()));
  m.encode(b.data(), 0, static_cast<int>(b.size()));
  return b;
}

inline constexpr std::size_t kMaxEcho = 80;

// Longest common substring of a (an answer, short) and b (the input; only
// its first 1 MiB is compared: an answer is far shorter than that).
inline std::size_t longest_common(const std::string& a, const std::string& b) {
  const std::size_t n = std::min<std::size_t>(b.size(), 1u << 20);
  std::vector<std::size_t> prev(a.size() + 1, 0), cur(a.size() + 1, 0);
  std::size_t best = 0;
  for (std::size_t j = 0; j < n; ++j) {
    for (std::size_t i = 0; i < a.size(); ++i) {
      cur[i + 1] = a[i] == b[j] ? prev[i] + 1 : 0;
      best = std::max(best, cur[i + 1]);
    }
    std::swap(prev, cur);
  }
  return best;
}

struct EchoRecord {
  std::size_t longest = 0;
  std::string where;
  int answers = 0;
};
inline EchoRecord& echo_record() {
  static EchoRecord r;
  return r;
}

// How much of `input` the answer `message` repeats; checked against kMaxEcho.
inline std::size_t expect_no_echo(const std::string& message, const std::string& input, const std::string& what) {
  const std::size_t n = longest_common(message, input);
  auto& r = echo_record();
  ++r.answers;
  if (n > r.longest) r.longest = n, r.where = what;
  EXPECT_LE(n, kMaxEcho) << what << ": the answer repeats " << n << " bytes of the input: " << message;
  return n;
}

// Prints the longest echo when the suite ends.
class EchoReport : public ::testing::Environment {
 public:
  void TearDown() override {
    const auto& r = echo_record();
    if (r.answers > 0)
      std::printf("redteam: longest echo of a rejected input in %d answers: %zu bytes (%s); bound %zu\n", r.answers,
                  r.longest, r.where.c_str(), kMaxEcho);
  }
};

}  // namespace cpm::redteam
