// SPDX-License-Identifier: Apache-2.0
// A program's segments as path_command_t chunks and back (docs/path.md):
// what `cpm run` sends and what cpmd assembles, in one place so that both
// ends agree on the layout. Not real-time.
//
// Frame and units: the machine frame (m, z down), SI, as path::PathQueue.
#pragma once

#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include <cpm_msgs/ack_t.hpp>
#include <cpm_msgs/path_command_t.hpp>

#include "cpm/path/path.hpp"

namespace cpm::daemon {

inline constexpr int kPathChunkSegments = 100;       // segments per path_command_t
inline constexpr int kMaxProgramSegments = 100000;   // segments per program (1000 chunks)
// The longest program accepted, by its programmed feeds, rapids at
// limits.velocity and dwells (s): the plan holds a knot per 1 ms (32 bytes:
// 115 MB for an hour) in memory that cpmd locks.
inline constexpr double kMaxProgramDuration = 3600.0;
inline constexpr std::int8_t kPathAckSource = cpm_msgs::ack_t::SOURCE_PATH;  // of path_command_t's acks

// The queue's segments as chunks of program `program` (ids, session, seq and
// the MAC are the sender's to set).
std::vector<cpm_msgs::path_command_t> path_chunks(const path::PathQueue& queue, std::int64_t program);

// A program put together from its chunks, each checked as it comes.
class PathAssembly {
 public:
  // Take a chunk: "" when taken, else what is wrong with it ("chunk 3 of
  // program 7 came after chunk 1", "segment 12: an arc of zero radius").
  // A chunk 0 starts a new program (whatever was being assembled is
  // dropped); a refused chunk drops the program.
  std::string add(const cpm_msgs::path_command_t& chunk);
  // The last chunk was taken: the program, whole.
  [[nodiscard]] bool complete() const noexcept { return complete_; }
  [[nodiscard]] std::int64_t program() const noexcept { return program_; }
  // The program (after the last chunk); the assembly is empty after.
  path::PathQueue take();
  void clear() noexcept;

 private:
  std::optional<path::PathQueue> queue_;
  std::int64_t program_ = 0;
  int next_chunk_ = 0;
  bool complete_ = false;
};

// A lower bound of the program's duration (s): each segment at its feed,
// rapids at `rapid` (m/s), dwells.
double program_duration_bound(const path::PathQueue& queue, double rapid);

}  // namespace cpm::daemon
