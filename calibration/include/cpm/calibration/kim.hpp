// SPDX-License-Identifier: Apache-2.0
// Kim's ball-bar experiment (Kim 2005, section 5), reproduced in simulation:
// a true machine carrying Kim's fitted errors (docs/calibration.md, "Kim's
// experiment in simulation"), the QC10's +-0.5 µm on every length, Kim's 32 poses
// commanded through the nominal model; the ball-bar fit; and the circular
// test (XY, radius 150 mm, CCW and CW) before and after calibration beside
// Kim's 534 -> 128 µm.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "cpm/calibration/ballbar.hpp"
#include "cpm/calibration/circular_test.hpp"
#include "cpm/calibration/poses.hpp"
#include "cpm/io/data_files.hpp"

namespace cpm::cal {

inline constexpr double kKimMaxErrorBefore = 534e-6;  // m
inline constexpr double kKimMaxErrorAfter = 128e-6;   // m

// Kim's fitted values in this project's frame (z down, so dq_z changes sign).
BallbarParameters kim_fitted_errors();
Vec3 kim_pivot();  // nominal pivot (0.430, 0.430, 0.530) m

// The true machine: the nominal machine with Kim's planes (ball-bar frame =
// machine frame, n_i = 0); the fixed ball really at kim_pivot() + dq.
ctl::MachineModel kim_true_machine();

struct KimOptions {
  double noise = 0.5e-6;       // half-width of the uniform length error (m): the QC10's +-0.5 µm
  std::uint64_t seed = 1;
  bool circular_test = true;
  CircularTestSpec circle;     // default: XY, radius 150 mm about (430, 430, 400) mm
};

struct ParameterCheck {
  std::string name, unit;
  double truth = 0.0, fitted = 0.0, std_error = 0.0;
  [[nodiscard]] double sigmas() const { return std::abs(fitted - truth) / std_error; }
  [[nodiscard]] bool within_3sigma() const { return std::abs(fitted - truth) <= 3.0 * std_error; }
};

struct KimReproduction {
  std::vector<PlannedPose> poses;
  io::BallbarData data;
  BallbarFit fit;
  std::vector<ParameterCheck> checks;
  bool all_within_3sigma = false;
  bool has_circular_test = false;
  CircularTestResult before, after;
  [[nodiscard]] std::string report() const;   // for people
  [[nodiscard]] std::string json() const;
};

KimReproduction reproduce_kim(const KimOptions& options = {});

}  // namespace cpm::cal
