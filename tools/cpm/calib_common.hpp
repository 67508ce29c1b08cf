// SPDX-License-Identifier: Apache-2.0
// Helpers shared by the calibration subcommands (calibrate, circular-test,
// plan-poses, simulate-measurement, kim-experiment).
#pragma once

#include <cmath>
#include <sstream>
#include <string>
#include <vector>

#include "cli.hpp"
#include "cpm/control/trajectory.hpp"
#include "cpm/kinematics/types.hpp"

namespace cpm::cli {

inline std::vector<double> calib_numbers(const std::string& what, const std::string& text) {
  std::vector<double> v;
  std::istringstream is(text);
  std::string part;
  while (std::getline(is, part, ',')) {
    double x = 0;
    if (!CLI::detail::lexical_cast(part, x) || !std::isfinite(x))
      throw UsageError(what + ": '" + text + "' is not a comma-separated list of finite numbers");
    v.push_back(x);
  }
  return v;
}

inline Vec3 calib_point(const std::string& what, const std::string& text) {
  const auto v = calib_numbers(what, text);
  if (v.size() != 3) throw UsageError(what + ": expected three numbers x,y,z in metres, got '" + text + "'");
  return Vec3(v[0], v[1], v[2]);
}

// A point as the help shows a default: "0.430,0.430,0.400" (m).
inline std::string point_text(const Vec3& v) {
  return CLI::detail::to_string(v.x()) + "," + CLI::detail::to_string(v.y()) + "," + CLI::detail::to_string(v.z());
}

inline ctl::CirclePlane calib_plane(const std::string& text) {
  if (text == "xy") return ctl::CirclePlane::xy;
  if (text == "yz") return ctl::CirclePlane::yz;
  if (text == "zx") return ctl::CirclePlane::zx;
  throw UsageError("--plane must be xy, yz or zx, got '" + text + "'");
}

}  // namespace cpm::cli
