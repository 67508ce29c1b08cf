// SPDX-License-Identifier: Apache-2.0
#include "cpm/control/controller.hpp"

#include <algorithm>
#include <cmath>

namespace cpm::ctl {

const char* law_name(ControlLaw law) noexcept {
  switch (law) {
    case ControlLaw::pd: return "pd";
    case ControlLaw::pd_gravity: return "pd_gravity";
    case ControlLaw::pd_feedforward: return "pd_feedforward";
    case ControlLaw::computed_torque: return "computed_torque";
  }
  return "unknown";
}

std::optional<ControlLaw> law_from_name(std::string_view name) noexcept {
  for (ControlLaw l : {ControlLaw::pd, ControlLaw::pd_gravity, ControlLaw::pd_feedforward,
                       ControlLaw::computed_torque})
    if (name == law_name(l)) return l;
  return std::nullopt;
}

void Gains::validate() const {
  if (!kp.allFinite() || !kd.allFinite() || (kp.array() < 0.0).any() || (kd.array() < 0.0).any())
    throw Error("controller gains: kp and kd must be finite and >= 0");
}

Gains table3_gains(ControlLaw law) noexcept {
  switch (law) {
    case ControlLaw::pd: return {Vec3::Constant(12691.0), Vec3::Constant(436.0)};
    case ControlLaw::pd_gravity: return {Vec3::Constant(8507.0), Vec3::Constant(436.0)};
    case ControlLaw::pd_feedforward: return {Vec3::Constant(7053.0), Vec3::Constant(436.0)};
    case ControlLaw::computed_torque: return {Vec3::Constant(2550.25), Vec3::Constant(101.0)};
  }
  return {};
}

Controller::Controller(const Machine& model, ControlLaw law, const Gains& gains)
    : model_(&model), law_(law), gains_(gains) {
  gains_.validate();
}

Status Controller::step(const ControlInput& in, ControllerState& state, ControlOutput& out) const noexcept {
  const Status s = control_law(in, state, out);
  // Recorded as sent: the force, or zero after a failure (what the caller then gives the drives).
  state.sent.push(in.kin.t, out.force);
  return s;
}

Status Controller::predict(const ControlInput& in, const ControllerState& state, ControlOutput& out, Vec3& d,
                           Vec3& d_dot) const noexcept {
  const Machine& m = *model_;
  out.predicted = out.estimate;
  d = in.d;
  d_dot = in.d_dot;
  const double tau = m.actuation_delay();
  if (!(tau > 0.0)) return {};
  // Until t + tau the commands already sent act: the model's dynamics under
  // them from the measured state, in RK4 steps no longer than kPredictionStep.
  const int steps = std::max(1, static_cast<int>(std::ceil(tau / kPredictionStep - 1e-9)));
  TaskState& x = out.predicted;
  if (Status s = integrate_delayed(m, in.kin, state.sent, tau, in.kin.t, tau, steps, x.p, x.p_dot); !s)
    return s;
  // The encoders as they will read then, for the laws that act on the joints.
  Mat3 J_inv;
  if (Status s = kin::inverse(m.kinematics(), x.p, in.kin, d); !s) return s;
  if (Status s = m.jacobian(d, x.p, in.kin, x.J); !s) return s;
  if (Status s = m.inverse_jacobian(d, x.p, in.kin, J_inv); !s) return s;
  d_dot.noalias() = J_inv * x.p_dot;
  return {};
}

Status Controller::control_law(const ControlInput& in, const ControllerState& state,
                               ControlOutput& out) const noexcept {
  out.force.setZero();
  out.force_unlimited.setZero();
  out.saturated = {false, false, false};
  const Machine& m = *model_;
  const kin::KinematicModel& km = m.kinematics();
  if (!in.ref.p.allFinite() || !in.ref.v.allFinite() || !in.ref.a.allFinite())
    return Status::failure(Fault::not_finite);
  if (Status s = m.task_state(in.d, in.d_dot, in.kin, out.estimate); !s) return s;
  // The state the command will meet: (d, d_dot) and out.predicted.
  Vec3 d, d_dot;
  if (Status s = predict(in, state, out, d, d_dot); !s) return s;

  // The reference through the calibrated inverse kinematics.
  Mat3 J_ref;
  if (Status s = kin::inverse(km, in.ref.p, in.kin, out.d_ref); !s) return s;
  if (Status s = m.jacobian(out.d_ref, in.ref.p, in.kin, J_ref); !s) return s;
  out.d_dot_ref = J_ref.partialPivLu().solve(in.ref.v);

  Vec3 F = Vec3::Zero();
  if (law_ == ControlLaw::computed_torque) {
    const TaskState& x = out.predicted;
    RigidBodyTerms t;
    if (Status s = m.rigid_body(x.p, x.p_dot, t); !s) return s;
    const Vec3 accel = in.ref.a + gains_.kd.cwiseProduct(in.ref.v - x.p_dot) +
                       gains_.kp.cwiseProduct(in.ref.p - x.p);
    F.noalias() = x.J.transpose() * (t.M * accel + t.Gv + t.K);
    // User expressions may read the axes' accelerations: the commanded ones
    // through J^-1 (dJ/dt d_dot left out, zero without kinematic effects).
    const Vec3 d_dd = m.user_effects_use_acceleration() ? Vec3(x.J.partialPivLu().solve(accel)) : Vec3::Zero();
    F += m.effect_forces(d, d_dot, d_dd, in.kin.t);
  } else {
    F = gains_.kp.cwiseProduct(out.d_ref - d) + gains_.kd.cwiseProduct(out.d_dot_ref - d_dot);
    if (law_ != ControlLaw::pd) {
      RigidBodyTerms t;
      if (Status s = m.rigid_body(in.ref.p, in.ref.v, t); !s) return s;
      Vec3 Fp = t.K;
      if (law_ == ControlLaw::pd_feedforward) {
        Fp.noalias() += t.M * in.ref.a + t.Gv;
        const Vec3 d_dd_ref =
            m.user_effects_use_acceleration() ? Vec3(J_ref.partialPivLu().solve(in.ref.a)) : Vec3::Zero();
        F += m.effect_forces(out.d_ref, out.d_dot_ref, d_dd_ref, in.kin.t);
      }
      F.noalias() += J_ref.transpose() * Fp;
    }
  }
  F.array() /= m.drive_gain().array();
  if (!F.allFinite()) return Status::failure(Fault::not_finite);
  out.force_unlimited = F;
  const double lim = m.force_limit();
  for (int i = 0; i < 3; ++i) {
    out.force[i] = std::clamp(F[i], -lim, lim);
    out.saturated[i] = out.force[i] != F[i];
  }
  return {};
}

}  // namespace cpm::ctl
