// SPDX-License-Identifier: Apache-2.0
// A velocity-ramped reference: the generator behind jogging, the daemon's
// homing moves and the reference while the actuators are held one by one
// (before homing). Each period the velocity moves toward a target velocity
// at a bounded acceleration and the position follows it; the reference
// brakes in time for the ends of a box it must stay in, and never leaves it.
//
// One generator serves both spaces: coordinates are the actuators'
// displacements d (m, m/s) or the platform's position in the machine frame
// (m, m/s), as the caller uses it. Plain data, allocation-free, noexcept.
#pragma once

#include <limits>

#include "cpm/kinematics/types.hpp"

namespace cpm::daemon {

struct Ramp {
  Vec3 p = Vec3::Zero();  // reference position
  Vec3 v = Vec3::Zero();  // reference velocity
  Vec3 a = Vec3::Zero();  // reference acceleration over the last period

  // The box the reference stays in (per coordinate); unbounded by default.
  static Vec3 unbounded_low() noexcept { return Vec3::Constant(-std::numeric_limits<double>::infinity()); }
  static Vec3 unbounded_high() noexcept { return Vec3::Constant(std::numeric_limits<double>::infinity()); }

  // At rest at `at`.
  void reset(const Vec3& at) noexcept;
  // One period `dt` (s) toward `v_target`, changing the velocity by at most
  // `accel` * dt as a vector (so a diagonal jog keeps its direction), and
  // within [lo, hi]: a coordinate's velocity toward an end is held to what
  // `accel` can still stop before it.
  void step(const Vec3& v_target, double accel, const Vec3& lo, const Vec3& hi, double dt) noexcept;
  // One period toward `target` (per coordinate), at most `speed` (m/s) and
  // `accel`: arrives at rest, exactly, without overshoot (the position
  // advances by the new velocity here, so that the braking curve is exact
  // in discrete time).
  void step_to(const Vec3& target, double speed, double accel, double dt) noexcept;
  // Move the reference (and the platform it describes) by `delta` without
  // motion: a coordinate's zero was redefined (homing).
  void shift(const Vec3& delta) noexcept { p += delta; }
  [[nodiscard]] bool at_rest() const noexcept { return v.isZero(0.0); }
  // The distance still travelled if the target velocity dropped to zero now
  // at `accel` (m, along the velocity).
  [[nodiscard]] double stopping_distance(double accel) const noexcept;
};

}  // namespace cpm::daemon
