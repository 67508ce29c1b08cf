// SPDX-License-Identifier: Apache-2.0
// The path queue's server side (docs/path.md): programs assembled from
// path_command_t chunks, each planned whole in a worker thread (not the LCM
// thread, which must keep the state flowing and hear a stop; not the
// real-time one), the plan checked at every knot; and the store of the
// plans. The loop holds a pointer to a plan while it is queued or playing
// and hands it back through ControlLoop::retired_plans(); only then is it
// freed here, on the LCM thread, as ModelStore does with models.
#pragma once

#include <condition_variable>
#include <cstdint>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include <cpm_msgs/path_command_t.hpp>

#include "cpm/control/machine.hpp"
#include "cpm/daemon/config.hpp"
#include "cpm/daemon/path_message.hpp"
#include "cpm/path/plan.hpp"

namespace cpm::daemon {

// An answer for the sender of a chunk.
struct PathAnswer {
  bool ok = false;
  std::int16_t reason = 0;  // ack_t.REASON_*
  std::string message;
};

// What the worker made of a program.
struct PlannedPath {
  std::int64_t id = 0;  // the last chunk's id
  PathAnswer answer;    // refused: why, with the program line
  const path::Plan* plan = nullptr;  // accepted: owned by the service
  Vec3 start = Vec3::Zero(), end = Vec3::Zero();
};

class PathService {
 public:
  explicit PathService(const LimitsConfig& limits);
  ~PathService();  // waits for a plan in progress, then stops the worker

  // A chunk from an admitted operator: the answer now, or nullopt when it
  // was the last and the program went to the worker (finished() answers).
  // `queue_end`: where the program must start (the queue's end, m).
  std::optional<PathAnswer> add(const cpm_msgs::path_command_t& chunk, const ctl::MachineModel& model,
                                const Vec3& queue_end);
  // The programs planned or refused since the last call.
  std::vector<PlannedPath> finished();
  // A plan handed to the loop as command `id`; answered(): the loop's ack
  // (refused: the loop never held it, so it is freed).
  void sent(std::int64_t id, const path::Plan* plan);
  void answered(std::int64_t id, bool accepted);
  // Free a plan the loop no longer holds.
  void release(const path::Plan* plan);
  [[nodiscard]] std::size_t plans() const;  // alive (tests)
  [[nodiscard]] bool busy() const;          // a program is being planned

 private:
  struct Job {
    std::int64_t id = 0;
    std::optional<path::PathQueue> queue;
    std::optional<ctl::MachineModel> model;
  };
  void work();
  PlannedPath plan(const Job& job);

  LimitsConfig limits_;
  PathAssembly assembly_;                                 // LCM thread
  std::map<std::int64_t, const path::Plan*> sent_;        // LCM thread: sent to the loop, not yet answered
  mutable std::mutex mu_;                                 // the rest, between the LCM thread and the worker
  std::condition_variable cv_;
  std::optional<Job> job_;
  bool working_ = false, stop_ = false;
  std::vector<PlannedPath> done_;
  std::map<const path::Plan*, std::unique_ptr<path::Plan>> plans_;
  std::thread worker_;
};

}  // namespace cpm::daemon
