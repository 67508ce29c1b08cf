// SPDX-License-Identifier: Apache-2.0
#include "cpm/kinematics/types.hpp"

#include <cmath>
#include <numbers>
#include <sstream>

namespace cpm {

const char* fault_name(Fault f) noexcept {
  switch (f) {
    case Fault::none: return "none";
    case Fault::not_finite: return "not_finite";
    case Fault::stroke_low: return "stroke_low";
    case Fault::stroke_high: return "stroke_high";
    case Fault::limb_unreachable: return "limb_unreachable";
    case Fault::near_singularity: return "near_singularity";
    case Fault::singular_planes: return "singular_planes";
    case Fault::no_convergence: return "no_convergence";
    case Fault::history_short: return "history_short";
  }
  return "unknown";
}

std::string describe(const Status& s) {
  std::ostringstream os;
  const int n = s.index + 1;
  switch (s.fault) {
    case Fault::none: return "ok";
    case Fault::not_finite: os << "an input is NaN or infinite"; break;
    case Fault::stroke_low:
      os << "actuator " << n << " at " << s.value * 1e3 << " mm is below its stroke minimum "
         << s.limit * 1e3 << " mm";
      break;
    case Fault::stroke_high:
      os << "actuator " << n << " at " << s.value * 1e3 << " mm is beyond its stroke maximum "
         << s.limit * 1e3 << " mm";
      break;
    case Fault::limb_unreachable:
      os << "limb " << n << " cannot reach the platform: |A B| = " << s.value * 1e3
         << " mm, limit " << s.limit * 1e3 << " mm";
      break;
    case Fault::near_singularity:
      os << "limb " << n << " is near its singularity: elbow " << s.value * 180.0 / std::numbers::pi
         << " deg from straight or folded, margin " << s.limit * 180.0 / std::numbers::pi << " deg";
      break;
    case Fault::singular_planes:
      os << "the limb planes do not meet in one point (det = " << s.value << ")";
      break;
    case Fault::no_convergence:
      os << "an iterative solve did not converge";
      if (s.index >= 0) os << " (limb " << n << ")";
      break;
    case Fault::history_short:
      os << "the command acting under the actuation delay of " << s.value * 1e3
         << " ms is older than the command history keeps";
      break;
  }
  return os.str();
}

}  // namespace cpm
