// SPDX-License-Identifier: Apache-2.0
#include "cpm/kinematics/workspace.hpp"

#include <cmath>
#include <numbers>

namespace cpm::kin {

void Strokes::validate() const {
  for (int i = 0; i < 3; ++i) {
    if (!std::isfinite(min[i]) || !std::isfinite(max[i]) || !(max[i] > min[i]))
      throw Error("strokes, actuator " + std::to_string(i + 1) +
                  ": need finite min < max, got [" + std::to_string(min[i]) + ", " +
                  std::to_string(max[i]) + "] m");
  }
}

Status check_strokes(const Strokes& s, const Vec3& d) noexcept {
  if (!all_finite(d)) return Status::failure(Fault::not_finite);
  for (int i = 0; i < 3; ++i) {
    if (d[i] < s.min[i]) return Status::failure(Fault::stroke_low, i, d[i], s.min[i]);
    if (d[i] > s.max[i]) return Status::failure(Fault::stroke_high, i, d[i], s.max[i]);
  }
  return {};
}

Status check_pose(const KinematicModel& m, const Strokes& s, const Vec3& p,
                  const KinematicInputs& in, WorkspaceMargins* margins) noexcept {
  if (!all_finite(p)) return Status::failure(Fault::not_finite);
  // Limbs first: a point out of reach has no meaningful actuator position.
  LimbPose pose;
  if (Status st = solve_limbs(m.limbs, p, pose); !st) return st;
  Vec3 d;
  if (Status st = inverse(m, p, in, d); !st) return st;
  if (Status st = check_strokes(s, d); !st) return st;
  if (margins) {
    margins->stroke_low = d - s.min;
    margins->stroke_high = s.max - d;
    const Vec3 elbow = pose.elbow();
    for (int i = 0; i < 3; ++i) margins->elbow[i] = std::min(std::abs(elbow[i]), std::numbers::pi - std::abs(elbow[i]));
  }
  return {};
}

}  // namespace cpm::kin
