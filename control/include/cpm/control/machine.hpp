// SPDX-License-Identifier: Apache-2.0
// The machine model: one constant description used by the controller (the
// model it believes), the simulator (the true machine) and identification
// (the numbers it fits). As in Pinocchio, the model is constant data and
// the algorithms are functions over it; per-cycle values live in the
// caller's preallocated structs.
//
// Dynamics (Elkady eqs. 4-14, docs/model.md), in the machine frame with z down
// and q = p the platform centre (m):
//     F = M(q) q_dd + G(q, q_d) q_d + K(q)
//     M = 2A I + 2B Gamma^T Gamma,  G = 2B Gamma^T Gamma_dot,
//     K = -(0, 0, E) + C Gamma^T (-cos t11, sin t21, 0)
// F is the force on the platform in the machine frame (N). Actuator forces
// are F_d = J^T F + sum of the additive effects, J = dp/dd of the calibrated
// kinematics.
//
// actuator_inertia effects (m_i kg on actuator i: rotor, coupling, screw)
// add m_i d_dd_i to actuator i's force. With d_dd = J^-1 p_dd + (d/dt J^-1) p_dot
// that is, on the platform, M gains J^-T diag(m) J^-1 and G p_dot gains
// J^-T diag(m) (d/dt J^-1) p_dot. Here J is the planes' (the calibrated
// kinematics without its kinematic effects), constant, so the second term is
// zero; kinematic effects bend J by a relative 1e-4..1e-2, which changes the
// reflected force by that share only (docs/effects.md, actuator_inertia).
#pragma once

#include <string_view>
#include <vector>

#include "cpm/control/effects.hpp"
#include "cpm/control/user_effects.hpp"
#include "cpm/kinematics/kinematic_effects.hpp"
#include "cpm/kinematics/limbs.hpp"
#include "cpm/kinematics/plane_model.hpp"
#include "cpm/kinematics/workspace.hpp"

namespace cpm::ctl {

inline constexpr double kGravity = 9.81;  // m/s^2, along +z (down)

// Elkady's Table 2 (kg): m1 first link of a limb (uniform rod), m2 second
// link (split between M_i and B_i), m3 prismatic joint and actuator, m4 tool.
struct LinkMasses {
  double m1 = 1.892994;
  double m2 = 0.695528;
  double m3 = 0.2;
  double m4 = 0.3;
};

// The four constants in which the dynamics is linear (docs/model.md):
// A (kg), B (kg m^2), C (N m), E (N).
struct InertiaConstants {
  double A = 0, B = 0, C = 0, E = 0;
  static InertiaConstants from_masses(const LinkMasses& m, double L1);
};

struct MachineModel {
  kin::KinematicModel kinematics = kin::KinematicModel::nominal();
  kin::Strokes strokes;
  LinkMasses masses;
  DynamicEffects effects;
  std::vector<UserEffect> user_effects;  // table and expression effects (user_effects.hpp)
  double force_limit = 120.0;  // |F_i| per actuator (N)

  static MachineModel elkady();  // the nominal machine of docs/model.md
  void validate() const;         // throws Error saying what and where
};

// Add an effect of docs/effects.md to a model by its stable name: kinematic ones
// (backlash, cyclic_error, ...) to limb `axis` (0..2) of the kinematics,
// dynamic ones to the effect list (axis -1 for machine-wide ones). Values in
// the order and units of docs/effects.md. Throws Error naming the effect and what
// is wrong (unknown name, wrong number of values, out of bounds).
void add_effect(MachineModel& model, std::string_view name, int axis,
                const std::vector<double>& values);

// Everything the dynamics computes at one state.
struct RigidBodyTerms {
  Mat3 M = Mat3::Zero();     // inertia matrix (kg)
  Vec3 Gv = Vec3::Zero();    // G(q, q_d) q_d (N)
  Vec3 K = Vec3::Zero();     // gravity (N)
  kin::LimbMotion limbs;     // limb angles, Gamma, Gamma_dot
};

// The platform seen through the actuators' encoders.
struct TaskState {
  Vec3 p = Vec3::Zero();      // platform point (m)
  Vec3 p_dot = Vec3::Zero();  // platform velocity (m/s)
  Mat3 J = Mat3::Identity();  // dp/dd
};

// A validated, prepared machine. Construction is the only step that can
// fail or allocate; the member functions are noexcept and allocation-free,
// fit for the control cycle.
class Machine {
 public:
  explicit Machine(MachineModel model);

  [[nodiscard]] const MachineModel& model() const noexcept { return model_; }
  [[nodiscard]] const kin::KinematicModel& kinematics() const noexcept { return model_.kinematics; }
  [[nodiscard]] const kin::LimbGeometry& limbs() const noexcept { return model_.kinematics.limbs; }
  // Effective constants: from the masses, plus inertia_error and payload_mass.
  [[nodiscard]] const InertiaConstants& inertia() const noexcept { return inertia_; }
  // Per actuator, the factor (1 + k) by which the drive scales its command.
  [[nodiscard]] const Vec3& drive_gain() const noexcept { return drive_gain_; }
  // Per actuator, the reflected inertia m_i (kg) of its actuator_inertia effects, and
  // J^-T diag(m) J^-1 (kg), the platform-space inertia it adds to M (see the top).
  [[nodiscard]] const Vec3& reflected_masses() const noexcept { return reflected_mass_; }
  [[nodiscard]] const Mat3& reflected_inertia() const noexcept { return reflected_inertia_; }
  // Dead time between a command and the force it makes (s): actuation_delay effects summed.
  [[nodiscard]] double actuation_delay() const noexcept { return actuation_delay_; }
  [[nodiscard]] double force_limit() const noexcept { return model_.force_limit; }
  [[nodiscard]] bool has_additive_effects() const noexcept { return additive_effects_; }
  // Without kinematic effects the planes make J = dp/dd constant: prepared
  // once, with its inverse, so the plant and the controller skip the solve.
  [[nodiscard]] bool has_constant_jacobian() const noexcept { return constant_jacobian_; }
  [[nodiscard]] const Mat3& constant_jacobian() const noexcept { return J_; }
  [[nodiscard]] const Mat3& constant_jacobian_inverse() const noexcept { return J_inv_; }

  // M, G q_d and K at (p, p_dot), M with the reflected inertia of the actuators.
  // Fails outside the limbs' reach or at a singularity.
  Status rigid_body(const Vec3& p, const Vec3& p_dot, RigidBodyTerms& out) const noexcept;
  // Platform force for a motion: M p_dd + G p_dot + K (N).
  Status inverse_dynamics(const Vec3& p, const Vec3& p_dot, const Vec3& p_dd,
                          Vec3& force) const noexcept;
  // Platform acceleration (m/s^2) under actuator commands (N), the plant's
  // equation with this machine as the truth:
  //   d = IK(p), d_dot = J^-1 p_dot, F_d = (1 + k) F_cmd - effects(d, d_dot),
  //   p_dd = M^-1 (J^-T F_d - G p_dot - K).
  // The command is the one acting now: actuation_delay is the caller's
  // (integrate_delayed in actuation.hpp).
  Status forward_dynamics(const Vec3& p, const Vec3& p_dot, const Vec3& force_command,
                          const kin::KinematicInputs& in, Vec3& p_dd) const noexcept;
  // The actuator command (N) that holds the platform at rest at p: the
  // weight through J^T, the effects at rest, over the drive gain. What the
  // drives were applying before a motion that starts at rest.
  Status holding_command(const Vec3& p, const kin::KinematicInputs& in, Vec3& command) const noexcept;
  // Sum of the additive effect forces on each actuator (N): the library's and
  // the user's, these at zero acceleration and t = 0.
  [[nodiscard]] Vec3 effect_forces(const Vec3& d, const Vec3& d_dot) const noexcept;
  // The same with the axes' accelerations d_dd (m/s^2) and time t (s), which
  // user expression effects may read (a1..a3, t).
  [[nodiscard]] Vec3 effect_forces(const Vec3& d, const Vec3& d_dot, const Vec3& d_dd,
                                   double t) const noexcept;
  [[nodiscard]] bool has_user_effects() const noexcept { return !user_.empty(); }
  // Some user expression reads a1..a3 (then forward_dynamics solves for p_dd).
  [[nodiscard]] bool user_effects_use_acceleration() const noexcept { return user_.uses_acceleration(); }
  // J = dp/dd at (d, p): the prepared constant one when the planes carry no
  // kinematic effects, else kin::jacobian.
  Status jacobian(const Vec3& d, const Vec3& p, const kin::KinematicInputs& in,
                  Mat3& J) const noexcept;
  // J^-1 = dd/dp, the same way (kin::inverse_jacobian: no inversion).
  Status inverse_jacobian(const Vec3& d, const Vec3& p, const kin::KinematicInputs& in,
                          Mat3& J_inv) const noexcept;
  // Platform state from encoder position and velocity through the calibrated kinematics.
  Status task_state(const Vec3& d, const Vec3& d_dot, const kin::KinematicInputs& in,
                    TaskState& out) const noexcept;

  // Energies of Elkady eqs. 4-5 (J), for checks and diagnostics; the kinetic
  // energy includes the actuators' 1/2 sum m_i d_dot_i^2.
  Status kinetic_energy(const Vec3& p, const Vec3& p_dot, double& T) const noexcept;
  Status potential_energy(const Vec3& p, double& V) const noexcept;

 private:
  MachineModel model_;
  UserEffectsRuntime user_;
  InertiaConstants inertia_;
  Vec3 drive_gain_ = Vec3::Ones();
  Vec3 reflected_mass_ = Vec3::Zero();
  Mat3 reflected_inertia_ = Mat3::Zero();
  double actuation_delay_ = 0.0;
  bool additive_effects_ = false;
  bool constant_jacobian_ = false;
  Mat3 J_ = Mat3::Identity(), J_inv_ = Mat3::Identity();
};

}  // namespace cpm::ctl
