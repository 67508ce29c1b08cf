// SPDX-License-Identifier: Apache-2.0
#include "cpm/path/limits.hpp"

#include <cmath>
#include <sstream>

namespace cpm::path {
namespace {

void positive(double v, const char* name, double max = 1e9) {
  if (!std::isfinite(v) || v <= 0.0 || v > max) {
    std::ostringstream o;
    o << "path: " << name << " must be > 0 and <= " << max << ", got " << v;
    throw Error(o.str());
  }
}

}  // namespace

const char* limit_name(Limit l) noexcept {
  switch (l) {
    case Limit::none: return "none";
    case Limit::feed: return "feed";
    case Limit::velocity: return "velocity";
    case Limit::acceleration: return "acceleration";
    case Limit::tangential: return "tangential_acceleration";
    case Limit::curvature_step: return "curvature_step";
    case Limit::actuator_velocity: return "actuator_velocity";
    case Limit::actuator_acceleration: return "actuator_acceleration";
    case Limit::actuator_force: return "actuator_force";
    case Limit::stop: return "stop";
  }
  return "?";
}

void PlannerOptions::validate() const {
  positive(cartesian.velocity, "cartesian.velocity (m/s)", 10.0);
  positive(cartesian.acceleration, "cartesian.acceleration (m/s^2)", 1e3);
  positive(cartesian.jerk, "cartesian.jerk (m/s^3)", 1e6);
  positive(cartesian.acceleration_step, "cartesian.acceleration_step (m/s^2)", 1e3);
  for (int i = 0; i < 3; ++i) {
    positive(actuators.velocity[i], "actuators.velocity (m/s)", 10.0);
    positive(actuators.acceleration[i], "actuators.acceleration (m/s^2)", 1e3);
    positive(actuators.force[i], "actuators.force (N)", 1e5);
  }
  if (!(actuators.force_reserve >= 0.0 && actuators.force_reserve < 1.0))
    throw Error("path: actuators.force_reserve must be in [0, 1)");
  positive(grid_step, "grid_step (m)", 0.1);
  positive(knot_period, "knot_period (s)", 0.1);
  if (max_repairs < 0 || max_repairs > 100) throw Error("path: max_repairs must be in [0, 100]");
}

}  // namespace cpm::path
