// SPDX-License-Identifier: Apache-2.0
// Elkady's Table 3 under the reference conditions of docs/model.md: the paper's
// circle from rest at P1, each of the four laws with its Table 3 gains,
// control at 1 kHz with zero-order hold, the plant integrated by RK4 in 10
// sub-steps, RMSE over the 4000 samples t = k ms. Controller model and true
// machine are both the nominal machine of docs/model.md.
#pragma once

#include <array>

#include "cpm/sim/closed_loop.hpp"

namespace cpm::sim {

struct Table3Row {
  ctl::ControlLaw law;
  ctl::Gains gains;
  TrackingMetrics metrics;
  Status fault;
  double paper_position_rmse;        // m, Elkady Table 3
  double paper_velocity_rmse;        // m/s, Elkady Table 3
  double independent_position_rmse;  // m, docs/model.md's independent re-implementation
};

std::array<Table3Row, 4> reproduce_table3();

}  // namespace cpm::sim
