// SPDX-License-Identifier: Apache-2.0
// Kinematics of the machine: the calibrated plane model of Kim 2005 plus the
// kinematic effects of docs/effects.md.
//
// Each limb i holds the platform centre P on a plane (Kim eq. 5, with the
// scale c_i as its own parameter, docs/model.md):
//     u_i^T p = (d~_i + d0_i) c_i + n_i
// where u_i is a unit normal, c_i the scale (cos gamma_i in Kim's terms, but
// free so that c_i > 1 is allowed), n_i the projected offset (m) and d~_i the
// effective displacement. With no effects d~_i = d_i, the encoder reading.
// The nominal model (Kim eq. 1) is u_i = e_i, c_i = 1, n_i = 0: p = d + d0.
//
// Frames: p in the machine frame (m, z down), d the actuator displacements
// read by the drives' encoders (m).
#pragma once

#include <array>
#include <cstdint>

#include "cpm/kinematics/limbs.hpp"
#include "cpm/kinematics/pitch_table.hpp"
#include "cpm/kinematics/types.hpp"

namespace cpm::kin {

struct LimbPlane {
  Vec3 normal = Vec3::Zero();  // u_i2, unit vector
  double scale = 1.0;          // c_i (1)
  double offset = 0.0;         // n_i (m)
};

// The kinematic effects of docs/effects.md, one set per limb. Zero means absent.
struct LimbKinematicEffects {
  double backlash = 0.0;             // b (m)
  double cyclic_amplitude = 0.0;     // a (m)
  double cyclic_wavelength = 0.0;    // lambda (m); needed when a != 0
  double cyclic_phase = 0.0;         // phi (rad)
  double guide_ka = 0.0;             // k_a (rad/m), along the lower other axis
  double guide_kb = 0.0;             // k_b (rad/m), along the higher other axis
  double twist = 0.0;                // alpha (rad)
  double thermal_expansion = 0.0;    // e (1)
  double thermal_time_constant = 0.0;// tau (s); needed when e != 0
  double actuator_scale = 0.0;       // s (1)
  PitchTable pitch_table;            // e(d) (m): d~ = d + e(d), a user-added table

  [[nodiscard]] bool any() const noexcept;
};

// What besides the encoder readings the effective displacement depends on.
struct KinematicInputs {
  std::array<std::int8_t, 3> dir{+1, +1, +1};  // direction each axis last moved (+-1)
  double t = 0.0;                              // time since the machine was cold (s)
};

// Keeps the direction each axis last moved in (for backlash): an axis whose
// speed is below `threshold` keeps its last direction. Real-time safe.
struct DirectionTracker {
  double threshold = 1e-6;  // m/s
  void update(const Vec3& d_dot, KinematicInputs& in) const noexcept {
    for (int i = 0; i < 3; ++i) {
      if (d_dot[i] > threshold) in.dir[i] = +1;
      if (d_dot[i] < -threshold) in.dir[i] = -1;
    }
  }
};

struct KinematicModel {
  std::array<LimbPlane, 3> planes{};
  std::array<LimbKinematicEffects, 3> effects{};
  Vec3 d0 = Vec3(0.2250, 0.2250, 0.2268);  // nominal actuator offsets (m), Kim Table 1
  LimbGeometry limbs = LimbGeometry::elkady();  // needed by the limb-twist effect

  static KinematicModel nominal();
  // Throws Error naming the parameter when the model is not usable: a normal
  // that is not unit length, a non-positive scale, planes that do not meet in
  // a point, a non-finite number, an effect with a missing wavelength.
  void validate() const;
  [[nodiscard]] bool has_twist() const noexcept;
};

// Forward kinematics: encoder readings -> platform point. With the limb-twist
// effect the plane offsets depend on p, solved by a short fixed-point
// iteration (a contraction of factor ~alpha*L2, a few iterations).
Status forward(const KinematicModel& m, const Vec3& d, const KinematicInputs& in,
               Vec3& p) noexcept;
// Inverse kinematics (Kim eq. 7 with the effects): platform point -> encoder
// readings. Each limb is a scalar equation in d_i, solved by Newton's method.
// With J_inv, also dd/dp at the result (as inverse_jacobian gives it): the
// Newton solve has its ingredients at hand.
Status inverse(const KinematicModel& m, const Vec3& p, const KinematicInputs& in,
               Vec3& d, Mat3* J_inv = nullptr) noexcept;
// J = dp/dd at the pose (d, p), p = forward(d). Maps actuator velocities to
// platform velocities; J^T maps platform forces to actuator forces.
Status jacobian(const KinematicModel& m, const Vec3& d, const Vec3& p, const KinematicInputs& in,
                Mat3& J) noexcept;
// J^-1 = dd/dp at the pose: what the plane equations give directly (no
// inversion), for a simulator that needs actuator rates and forces from the
// platform's.
Status inverse_jacobian(const KinematicModel& m, const Vec3& d, const Vec3& p, const KinematicInputs& in,
                        Mat3& J_inv) noexcept;

// Effective displacement d~_i and its derivative with respect to d_i.
double effective_displacement(const LimbKinematicEffects& e, double d, int dir, double t,
                              double* d_dd = nullptr) noexcept;
// Effective plane normal u~_i and its derivative with respect to d_i.
Vec3 effective_normal(const LimbKinematicEffects& e, int limb, const Vec3& u, double d,
                      Vec3* du_dd = nullptr) noexcept;

}  // namespace cpm::kin
