// SPDX-License-Identifier: Apache-2.0
// Workspace check: does a platform point lie where the machine can go?
//
// Three kinds of limit, reported with the limb or actuator that breaks it:
// the actuator strokes (through the inverse kinematics of the model), the
// reach of each limb (|A_i B_i| between |L1 - L2| and L1 + L2) and the
// distance of each limb's elbow from straight or folded (the singularity of
// Elkady's Gamma, where the limb's first joint would have to turn infinitely
// fast).
#pragma once

#include "cpm/kinematics/limbs.hpp"
#include "cpm/kinematics/plane_model.hpp"

namespace cpm::kin {

struct Strokes {
  Vec3 min = Vec3::Zero();                 // (m)
  Vec3 max = Vec3(0.400, 0.400, 0.300);    // (m), docs/model.md
  void validate() const;
};

// Distances of a pose to each limit, for a planner or a safety monitor.
struct WorkspaceMargins {
  Vec3 stroke_low = Vec3::Zero();   // d_i - min_i (m)
  Vec3 stroke_high = Vec3::Zero();  // max_i - d_i (m)
  Vec3 elbow = Vec3::Zero();        // angle of each elbow from straight or folded (rad)
};

// Check an actuator position (encoder readings) against the strokes.
Status check_strokes(const Strokes& s, const Vec3& d) noexcept;

// Check a platform point: strokes through the inverse kinematics of `m`,
// limb reach and singularity distance through m.limbs. `margins` (optional)
// receives the distances to each limit when the pose is valid.
Status check_pose(const KinematicModel& m, const Strokes& s, const Vec3& p,
                  const KinematicInputs& in, WorkspaceMargins* margins = nullptr) noexcept;

}  // namespace cpm::kin
