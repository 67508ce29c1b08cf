// SPDX-License-Identifier: Apache-2.0
// cpmd's state stream as a motion log (docs/data-formats.md, kind =
// motion): what `cpm record` and `cpm lcm-log-to-csv` write, and what
// `cpm compare`, `diagnose` and `fit` read directly from an lcm-logger file.
// Not a subcommand itself.
#pragma once

#include <cstdint>
#include <string>

#include "cpm/io/data_files.hpp"
#include "cpm_msgs/state_t.hpp"

namespace cpm::cli {

// Builds a motion log from state_t messages, in order. Keeps the cycles in
// which the drives applied the commanded force (modes HOLDING, MOVING,
// STOPPING): in the others the drives are off and the brake holds the
// platform, so a row would show the whole weight as model error. Each
// unbroken stretch of such cycles is one run (the `run` column), so a pause
// with the drives off splits the log instead of joining its two ends.
class StateToMotion {
 public:
  // `location`: where the message came from (an lcm-logger event number), kept
  // per row for error messages; 0 when unknown.
  void add(const cpm_msgs::state_t& s, int location = 0);
  // The log so far; `rate` is the median sample rate (Hz) of its runs.
  [[nodiscard]] io::MotionData finish(const std::string& path, const std::string& source) const;
  [[nodiscard]] std::size_t rows() const noexcept { return data_.t.size(); }
  [[nodiscard]] long inactive() const noexcept { return inactive_; }  // messages left out (drives not applying force)

 private:
  io::MotionData data_;
  bool in_run_ = false;
  long run_ = -1;
  long inactive_ = 0;
};

// The first bytes are an lcm-logger event's sync word.
bool is_lcm_log(const std::string& path);

struct StateLogRead {
  io::MotionData data;
  long undecodable = 0;  // events on the channel that were skipped (lenient reading only)
  long inactive = 0;     // states left out: the drives did not apply the force
};

// Every event of `channel` in an lcm-logger file, as a motion log. Strict: an
// event that does not decode as state_t, or a non-finite time, displacement,
// velocity or force, is an Error naming the file, the event and the field;
// lenient (conversion): such events are counted and skipped.
StateLogRead read_state_log(const std::string& path, const std::string& channel, bool strict);

// What compare, diagnose and fit read: an lcm-logger file of cpmd's state
// channel (strictly, as a motion log), or a CSV of docs/data-formats.md.
io::DataSet read_measurements(const std::string& path, const std::string& channel = "CPMD_STATE");

}  // namespace cpm::cli
