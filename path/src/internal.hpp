// What the path module's sources share and nobody else needs.
#pragma once

#include <array>

#include "cpm/path/plan.hpp"

namespace cpm::path::detail {

// Arc length of a quintic Bezier curve (m).
double bezier_length(const std::array<Vec3, 6>& P);

// A plan's sample at t from its geometry and knots (Plan::sample_path).
PathSample sample(const Geometry& g, const std::vector<Knot>& knots, double dt, double t, SampleCost* cost) noexcept;

}  // namespace cpm::path::detail
