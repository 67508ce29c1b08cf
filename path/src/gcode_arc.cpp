// SPDX-License-Identifier: Apache-2.0
// Arc centres from I J K or R, with LinuxCNC's tolerances (gcode_internal.hpp).
#include <cmath>
#include <numbers>
#include <sstream>

#include "gcode_internal.hpp"

namespace cpm::path::detail {
namespace {

constexpr double kInch = 0.0254;  // m

std::string length(double m, bool inch) {
  std::ostringstream o;
  o.precision(6);
  o << (inch ? m / kInch : m * 1e3) << (inch ? " in" : " mm");
  return o.str();
}

bool centre_ijk(const ArcInput& in, double radius_tol, double& ca, double& cb, std::string& error) {
  ca = in.absolute ? in.i : in.a0 + in.i;
  cb = in.absolute ? in.j : in.b0 + in.j;
  const double r0 = std::hypot(ca - in.a0, cb - in.b0), r1 = std::hypot(ca - in.a1, cb - in.b1);
  if (r0 < radius_tol || r1 < radius_tol) {
    error = "arc of zero radius";
    return false;
  }
  const double spiral = (in.inch ? 0.002 * kInch : 0.02e-3) * std::numbers::sqrt2;
  const double diff = std::abs(r0 - r1), rel = diff / std::max(r0, r1);
  if (diff > spiral && rel > 1e-3) {
    std::ostringstream o;
    o << "radius to the arc's end " << length(r1, in.inch) << " differs from radius to its start "
      << length(r0, in.inch) << " by " << length(diff, in.inch) << " (" << rel * 100 << " %)";
    error = o.str();
    return false;
  }
  return true;
}

bool centre_r(const ArcInput& in, double radius_tol, double& ca, double& cb, std::string& error) {
  if (in.a0 == in.a1 && in.b0 == in.b1) {
    error = "an R arc needs an end point other than its start";
    return false;
  }
  const double r = std::abs(in.r);
  const double ma = 0.5 * (in.a0 + in.a1), mb = 0.5 * (in.b0 + in.b1);
  double half = std::hypot(ma - in.a1, mb - in.b1);
  if (half - r > radius_tol) {
    error = "radius " + length(r, in.inch) + " is too small to reach the end point";
    return false;
  }
  if (half / r > 1.0 - 1e-12) half = r;  // a half circle, within rounding
  // R > 0: at most half a turn, the centre to the right of the chord for G2.
  const bool right = in.clockwise == (in.r > 0.0);
  const double theta = std::atan2(in.b1 - in.b0, in.a1 - in.a0) + (right ? -0.5 : 0.5) * std::numbers::pi;
  const double offset = r * std::cos(std::asin(half / r));
  ca = ma + offset * std::cos(theta);
  cb = mb + offset * std::sin(theta);
  return true;
}

}  // namespace

bool arc_centre(const ArcInput& in, double& ca, double& cb, std::string& error) {
  const double radius_tol = in.inch ? 0.00005 * kInch : 0.00127e-3;
  return in.has_r ? centre_r(in, radius_tol, ca, cb, error) : centre_ijk(in, radius_tol, ca, cb, error);
}

}  // namespace cpm::path::detail
