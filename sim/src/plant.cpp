// SPDX-License-Identifier: Apache-2.0
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

Status Plant::reset(const Vec3& p, const Vec3& p_dot, const Vec3& force_before) noexcept {
  if (!all_finite(p) || !all_finite(p_dot)) return Status::failure(Fault::not_finite);
  t_ = 0.0;
  kin_in_ = {};
  commands_.reset(force_before);
  if (Status s = kin::check_pose(truth_->kinematics(), truth_->model().strokes, p, kin_in_); !s)
    return s;
  p_ = p;
  p_dot_ = p_dot;
  return {};
}

Status Plant::acceleration(const Vec3& p, const Vec3& p_dot, const Vec3& force_command,
                           Vec3& p_dd) const noexcept {
  return truth_->forward_dynamics(p, p_dot, force_command, kin_in_, p_dd);
}

Status Plant::step(const Vec3& force_command, double dt) noexcept {
  if (!all_finite(force_command) || !std::isfinite(dt) || !(dt > 0.0))
    return Status::failure(Fault::not_finite);
  // The command is given now; under the truth's actuation_delay it acts
  // from t + tau on, and the commands given before it act until then.
  commands_.push(t_, force_command);
  Vec3 p = p_, v = p_dot_;
  if (Status s = ctl::integrate_delayed(*truth_, kin_in_, commands_, truth_->actuation_delay(), t_, dt,
                                        opt_.substeps, p, v);
      !s)
    return s;
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
