// SPDX-License-Identifier: Apache-2.0
// A per-axis pitch table: the error e(d) of the effective displacement
// against the axis position, the form every CNC controller uses for lead
// screw compensation (docs/effects.md, "Effects you add"):
//     d~_i = d_i + e_i(d_i)
// e is the linear interpolation of (node, value) pairs, held constant beyond
// the first and last node. Fixed capacity, so a KinematicModel stays plain
// data that the control cycle reads without allocating.
#pragma once

#include <array>
#include <string>

namespace cpm::kin {

struct PitchTable {
  static constexpr int kCapacity = 128;  // nodes per axis
  int size = 0;                          // 0: no table
  std::array<double, kCapacity> node{};  // axis position d (m), strictly increasing
  std::array<double, kCapacity> error{}; // e(d) (m)

  [[nodiscard]] bool empty() const noexcept { return size == 0; }
  // e(d) (m) and, when `slope` is given, de/dd (1): the slope of the segment
  // d lies in (the right one at a node), 0 beyond the ends.
  [[nodiscard]] double operator()(double d, double* slope = nullptr) const noexcept;
  // Throws Error ("pitch_table: ...") when there is one node only, more than
  // kCapacity, a value that is not finite, nodes not strictly increasing, or
  // an error so steep (|de/dd| >= 0.5) that d~ would no longer grow with d.
  void validate() const;
};

// Linear interpolation of (x, y), held constant beyond the ends: the rule
// shared by the pitch table and the dynamic `table` effect. x strictly
// increasing, n >= 1. slope (when given): dy/dx of the segment, 0 outside.
double interpolate_held(const double* x, const double* y, int n, double at,
                        double* slope = nullptr) noexcept;

}  // namespace cpm::kin
