// SPDX-License-Identifier: Apache-2.0
#include "cpm/identification/motion.hpp"

#include <algorithm>
#include <cmath>

#include "motion_stages.hpp"

namespace cpm::ident {

void MotionOptions::validate() const {
  if (!std::isfinite(half_window) || !(half_window > 0.0) || half_window > 1.0)
    throw Error("motion filter: half window must be within (0, 1] s, got " +
                std::to_string(half_window));
  if (order < 2 || order > 8) throw Error("motion filter: order must be 2..8");
  if (stride < 0) throw Error("motion filter: stride must be >= 0");
  if (min_rows < 5) throw Error("motion filter: min_rows must be >= 5");
}

namespace {
// E[f(v - e)], e ~ N(0, sigma^2), by 5-point Gauss-Hermite where f bends on
// the scale of sigma (|v| within a few epsilon of rest); f(v) elsewhere.
template <class F>
double noise_expectation(F&& f, double v, double sigma) {
  if (!(sigma > 0.0) || std::fabs(v) > 8.0 * ctl::kSignEpsilon + 6.0 * sigma) return f(v);
  static constexpr double x[5] = {-2.856970013872806, -1.355626179974266, 0.0, 1.355626179974266, 2.856970013872806};
  static constexpr double w[5] = {0.011257411327721, 0.222075922005613, 0.533333333333333, 0.222075922005613,
                                  0.011257411327721};
  double s = 0.0;
  for (int q = 0; q < 5; ++q) s += w[q] * f(v + sigma * x[q]);
  return s;
}
}  // namespace

Eigen::VectorXd MotionProblem::effect_column(const ctl::DynamicEffect& e, int j) const {
  const int i = e.axis;
  if (e.type == ctl::DynamicEffectType::actuator_inertia) return actuator_acceleration_column(i);
  return filter_axis(i, [&](int k, int ax) {
    return noise_expectation([&](double vel) { return ctl::effect_force_gradient(e, j, d_hat[k][ax], vel); },
                             v_hat[k][ax], v_hat_noise[ax]);
  });
}

Eigen::VectorXd MotionProblem::actuator_acceleration_column(int axis) const {
  Eigen::VectorXd c = Eigen::VectorXd::Zero(3 * rows());
  for (int r = 0; r < rows(); ++r) c(3 * r + axis) = a_columns[r][axis];
  return c;
}

Eigen::VectorXd MotionProblem::effect_force_column(const ctl::DynamicEffect& e) const {
  if (e.type == ctl::DynamicEffectType::actuator_inertia) return e.param[0] * actuator_acceleration_column(e.axis);
  return filter_axis(e.axis, [&](int k, int ax) {
    return noise_expectation([&](double vel) { return ctl::effect_force(e, d_hat[k][ax], vel); }, v_hat[k][ax],
                             v_hat_noise[ax]);
  });
}

Eigen::VectorXd MotionProblem::user_force_column(const std::vector<ctl::UserEffect>& effects) const {
  Eigen::VectorXd out = Eigen::VectorXd::Zero(3 * rows());
  if (effects.empty()) return out;
  const ctl::UserEffectsRuntime user(effects);  // its own: one evaluation at a time
  if (user.uses_acceleration()) {
    for (int r = 0; r < rows(); ++r) {
      Vec3 force = Vec3::Zero();
      user.add_forces(d[r], v[r], a[r], t[r], force);
      out.segment<3>(3 * r) = force;
    }
    return out;
  }
  // Every axis at each sample at once, then filtered per axis.
  const int n = static_cast<int>(d_hat.size());
  std::vector<Vec3> per_sample(static_cast<std::size_t>(n));
  for (int k = 0; k < n; ++k) {
    const auto kk = static_cast<std::size_t>(k);
    Vec3 force = Vec3::Zero();
    user.add_forces(d_hat[kk], v_hat[kk], Vec3::Zero(), t_sample[kk], force);
    per_sample[kk] = force;
  }
  for (int i = 0; i < 3; ++i)
    out += filter_axis(i, [&](int k, int ax) { return per_sample[static_cast<std::size_t>(k)][ax]; });
  return out;
}

Eigen::VectorXd MotionProblem::force_gain_column_logged(int axis) const {
  Eigen::VectorXd c = Eigen::VectorXd::Zero(3 * rows());
  for (int r = 0; r < rows(); ++r) c(3 * r + axis) = -drive_gain[axis] * f[r][axis];
  return c;
}

Eigen::VectorXd MotionProblem::force_gain_column(int axis) const {
  Eigen::VectorXd c = Eigen::VectorXd::Zero(3 * rows());
  for (int r = 0; r < rows(); ++r) c(3 * r + axis) = -drive_gain[axis] * f_predicted[r][axis];
  return c;
}

Eigen::VectorXd MotionProblem::at_delay(const Eigen::MatrixXd& at_shift, double tau, double dt) {
  const double x = std::clamp(tau / dt, double(kShiftLo), double(kShiftHi)) - kShiftLo;
  const int n = std::min(static_cast<int>(std::floor(x)), kShiftHi - kShiftLo - 1);
  const double phi = x - n;
  return (1.0 - phi) * at_shift.col(n) + phi * at_shift.col(n + 1);
}

Eigen::VectorXd MotionProblem::force_delayed(double tau) const { return at_delay(force_at_shift, tau, dt); }

Eigen::VectorXd MotionProblem::force_delay_slope(double tau) const {
  // Central over one period around tau: the piecewise-linear interpolation
  // has a kink at every whole period, where a one-sided slope would jump.
  return (force_delayed(tau + 0.5 * dt) - force_delayed(tau - 0.5 * dt)) / dt;
}

void MotionProblem::set_delay(double tau) {
  delay = tau;
  const Eigen::VectorXd F = force_delayed(tau);
  residual = F - model_force;
  // The force acting over the row's interval was commanded at about t_k + T/2 - tau.
  const double u = 0.5 - tau / dt;
  for (int r = 0; r < rows(); ++r)
    for (int i = 0; i < 3; ++i) {
      f[r][i] = F(3 * r + i) / drive_gain[i];
      if (f_past.rows() == 3 * rows())
        f_predicted[r][i] = f_past(3 * r + i, 0) + u * (f_past(3 * r + i, 1) + u * (f_past(3 * r + i, 2) + u * f_past(3 * r + i, 3)));
    }
}

namespace {

// Stage 1's sampling as the problem keeps it.
void keep_sampling(const io::MotionData& data, const motion_stages::Sampling& S, int half_width, const MotionOptions& opt,
                   MotionProblem& P) {
  const int n = static_cast<int>(data.t.size());
  P.dt = S.dt;
  P.half_width = half_width;
  P.stride = opt.stride > 0 ? opt.stride : half_width;
  P.t_sample = data.t;
  P.f_sample = data.f;
  P.line.assign(n, 0);
  for (int k = 0; k < n && k < static_cast<int>(data.info.line_of_row.size()); ++k)
    P.line[k] = data.info.line_of_row[k];
  P.segment_end = S.segment_end;
  P.segments = S.segments;
  P.warnings = S.warnings;
}

// Stage 2's choice as the problem reports it, and the filters of both sides.
void keep_acceleration(const motion_stages::AccelerationEstimate& A, MotionProblem& P) {
  P.accel_source = A.text;
  P.position_noise = A.position_noise;
  P.velocity_noise = A.velocity_noise;
  P.accel_noise = A.accel_noise;
  P.accel_kernel = A.accel_kernel;
  P.smooth_force = A.smooth_force;
  P.smooth_state = A.smooth_state;
}

}  // namespace

MotionProblem prepare_motion(const io::MotionData& data, const ctl::Machine& model,
                             const MotionOptions& opt) {
  using namespace motion_stages;
  opt.validate();
  MotionProblem P;
  // 1. Sampling: input checks, period, segments, kernel width.
  const Sampling S = read_sampling(data);
  const int m = kernel_half_width(data, S.dt, opt);
  keep_sampling(data, S, m, opt, P);
  // 2. Noise, acceleration source, kernels.
  const AccelerationEstimate A = choose_acceleration(data, S.dt, m, opt);
  keep_acceleration(A, P);
  // 3. The state at every sample.
  SampleStates X = estimate_sample_states(data, S, A, opt);
  P.d_hat = std::move(X.d_hat);
  P.v_hat = std::move(X.v_hat);
  P.v_hat_noise = X.v_hat_noise;
  // 4. The kept rows: filtered state, acceleration, force at every shift,
  //    the columns' acceleration, the force-gain instrument.
  const ForceInstrument I = force_instrument(m);
  P.past_samples = I.samples;
  P.past_gap = I.past_gap;
  P.future_gap = I.future_gap;
  P.sample = kept_samples(S, m, P.stride, I.samples);
  check_enough_rows(data, P, I.samples, opt);
  P.drive_gain = model.drive_gain();
  filter_kept_rows(data, S, A, I, opt, P);
  // 5. The base columns, the model force and the residual.
  add_base_columns(data, model, opt, P);
  return P;
}

}  // namespace cpm::ident
