// SPDX-License-Identifier: Apache-2.0
// A controller closing the loop on the plant at a fixed control rate, the
// way the daemon does it on its embedded simulator backend: each period the
// encoders are read, the controller computes forces from the reference at
// the period's nominal time, and the plant integrates under those forces
// held constant (zero-order hold).
#pragma once

#include <string>
#include <vector>

#include "cpm/control/controller.hpp"
#include "cpm/io/data_files.hpp"
#include "cpm/sim/plant.hpp"

namespace cpm::sim {

struct LoopOptions {
  double rate_hz = 1000.0;
  double duration = -1.0;     // s; < 0: the trajectory's duration
  bool keep_log = true;
  void validate() const;
};

// One control period, as the motion log records it.
struct LogRow {
  double t = 0.0;
  Vec3 d = Vec3::Zero(), d_dot = Vec3::Zero();  // encoder reading (m, m/s)
  Vec3 force = Vec3::Zero();                    // actuator command (N)
  Vec3 p = Vec3::Zero(), p_dot = Vec3::Zero();  // true platform state
  Vec3 p_ref = Vec3::Zero(), v_ref = Vec3::Zero();
};

struct TrackingMetrics {
  // Over the samples t = k / rate, k = 0 .. N-1, of |p_ref - p| and |v_ref - p_dot|
  // with p the true platform state (Elkady eqs. 22-23).
  double position_rmse = 0.0;   // m
  double velocity_rmse = 0.0;   // m/s
  double position_max = 0.0;    // m
  double velocity_max = 0.0;    // m/s
  Vec3 position_rms_axis = Vec3::Zero();
  long samples = 0;
  long saturated_samples = 0;   // periods in which some actuator hit its limit
};

struct RunResult {
  TrackingMetrics metrics;
  std::vector<LogRow> log;
  Status fault;               // why the run stopped early, if it did
  double fault_time = 0.0;    // s
  [[nodiscard]] bool ok() const noexcept { return fault.ok(); }
};

RunResult run_closed_loop(const ctl::Controller& controller, Plant& plant,
                          const ctl::Trajectory& trajectory, const LoopOptions& options);

// The log as a motion data set of docs/data-formats.md (t, d, v, f; no acceleration).
io::MotionData to_motion_data(const std::vector<LogRow>& log, double rate_hz);
// Motion log of docs/data-formats.md (kind = motion), written
// atomically (io::write_motion).
void write_motion_log(const std::string& path, const std::vector<LogRow>& log, double rate_hz);

}  // namespace cpm::sim
