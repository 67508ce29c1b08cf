// SPDX-License-Identifier: Apache-2.0
// The three PRRR limbs: where their links are for a given platform point.
//
// Geometry of docs/model.md (read from Elkady's matrix Gamma):
//   limb 1 (drives x) moves in the (y, z) plane: A1 = (0, 0),
//          M1 = A1 + L1 (cos t11, sin t11),  B1 = (y - L, z)
//   limb 2 (drives y) moves in the (x, z) plane: A2 = (0, 0),
//          M2 = A2 + L1 (sin t21, cos t21),  B2 = (x - L, z)
//   limb 3 (drives z) moves in the (x, y) plane: A3 = (0, D),
//          M3 = A3 + L1 (cos t31, -sin t31), B3 = (x, y + L)
// with |B_i - M_i| = L2. Lengths in metres, angles in radians, p in the
// machine frame (z down).
//
// Each limb has two assembly modes (the elbow on one side or the other of
// the line A_i B_i). The default modes are the ones docs/model.md fixes: at
// p = (0.600, 0.425, 0.300) they give t11 = 89.41 deg, t21 = 19.17 deg,
// t31 = 2.89 deg. A mode is a fixed branch of the closed-form solution, so
// the angles stay continuous along any motion that avoids the singularity.
#pragma once

#include <array>

#include "cpm/kinematics/types.hpp"

namespace cpm::kin {

struct LimbGeometry {
  double L = 0.105;    // half side of the platform square (m)
  double L1 = 0.5;     // first link A_i M_i (m)
  double L2 = 0.373;   // second link M_i B_i (m)
  double D = 0.9144;   // offset of limb 3's base along y (m)
  // Assembly mode of each limb: +1 or -1, the sign of the branch of the
  // closed-form solution. default_modes() gives those of docs/model.md.
  std::array<int, 3> mode{+1, +1, +1};
  // A limb whose elbow is within this angle of straight or folded is
  // reported as near its singularity (rad).
  double singularity_margin = 0.05;

  static LimbGeometry elkady();  // Table 1 of Elkady with the default modes
};

// Everything the dynamics needs of the limbs at one pose: the cosine and
// sine of the first-joint angles theta (t11, t21, t31) and of the signed
// elbow angles phi_i (from A->M to M->B, with theta's orientation), and
// Gamma = d theta / d p. The dynamics needs only cosines and sines, which
// the links' directions give without trigonometry; the angles themselves
// (atan2) are computed on demand, for reports and tests.
struct LimbPose {
  Vec3 cos_theta = Vec3::Ones(), sin_theta = Vec3::Zero();
  Vec3 cos_elbow = Vec3::Ones(), sin_elbow = Vec3::Zero();
  Mat3 Gamma = Mat3::Zero();
  [[nodiscard]] Vec3 theta() const noexcept;  // rad, in (-pi, pi]
  [[nodiscard]] Vec3 elbow() const noexcept;  // rad, in (-pi, pi]
};

// The same with the time derivative of Gamma along a velocity p_dot.
struct LimbMotion {
  LimbPose pose;
  Vec3 theta_dot = Vec3::Zero();
  Mat3 Gamma_dot = Mat3::Zero();
};

// Solve the limbs at p. Fails (limb_unreachable, near_singularity,
// not_finite) with the limb index; never returns a wrong number silently.
Status solve_limbs(const LimbGeometry& g, const Vec3& p, LimbPose& out) noexcept;

// Solve the limbs at p and their rates for the platform velocity p_dot
// (closed-form Gamma_dot, no finite differences).
Status solve_limb_motion(const LimbGeometry& g, const Vec3& p, const Vec3& p_dot,
                         LimbMotion& out) noexcept;

// Gradient of the elbow angles with respect to p (row i = d phi_i / d p),
// used by the limb-twist effect.
Status elbow_gradient(const LimbGeometry& g, const Vec3& p, Mat3& out) noexcept;

// The modes of docs/model.md, found from its reference pose and angles.
std::array<int, 3> default_assembly_modes(const LimbGeometry& g);

}  // namespace cpm::kin
