// SPDX-License-Identifier: Apache-2.0
// What the path module's sources share and nobody else needs.
#pragma once

#include <array>

#include "cpm/path/plan.hpp"

namespace cpm::path::detail {

// The quintic Hermite interpolant over [0, h] of y0, y0', y0'' at 0 and
// y1, y1', y1'' at h (y = {y0, y0', y0'', y1, y1', y1''}), at tau * h
// (tau in [0, 1]): its value and first two derivatives. noexcept.
void quintic_hermite(const std::array<double, 6>& y, double h, double tau, double& v, double& d1, double& d2) noexcept;

// Arc length of a quintic Bezier curve (m).
double bezier_length(const std::array<Vec3, 6>& P);

// A plan's sample at t from its geometry and knots (Plan::sample_path).
PathSample sample(const Geometry& g, const std::vector<Knot>& knots, double dt, double t, SampleCost* cost) noexcept;

}  // namespace cpm::path::detail
