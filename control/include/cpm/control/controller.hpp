// The four control laws of Elkady section 4, with the actuator force limit.
//
// Errors and gains:
//  * The PD laws act on the actuated joints, as in the paper (eq. 15):
//    e_d = d_ref - d with d_ref = IK(p_ref) through the calibrated inverse
//    kinematics, and e_d_dot = J_ref^-1 v_ref - d_dot.
//  * Their model terms (gravity K(q_d), eq. 16; full feedforward, eq. 17)
//    are platform forces at the reference, mapped to the actuators by J_ref^T,
//    plus the model's additive effects at the reference.
//  * Computed torque (eq. 18) linearises in task space: with p, p_dot from the
//    calibrated forward kinematics of the encoders,
//    F_p = M(p) (a_ref + Kd (v_ref - p_dot) + Kp (p_ref - p)) + G(p, p_dot) p_dot + K(p),
//    F_d = J^T F_p + effects(d, d_dot).
// Every law then divides by the model's drive gain (force_gain effect) and
// clamps each actuator to +-force_limit. With the nominal kinematics J = I
// and all of this reduces to the paper's equations.
#pragma once

#include <optional>
#include <string_view>

#include "cpm/control/machine.hpp"
#include "cpm/control/trajectory.hpp"

namespace cpm::ctl {

enum class ControlLaw : std::uint8_t { pd, pd_gravity, pd_feedforward, computed_torque };

const char* law_name(ControlLaw law) noexcept;  // "pd", "pd_gravity", ...
std::optional<ControlLaw> law_from_name(std::string_view name) noexcept;

struct Gains {
  Vec3 kp = Vec3::Zero();  // PD laws: N/m; computed torque: 1/s^2
  Vec3 kd = Vec3::Zero();  // PD laws: N s/m; computed torque: 1/s
  void validate() const;
};

// The gains of Elkady's Table 3 for each law.
Gains table3_gains(ControlLaw law) noexcept;

struct ControlInput {
  Vec3 d = Vec3::Zero();       // encoder positions (m)
  Vec3 d_dot = Vec3::Zero();   // encoder velocities (m/s)
  kin::KinematicInputs kin;    // direction of motion, time (for kinematic effects)
  TrajectorySample ref;        // reference of the platform centre
};

struct ControlOutput {
  Vec3 force = Vec3::Zero();            // actuator commands after the limit (N)
  Vec3 force_unlimited = Vec3::Zero();  // before it (N)
  std::array<bool, 3> saturated{};      // which actuators hit the limit
  TaskState estimate;                   // platform state from the encoders
  Vec3 d_ref = Vec3::Zero();            // actuator reference (m)
  Vec3 d_dot_ref = Vec3::Zero();        // actuator velocity reference (m/s)
};

class Controller {
 public:
  // The controller keeps a reference to `model`: it must outlive it.
  Controller(const Machine& model, ControlLaw law, const Gains& gains);

  // One control step: allocation-free and noexcept. On failure (reference
  // or state outside the model's workspace, NaN) `out.force` is zero and the
  // status says why.
  Status step(const ControlInput& in, ControlOutput& out) const noexcept;

  [[nodiscard]] ControlLaw law() const noexcept { return law_; }
  [[nodiscard]] const Gains& gains() const noexcept { return gains_; }
  [[nodiscard]] const Machine& model() const noexcept { return *model_; }

 private:
  const Machine* model_;
  ControlLaw law_;
  Gains gains_;
};

}  // namespace cpm::ctl
