#include "cpm/sim/plant.hpp"

#include <cmath>

namespace cpm::sim {

void EncoderModel::validate() const {
  if (!std::isfinite(resolution) || resolution < 0.0)
    throw Error("encoder: resolution must be a finite length >= 0 m");
  if (!std::isfinite(position_noise) || position_noise < 0.0 || !std::isfinite(velocity_noise) ||
      velocity_noise < 0.0)
    throw Error("encoder: noise standard deviations must be finite and >= 0");
}

void PlantOptions::validate() const {
  if (substeps < 1 || substeps > 10000) throw Error("plant: substeps must be within 1..10000");
  if (!std::isfinite(direction_threshold) || direction_threshold < 0.0)
    throw Error("plant: direction threshold must be >= 0 m/s");
  encoder.validate();
}

Plant::Plant(const Machine& truth, const PlantOptions& options)
    : truth_(&truth), opt_(options), rng_(options.encoder.seed) {
  opt_.validate();
}

Status Plant::reset(const Vec3& p, const Vec3& p_dot) noexcept {
  if (!all_finite(p) || !all_finite(p_dot)) return Status::failure(Fault::not_finite);
  t_ = 0.0;
  kin_in_ = {};
  if (Status s = kin::check_pose(truth_->kinematics(), truth_->model().strokes, p, kin_in_); !s)
    return s;
  p_ = p;
  p_dot_ = p_dot;
  return {};
}

Status Plant::acceleration(const Vec3& p, const Vec3& p_dot, const Vec3& force_command,
                           Vec3& p_dd) const noexcept {
  const Machine& m = *truth_;
  const kin::KinematicInputs& in = kin_in_;
  Mat3 J_inv;
  Vec3 d = Vec3::Zero();
  // Without kinematic effects J is constant and d matters only to
  // position-dependent dynamic effects: skip what is not needed. With them,
  // the inverse kinematics gives dd/dp on the way.
  if (!m.has_constant_jacobian()) {
    if (Status s = kin::inverse(m.kinematics(), p, in, d, &J_inv); !s) return s;
  } else {
    J_inv = m.constant_jacobian_inverse();
    if (m.has_additive_effects())
      if (Status s = kin::inverse(m.kinematics(), p, in, d); !s) return s;
  }
  ctl::RigidBodyTerms t;
  if (Status s = m.rigid_body(p, p_dot, t); !s) return s;
  const Vec3 d_dot = J_inv * p_dot;
  const Vec3 f_act = m.drive_gain().cwiseProduct(force_command) - m.effect_forces(d, d_dot);
  // Platform force from actuator forces: F_d = J^T F_p.
  const Vec3 f_platform = J_inv.transpose() * f_act;
  p_dd = t.M.llt().solve(f_platform - t.Gv - t.K);
  if (!all_finite(p_dd)) return Status::failure(Fault::not_finite);
  return {};
}

Status Plant::step(const Vec3& force_command, double dt) noexcept {
  if (!all_finite(force_command) || !std::isfinite(dt) || !(dt > 0.0))
    return Status::failure(Fault::not_finite);
  const double h = dt / opt_.substeps;
  Vec3 p = p_, v = p_dot_;
  for (int k = 0; k < opt_.substeps; ++k) {
    Vec3 a1, a2, a3, a4;
    if (Status s = acceleration(p, v, force_command, a1); !s) return s;
    const Vec3 v1 = v;
    const Vec3 v2 = v + 0.5 * h * a1;
    if (Status s = acceleration(p + 0.5 * h * v1, v2, force_command, a2); !s) return s;
    const Vec3 v3 = v + 0.5 * h * a2;
    if (Status s = acceleration(p + 0.5 * h * v2, v3, force_command, a3); !s) return s;
    const Vec3 v4 = v + h * a3;
    if (Status s = acceleration(p + h * v3, v4, force_command, a4); !s) return s;
    p += h / 6.0 * (v1 + 2.0 * v2 + 2.0 * v3 + v4);
    v += h / 6.0 * (a1 + 2.0 * a2 + 2.0 * a3 + a4);
  }
  if (Status s = kin::check_pose(truth_->kinematics(), truth_->model().strokes, p, kin_in_); !s)
    return s;
  p_ = p;
  p_dot_ = v;
  t_ += dt;
  kin_in_.t = t_;
  // Direction of motion of each axis, for backlash: kept while the axis rests.
  Vec3 d, d_dot;
  if (Status s = actuator_state(d, d_dot); !s) return s;
  kin::DirectionTracker{opt_.direction_threshold}.update(d_dot, kin_in_);
  return {};
}

Status Plant::actuator_state(Vec3& d, Vec3& d_dot) const noexcept {
  Mat3 J_inv = truth_->constant_jacobian_inverse();
  if (Status s = kin::inverse(truth_->kinematics(), p_, kin_in_, d, truth_->has_constant_jacobian() ? nullptr : &J_inv);
      !s)
    return s;
  d_dot.noalias() = J_inv * p_dot_;
  return {};
}

EncoderReading Plant::read() noexcept {
  EncoderReading r;
  if (!actuator_state(r.d, r.d_dot)) {
    r.d.setConstant(std::numeric_limits<double>::quiet_NaN());
    r.d_dot.setConstant(std::numeric_limits<double>::quiet_NaN());
    return r;
  }
  const EncoderModel& e = opt_.encoder;
  for (int i = 0; i < 3; ++i) {
    if (e.position_noise > 0.0) r.d[i] += e.position_noise * normal_(rng_);
    if (e.resolution > 0.0) r.d[i] = e.resolution * std::round(r.d[i] / e.resolution);
    if (e.velocity_noise > 0.0) r.d_dot[i] += e.velocity_noise * normal_(rng_);
  }
  return r;
}

}  // namespace cpm::sim
