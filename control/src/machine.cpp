// SPDX-License-Identifier: Apache-2.0
#include "cpm/control/machine.hpp"

#include <cmath>
#include <sstream>

namespace cpm::ctl {

InertiaConstants InertiaConstants::from_masses(const LinkMasses& m, double L1) {
  const double total = m.m1 + 2.0 * m.m2 + m.m3 + m.m4;
  return {0.5 * total, (m.m1 / 6.0 + m.m2 / 4.0) * L1 * L1, 0.5 * (m.m1 + m.m2) * kGravity * L1,
          total * kGravity};
}

MachineModel MachineModel::elkady() { return MachineModel{}; }

void MachineModel::validate() const {
  kinematics.validate();
  strokes.validate();
  const double ms[] = {masses.m1, masses.m2, masses.m3, masses.m4};
  const char* names[] = {"m1", "m2", "m3", "m4"};
  for (int i = 0; i < 4; ++i)
    if (!std::isfinite(ms[i]) || ms[i] < 0.0)
      throw Error(std::string("model masses: ") + names[i] + " must be a finite mass >= 0 kg");
  if (!std::isfinite(force_limit) || !(force_limit > 0.0))
    throw Error("model: force_limit must be a finite force > 0 N");
  const kin::LimbGeometry& g = kinematics.limbs;
  if (!(g.L > 0 && g.L1 > 0 && g.L2 > 0 && g.D > 0) || !std::isfinite(g.L + g.L1 + g.L2 + g.D))
    throw Error("model limbs: L, L1, L2 and D must be finite lengths > 0 m");
  for (int i = 0; i < 3; ++i)
    if (g.mode[i] != 1 && g.mode[i] != -1)
      throw Error("model limbs: assembly mode of limb " + std::to_string(i + 1) +
                  " must be +1 or -1");
  for (const DynamicEffect& e : effects) e.validate();
  for (std::size_t i = 0; i < user_effects.size(); ++i)
    validate_user_effect(user_effects[i], static_cast<int>(i));
}

void add_effect(MachineModel& model, std::string_view name, int axis,
                const std::vector<double>& values) {
  const std::string label = std::string(name);
  if (const auto kt = kin::kinematic_effect_from_name(name)) {
    const kin::KinematicEffectInfo& in = kin::info(*kt);
    if (axis < 0 || axis > 2) throw Error(label + ": a kinematic effect needs an axis 1, 2 or 3");
    if (static_cast<int>(values.size()) != in.n_params)
      throw Error(label + ": expects " + std::to_string(in.n_params) + " values, got " +
                  std::to_string(values.size()));
    std::array<double, 3> v{};
    for (int j = 0; j < in.n_params; ++j) {
      const auto& p = in.params[j];
      if (!std::isfinite(values[j]) || values[j] < p.lower || values[j] > p.upper) {
        std::ostringstream os;
        os << label << "[axis " << axis + 1 << "]: " << p.name << " = " << values[j] << " " << p.unit
           << " is outside its physical range [" << p.lower << ", " << p.upper << "]";
        throw Error(os.str());
      }
      v[j] = values[j];
    }
    kin::set_params(model.kinematics.effects[axis], *kt, v);
    model.kinematics.validate();
    return;
  }
  const auto dt = dynamic_effect_from_name(name);
  if (!dt) throw Error("unknown effect '" + label + "' (see docs/effects.md for the names)");
  const DynamicEffectInfo& in = info(*dt);
  if (static_cast<int>(values.size()) != in.n_params)
    throw Error(label + ": expects " + std::to_string(in.n_params) + " values, got " +
                std::to_string(values.size()));
  DynamicEffect e;
  e.type = *dt;
  e.axis = static_cast<std::int8_t>(in.per_axis ? axis : -1);
  if (!in.per_axis && axis >= 0) throw Error(label + " acts on all axes together; give no axis");
  for (int j = 0; j < in.n_params; ++j) e.param[j] = values[j];
  model.effects.add(e);
}

Machine::Machine(MachineModel model) : model_(std::move(model)) {
  model_.validate();
  user_ = UserEffectsRuntime(model_.user_effects);
  if (!user_.empty()) additive_effects_ = true;
  inertia_ = InertiaConstants::from_masses(model_.masses, model_.kinematics.limbs.L1);
  for (const DynamicEffect& e : model_.effects) {
    switch (e.type) {
      case DynamicEffectType::force_gain: drive_gain_[e.axis] *= 1.0 + e.param[0]; break;
      case DynamicEffectType::payload_mass:
        inertia_.A += 0.5 * e.param[0];
        inertia_.E += e.param[0] * kGravity;
        break;
      case DynamicEffectType::inertia_error:
        inertia_.A += e.param[0];
        inertia_.B += e.param[1];
        inertia_.C += e.param[2];
        inertia_.E += e.param[3];
        break;
      case DynamicEffectType::actuation_delay: actuation_delay_ += e.param[0]; break;
      case DynamicEffectType::actuator_inertia: reflected_mass_[e.axis] += e.param[0]; break;
      default: additive_effects_ = true; break;
    }
  }
  const auto& k = model_.kinematics;
  constant_jacobian_ = !k.effects[0].any() && !k.effects[1].any() && !k.effects[2].any();
  if (constant_jacobian_) {
    // J = U^-1 diag(c): any point will do, the planes are fixed.
    if (!kin::jacobian(k, Vec3::Zero(), Vec3::Zero(), {}, J_))
      throw Error("model: the limb planes do not meet in one point");
    J_inv_ = J_.inverse();
  }
  if (!(inertia_.A > 0.0) || inertia_.B < 0.0) {
    std::ostringstream os;
    os << "model: with its effects the machine has A = " << inertia_.A << " kg, B = " << inertia_.B
       << " kg m^2; A must be > 0 and B >= 0 (is a payload or inertia error too negative?)";
    throw Error(os.str());
  }
  if (!reflected_mass_.isZero()) {
    // The planes' J (constant): the kinematic effects bend it by a relative 1e-4..1e-2 only.
    kin::KinematicModel planes = k;
    planes.effects = {};
    Mat3 Jp;
    if (!kin::jacobian(planes, Vec3::Zero(), Vec3::Zero(), {}, Jp))
      throw Error("model: the limb planes do not meet in one point");
    const Mat3 Jp_inv = Jp.inverse();
    reflected_inertia_ = Jp_inv.transpose() * reflected_mass_.asDiagonal() * Jp_inv;
    // M = 2A I + 2B Gamma^T Gamma + this, and B >= 0: positive definite everywhere if this
    // with 2A I is.
    const Mat3 least = reflected_inertia_ + 2.0 * inertia_.A * Mat3::Identity();
    if (least.llt().info() != Eigen::Success) {
      std::ostringstream os;
      os << "model: the actuator_inertia effects (" << reflected_mass_.transpose()
         << " kg on axes 1..3) leave the machine a negative inertia";
      throw Error(os.str());
    }
  }
}

Status Machine::rigid_body(const Vec3& p, const Vec3& p_dot, RigidBodyTerms& out) const noexcept {
  if (Status s = kin::solve_limb_motion(limbs(), p, p_dot, out.limbs); !s) return s;
  const Mat3& Gam = out.limbs.pose.Gamma;
  const InertiaConstants& c = inertia_;
  out.M.noalias() = 2.0 * c.B * Gam.transpose() * Gam;
  out.M.diagonal().array() += 2.0 * c.A;
  out.M += reflected_inertia_;
  out.Gv.noalias() = 2.0 * c.B * Gam.transpose() * (out.limbs.Gamma_dot * p_dot);
  const Vec3 lambda(-out.limbs.pose.cos_theta[0], out.limbs.pose.sin_theta[1], 0.0);
  out.K.noalias() = c.C * Gam.transpose() * lambda;
  out.K.z() -= c.E;
  return {};
}

Status Machine::inverse_dynamics(const Vec3& p, const Vec3& p_dot, const Vec3& p_dd,
                                 Vec3& force) const noexcept {
  if (!all_finite(p_dd)) return Status::failure(Fault::not_finite);
  RigidBodyTerms t;
  if (Status s = rigid_body(p, p_dot, t); !s) return s;
  force.noalias() = t.M * p_dd + t.Gv + t.K;
  return {};
}

Status Machine::forward_dynamics(const Vec3& p, const Vec3& p_dot, const Vec3& force_command,
                                 const kin::KinematicInputs& in, Vec3& p_dd) const noexcept {
  Mat3 J_inv;
  Vec3 d = Vec3::Zero();
  // Without kinematic effects J is constant and d matters only to
  // position-dependent dynamic effects: skip what is not needed. With them,
  // the inverse kinematics gives dd/dp on the way.
  if (!has_constant_jacobian()) {
    if (Status s = kin::inverse(kinematics(), p, in, d, &J_inv); !s) return s;
  } else {
    J_inv = constant_jacobian_inverse();
    if (has_additive_effects())
      if (Status s = kin::inverse(kinematics(), p, in, d); !s) return s;
  }
  RigidBodyTerms t;
  if (Status s = rigid_body(p, p_dot, t); !s) return s;
  const Vec3 d_dot = J_inv * p_dot;
  const Vec3 f_act = drive_gain().cwiseProduct(force_command) - effect_forces(d, d_dot, Vec3::Zero(), in.t);
  // Platform force from actuator forces: F_d = J^T F_p.
  const Vec3 f_platform = J_inv.transpose() * f_act;
  p_dd = t.M.llt().solve(f_platform - t.Gv - t.K);
  if (!all_finite(p_dd)) return Status::failure(Fault::not_finite);
  if (!user_.uses_acceleration()) return {};
  // A user force f(a) that reads the axes' accelerations makes the equation
  // implicit: M p_dd + Gv + K = J^-T (g F - f(a)), a = J^-1 p_dd (the term
  // dJ^-1/dt p_dot is left out: it is zero without kinematic effects and of
  // the order of their micrometres with them). Newton's method on p_dd, with
  // df/da by differences of step 1 m/s^2 (exact for a law linear in a):
  // one step solves a linear law, nonlinear ones take a few.
  // f_act holds the user forces at a = 0: add them back, take them at a below.
  Vec3 f_user_rest = Vec3::Zero();
  user_.add_forces(d, d_dot, Vec3::Zero(), in.t, f_user_rest);
  const Vec3& f_drive = f_act;
  for (int it = 0; it < 8; ++it) {
    const Vec3 a = J_inv * p_dd;
    Vec3 f0 = Vec3::Zero();
    user_.add_forces(d, d_dot, a, in.t, f0);
    Mat3 Ka;
    for (int j = 0; j < 3; ++j) {
      Vec3 fj = Vec3::Zero();
      user_.add_forces(d, d_dot, a + Vec3::Unit(j), in.t, fj);
      Ka.col(j) = fj - f0;
    }
    // Residual of the platform equation at p_dd and its derivative.
    const Vec3 r = t.M * p_dd + t.Gv + t.K - J_inv.transpose() * (f_drive + f_user_rest - f0);
    const Mat3 D = t.M + J_inv.transpose() * Ka * J_inv;
    const Vec3 step = D.partialPivLu().solve(r);
    p_dd -= step;
    if (!all_finite(p_dd)) return Status::failure(Fault::not_finite);
    if (step.norm() <= 1e-12 * (1.0 + p_dd.norm())) return {};
  }
  return Status::failure(Fault::no_convergence);
}

Status Machine::holding_command(const Vec3& p, const kin::KinematicInputs& in, Vec3& command) const noexcept {
  Vec3 d, F_p;
  Mat3 J;
  if (Status s = kin::inverse(kinematics(), p, in, d); !s) return s;
  if (Status s = jacobian(d, p, in, J); !s) return s;
  if (Status s = inverse_dynamics(p, Vec3::Zero(), Vec3::Zero(), F_p); !s) return s;
  command = (J.transpose() * F_p + effect_forces(d, Vec3::Zero(), Vec3::Zero(), in.t)).cwiseQuotient(drive_gain());
  return {};
}

Vec3 Machine::effect_forces(const Vec3& d, const Vec3& d_dot) const noexcept {
  return effect_forces(d, d_dot, Vec3::Zero(), 0.0);
}

Vec3 Machine::effect_forces(const Vec3& d, const Vec3& d_dot, const Vec3& d_dd, double t) const noexcept {
  Vec3 f = Vec3::Zero();
  if (!additive_effects_) return f;
  for (const DynamicEffect& e : model_.effects)
    if (e.axis >= 0) f[e.axis] += effect_force(e, d[e.axis], d_dot[e.axis]);
  user_.add_forces(d, d_dot, d_dd, t, f);
  return f;
}

Status Machine::jacobian(const Vec3& d, const Vec3& p, const kin::KinematicInputs& in,
                         Mat3& J) const noexcept {
  if (!constant_jacobian_) return kin::jacobian(kinematics(), d, p, in, J);
  if (!all_finite(d) || !all_finite(p)) return Status::failure(Fault::not_finite);
  J = J_;
  return {};
}

Status Machine::inverse_jacobian(const Vec3& d, const Vec3& p, const kin::KinematicInputs& in,
                                 Mat3& J_inv) const noexcept {
  if (!constant_jacobian_) return kin::inverse_jacobian(kinematics(), d, p, in, J_inv);
  if (!all_finite(d) || !all_finite(p)) return Status::failure(Fault::not_finite);
  J_inv = J_inv_;
  return {};
}

Status Machine::task_state(const Vec3& d, const Vec3& d_dot, const kin::KinematicInputs& in,
                           TaskState& out) const noexcept {
  if (!all_finite(d_dot)) return Status::failure(Fault::not_finite);
  if (Status s = kin::forward(kinematics(), d, in, out.p); !s) return s;
  if (Status s = jacobian(d, out.p, in, out.J); !s) return s;
  out.p_dot.noalias() = out.J * d_dot;
  return {};
}

Status Machine::kinetic_energy(const Vec3& p, const Vec3& p_dot, double& T) const noexcept {
  kin::LimbPose pose;
  if (Status s = kin::solve_limbs(limbs(), p, pose); !s) return s;
  T = inertia_.A * p_dot.squaredNorm() + inertia_.B * (pose.Gamma * p_dot).squaredNorm() +
      0.5 * p_dot.dot(reflected_inertia_ * p_dot);
  return {};
}

Status Machine::potential_energy(const Vec3& p, double& V) const noexcept {
  kin::LimbPose pose;
  if (Status s = kin::solve_limbs(limbs(), p, pose); !s) return s;
  V = -inertia_.C * (pose.sin_theta[0] + pose.cos_theta[1]) - inertia_.E * p.z();
  return {};
}

}  // namespace cpm::ctl
