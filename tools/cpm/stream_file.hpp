// SPDX-License-Identifier: Apache-2.0
// cpm stream's setpoint file and the checks it passes before anything is
// sent (cmd_client_motion.cpp); cpm excite checks its design with the same.
#pragma once

#include <array>
#include <functional>
#include <string>
#include <vector>

#include "cpm/control/machine.hpp"
#include "cpm/control/trajectory.hpp"
#include "cpm_msgs/state_t.hpp"
#include "cpm/daemon/client.hpp"
#include "cpm/daemon/config.hpp"
#include "cpm_msgs/params_t.hpp"
#include "cpm_msgs/trajectory_command_t.hpp"

namespace cpm::cli::client {

// A stream file's setpoints (SI) and the file line each came from.
struct StreamRows {
  std::vector<std::array<double, 7>> rows;  // t, x, y, z, vx, vy, vz
  std::vector<int> line;                    // the file's line of each row (1-based); 0: appended here
};

// CSV with columns t,x,y,z and optionally vx,vy,vz (SI).
StreamRows read_stream(const std::string& path);
// A stop at half the acceleration limit appended to a file that ends at speed; its duration (s), 0 when none.
double append_stop(StreamRows& s, double acceleration_limit);
// cpmd's messages, and the row each starts at.
std::vector<cpm_msgs::trajectory_command_t> stream_chunks(const StreamRows& s, std::vector<std::size_t>& first_row);
// The whole file through cpmd's segment and start checks: "" when it passes, else what and where.
std::string check_stream(const StreamRows& s, const std::vector<cpm_msgs::trajectory_command_t>& chunks,
                         const std::vector<std::size_t>& first_row, const ctl::Machine& machine,
                         const daemon::LimitsConfig& L, double dt);
// cpmd's limits as it publishes them (params_t), over the configured ones.
void apply_published_limits(const cpm_msgs::params_t& p, daemon::DaemonConfig& cfg);

// Play checked chunks on cpmd: the approach to the first row (a jerk-limited
// move, as cpm circle makes it), then the chunks as fast as cpmd accepts
// them, then (wait) until the last one ends. 0 when it played to its end.
struct PlayOptions {
  bool approach = true;
  double approach_vmax = 0.1, approach_amax = 1.0;  // m/s, m/s^2
  bool wait = true;
  std::function<void()> on_approached;  // called at rest at the first row, before the first chunk
};
int play_stream(daemon::Client& c, const StreamRows& s, const std::vector<cpm_msgs::trajectory_command_t>& chunks,
                const std::vector<std::size_t>& first_row, const PlayOptions& o);

// Run a circle on cpmd (cpm circle): the approach to its start, the circle,
// and (wait) its end, whose state (`end`) carries the tracking error over it
// (last_segment_rmse, m). 0 when it ran to its end.
struct CircleOptions {
  bool paper = false;          // Elkady's: full speed from rest (cpmd grants the step on its simulator)
  bool approach = true;
  double approach_vmax = 0.1;  // m/s
  bool wait = true;
};
int play_circle(daemon::Client& c, const ctl::CircleSpec& spec, const CircleOptions& o,
                cpm_msgs::state_t* end = nullptr);

}  // namespace cpm::cli::client
