// SPDX-License-Identifier: Apache-2.0
// What the path planner must respect: the platform's motion along the path
// (machine frame) and, in the actuator-aware mode, what each of the three
// actuators can do (velocity, acceleration, force), reached through the
// machine's inverse kinematics, Jacobian and dynamics.
//
// Plain data, so that the daemon can fill it from its configuration and the
// model (limits.velocity, limits.acceleration, min(limits.force, the model's
// force_limit)) without the planner knowing either.
#pragma once

#include <cstdint>

#include "cpm/kinematics/types.hpp"

namespace cpm::path {

enum class PlanMode : std::uint8_t {
  cartesian_only,  // feed, |v|, |a| and jerk of the platform only: what a serial X-Y-Z controller plans
  actuator_aware,  // feed, |v| and jerk of the platform; each actuator's velocity, acceleration and force
};

// Limits of the platform centre's motion (machine frame).
struct CartesianLimits {
  double velocity = 0.5;       // |v| (m/s); the speed of rapids (G0)
  double acceleration = 5.0;   // |a| (m/s^2); cartesian_only mode
  double jerk = 1000.0;        // along the path, |d3s/dt3| (m/s^3)
  // Where the programmed path's curvature jumps (a line meeting an arc
  // tangentially), the acceleration steps by v^2 |dk|: the speed there is
  // held to keep that step below this (m/s^2). The default is what the jerk
  // limit builds up in 1 ms, one control period.
  double acceleration_step = 1.0;
};

// Limits of actuator i, on its displacement d_i (the encoders' axis).
struct ActuatorLimits {
  Vec3 velocity = Vec3::Constant(0.5);       // |d_dot_i| (m/s)
  Vec3 acceleration = Vec3::Constant(30.0);  // |d_dd_i| (m/s^2)
  Vec3 force = Vec3::Constant(120.0);        // |F_i| the drive can give (N)
  // Fraction of the force kept for the controller's feedback: the planned
  // (feedforward) force stays within (1 - force_reserve) force.
  double force_reserve = 0.2;
};

struct PlannerOptions {
  PlanMode mode = PlanMode::actuator_aware;
  CartesianLimits cartesian;
  ActuatorLimits actuators;
  double grid_step = 1e-3;    // m: the planner checks the limits at least this often along the path
  double knot_period = 1e-3;  // s between the prepared plan's knots (the daemon's period)
  int max_repairs = 12;       // rounds of slowing down where the checked plan broke a limit
  void validate() const;      // throws Error saying which option and why
};

// What held the speed down at a stretch of the path.
enum class Limit : std::uint8_t {
  none,
  feed,                   // the programmed feed
  velocity,               // |v| ceiling
  acceleration,           // |a| (cartesian_only)
  tangential,             // the tangential acceleration the jerk limit allows
  curvature_step,         // acceleration_step at a curvature jump
  actuator_velocity,
  actuator_acceleration,
  actuator_force,
  stop,                   // a corner without blend, a dwell, the start or the end
};
const char* limit_name(Limit l) noexcept;  // "feed", "actuator_force", ...

}  // namespace cpm::path
