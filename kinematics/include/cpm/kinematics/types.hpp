// SPDX-License-Identifier: Apache-2.0
// Basic types shared by every module.
//
// Units are SI everywhere inside the project: metres, seconds, newtons,
// radians. The machine frame is the one of docs/model.md: origin on
// the base, x, y, z along the three nominal actuator axes, z pointing down.
#pragma once

#include <Eigen/Dense>

#include <cstdint>
#include <stdexcept>
#include <string>

#include "cpm/kinematics/error.hpp"

namespace cpm {

using Vec3 = Eigen::Vector3d;
using Mat3 = Eigen::Matrix3d;

// Why a real-time computation refused its input. Plain data, no allocation.
enum class Fault : std::uint8_t {
  none = 0,
  not_finite,          // an input was NaN or infinite
  stroke_low,          // actuator displacement below its stroke
  stroke_high,         // actuator displacement above its stroke
  limb_unreachable,    // the limb cannot reach the platform point
  near_singularity,    // the limb's elbow is (almost) straight or folded
  singular_planes,     // the three limb planes do not intersect in one point
  no_convergence,      // an iterative solve did not converge
  history_short,       // a delayed command is older than the command history keeps
};

// Result of a real-time computation. `index` is the limb or actuator (0..2)
// the fault concerns, -1 when it concerns none in particular; `value` and
// `limit` give the offending figure and the bound it broke, in SI units.
struct Status {
  Fault fault = Fault::none;
  std::int8_t index = -1;
  double value = 0.0;
  double limit = 0.0;

  [[nodiscard]] bool ok() const noexcept { return fault == Fault::none; }
  explicit operator bool() const noexcept { return ok(); }
  static Status failure(Fault f, int i = -1, double v = 0.0, double l = 0.0) noexcept {
    return Status{f, static_cast<std::int8_t>(i), v, l};
  }
};

// Short name of a fault ("stroke_high", ...), for logs and JSON.
const char* fault_name(Fault f) noexcept;

// A sentence for people: what broke, on which limb or actuator, by how much
// (in mm or degrees where that reads better). Not for the real-time path.
std::string describe(const Status& s);

inline bool all_finite(const Vec3& v) noexcept { return v.allFinite(); }

}  // namespace cpm
