// SPDX-License-Identifier: Apache-2.0
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
//
// Actuation delay: when the model has an actuation_delay tau > 0, the
// command computed now acts only from t + tau. The controller therefore
// first predicts the platform state at t + tau: the model's forward
// dynamics integrated from the measured state under the commands it already
// sent that act before then (its ControllerState, switched at the same
// fractional instants as the plant), and applies the law at that predicted
// state against the reference at t + tau. The caller samples the reference
// at t + lookahead(). With tau = 0 nothing of this runs.
#pragma once

#include <optional>
#include <string_view>

#include "cpm/control/actuation.hpp"
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
  kin::KinematicInputs kin;    // direction of motion, time (for kinematic effects); kin.t (s)
                               // is also when this command is given, which stamps it for the delay
  TrajectorySample ref;        // reference of the platform centre at kin.t + Controller::lookahead()
};

// What the controller remembers between cycles: the commands it sent, for
// the prediction across the actuation delay. Owned by the caller (the
// Controller itself stays a constant description); reset() when the drives
// are enabled, since until then they were given nothing (or with the force
// they were applying, when a run starts from a platform held at rest).
struct ControllerState {
  CommandHistory sent;  // forces returned by step(), stamped with in.kin.t
  void reset(const Vec3& before = Vec3::Zero()) noexcept { sent.reset(before); }
};

struct ControlOutput {
  Vec3 force = Vec3::Zero();            // actuator commands after the limit (N)
  Vec3 force_unlimited = Vec3::Zero();  // before it (N)
  std::array<bool, 3> saturated{};      // which actuators hit the limit
  TaskState estimate;                   // platform state from the encoders
  TaskState predicted;                  // state at kin.t + lookahead() the law acted on
                                        // (the estimate when the model has no delay)
  Vec3 d_ref = Vec3::Zero();            // actuator reference (m)
  Vec3 d_dot_ref = Vec3::Zero();        // actuator velocity reference (m/s)
};

class Controller {
 public:
  // The controller keeps a reference to `model`: it must outlive it.
  Controller(const Machine& model, ControlLaw law, const Gains& gains);

  // One control step: allocation-free and noexcept. Records the command it
  // returns in `state`. On failure (reference or state outside the model's
  // workspace, NaN, the history too short for the delay) `out.force` is
  // zero, recorded as such, and the status says why.
  Status step(const ControlInput& in, ControllerState& state, ControlOutput& out) const noexcept;

  // How far ahead of kin.t the reference must be sampled (s): the model's
  // actuation delay, when the command will start to act.
  [[nodiscard]] double lookahead() const noexcept { return model_->actuation_delay(); }
  // Longest RK4 step of the prediction across the delay (s). One step over
  // a 1 ms period errs by 3e-10 m on the paper's circle (docs/performance.md:
  // one period at 1 against 40 sub-steps), far below an encoder count, and
  // costs four evaluations of the forward dynamics (~1 us) where 0.1 ms
  // steps cost ten times that in every cycle.
  static constexpr double kPredictionStep = 1e-3;

  [[nodiscard]] ControlLaw law() const noexcept { return law_; }
  [[nodiscard]] const Gains& gains() const noexcept { return gains_; }
  [[nodiscard]] const Machine& model() const noexcept { return *model_; }

 private:
  Status control_law(const ControlInput& in, const ControllerState& state, ControlOutput& out) const noexcept;
  Status predict(const ControlInput& in, const ControllerState& state, ControlOutput& out, Vec3& d,
                 Vec3& d_dot) const noexcept;

  const Machine* model_;
  ControlLaw law_;
  Gains gains_;
};

}  // namespace cpm::ctl
