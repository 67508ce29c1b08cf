// SPDX-License-Identifier: Apache-2.0
// The force residual of a model on a motion log (kind = motion):
//     r = g . F_commanded - ( J^T (M p_dd + G p_dot + K) + model effects )
// per actuator (N), g the model's drive gain (force_gain effect).
//
// Acceleration: from a1..a3 when the log has them; otherwise estimated from
// the velocities (first derivative) or the positions (second derivative) of
// a zero-phase Savitzky-Golay fit, whichever adds less noise. Both sides of
// the equation go through the same weights: a force commanded at t_k acts
// (zero-order hold) over [t_k, t_k+1), and the acceleration estimate is
// exactly a weighted sum of those intervals' mean accelerations
// (filter.hpp, zoh_force_kernel); the commanded forces are filtered with
// those weights, every effect column with their trapezoid version. The
// equation then holds after filtering whatever the motion's frequency
// content, the sharp force of friction at a reversal included. The base
// columns use a longer acceleration estimate (`a_columns`) so that they do
// not share the residual's noise. What is left: terms nonlinear in the
// state (M(q), sgn) are evaluated on filtered states (second order in the
// motion within one kernel width), and the noise the acceleration estimate
// adds, reported in `accel_noise` / `force_noise`.
//
// The filtered rows are decimated by `stride` (default: the kernel half
// width) so that neighbouring rows are nearly independent; the statistics
// still correct for what correlation remains (stats.hpp).
//
// Rows of every vector and matrix below: 3 per kept sample, row 3 r + i for
// axis i (0..2).
//
// prepare_motion runs it in stages (identification/src/motion_stages.hpp):
// sampling and segments; noise and acceleration source; the per-sample state;
// the kept rows; the base columns, the model force and the residual.
#pragma once

#include <array>
#include <string>
#include <vector>

#include <Eigen/Dense>

#include "cpm/control/machine.hpp"
#include "cpm/identification/filter.hpp"
#include "cpm/io/data_files.hpp"

namespace cpm::ident {

struct MotionOptions {
  double half_window = 0.012;  // s: half width of the zero-phase kernel
  int order = 4;               // polynomial degree of the kernel
  int stride = 0;              // rows kept every `stride` samples; 0 = kernel half width
  enum class Accel { automatic, velocity, position } accel = Accel::automatic;
  int min_rows = 30;           // fewer rows after filtering: refuse the file
  // Nuisance for kinematic errors of an uncalibrated model: `coupling` fits
  // the share of each platform-force component each actuator feels (the
  // J^T part of tilted planes), `tilt` perturbs the plane normals (J^T and
  // the pose), `none` trusts the model's kinematics.
  enum class Nuisance { none, coupling, tilt } nuisance = Nuisance::tilt;
  void validate() const;
};

// A parameter of the base model that diagnosis refits with every candidate:
// the rigid-body constants and the linear parameters of the model's own effects.
struct BaseParameter {
  std::string name;     // "A", "B", "C", "E" or "coulomb_friction[axis 1].f_c"
  std::string unit;
  double value = 0.0;   // the model's value
  int effect = -1;      // index in the model's effect list, -1 for A..E
  int param = -1;       // parameter index in that effect (or 0..3 for A..E)
  // Not a model parameter but always fitted: coupling[i<-j] (1), the share of
  // the platform force along j that actuator i feels beyond the model's J^T,
  // i.e. plane misalignment the model's kinematics does not know (calibrate).
  bool nuisance = false;
};

struct MotionProblem {
  // Per sample of the log.
  std::vector<double> t_sample;   // s
  std::vector<Vec3> d_hat, v_hat; // zero-phase state estimate at each sample (m, m/s)
  std::vector<Vec3> f_sample;     // commanded forces as logged (N)
  std::vector<int> line;          // file line of each sample (0 when unknown)
  std::vector<int> segment_end;   // per sample: one past the last sample of its segment
  double dt = 0.0;                // sample period (s)
  int segments = 0;

  // Kept rows (filtered, decimated).
  std::vector<int> sample;        // sample index of each row
  std::vector<double> t;          // time of the state of the row: t_k + dt/2 (s)
  std::vector<Vec3> d, v, a;      // filtered state (m, m/s, m/s^2)
  std::vector<Vec3> f;            // filtered commanded force (N)
  // The force-gain regressor: the commanded force at the row interpolated
  // from the samples around the row's window only (a cubic through
  // past_samples on each side). A column built from the force of the window
  // itself shares its noise with the residual (errors in variables: with the
  // logged force measured with noise, a log with nothing missing came out
  // with a significant gain on z); the samples around it do not. It is the
  // instrument of two-stage least squares (diagnose.cpp, instrumented): its
  // first stage scales it to the row's own force. f_predicted is the
  // interpolation at the current alignment; f_past its cubic per row (4
  // coefficients per axis, in samples from the row's sample).
  std::vector<Vec3> f_predicted;   // N
  Eigen::MatrixXd f_past;          // 3R x 4
  int past_samples = 0;            // samples on each side
  int past_gap = 0;                // samples between the earlier ones and the row's sample
  int future_gap = 0;              // samples between the row's sample and the later ones
  // Acceleration for the regressor columns (base, nuisance): the same
  // estimate over a 6x longer kernel. The residual carries -M times the
  // noise of `a`; a column built on `a` would carry the same noise and bias
  // (attenuate) the inertia it fits, and a clean column correlated with the
  // acceleration (the force, a spring on an axis that moves sinusoidally)
  // would then look significant in its place. The long estimate's noise
  // shares ~(1/6)^3 of that covariance (of a disturbance in the plant, real
  // acceleration both estimates average, about 1/6); for motion below a few Hz its
  // signal is the same.
  std::vector<Vec3> a_columns;    // m/s^2
  std::vector<Vec3> platform_force;  // model's M p_dd + G p_dot + K at the row, with a_columns (N)
  Eigen::VectorXd residual;       // g F(aligned by `delay`) - model force (N), 3 rows per kept row
  Eigen::VectorXd model_force;    // the model's force at the rows: rigid body + its own effects (N)

  // Force-to-motion alignment (docs/effects.md, actuation_delay). Row
  // k's logged force acts over [t_k + tau, t_k+1 + tau); over one sample
  // interval that is the mix (1 - phi) F_{k-n} + phi F_{k-n-1}, tau = (n + phi) T,
  // exact for the interval means the acceleration estimate sees. The filtered
  // force is kept at every whole shift n in [kShiftLo, kShiftHi]; any tau in
  // between is their linear interpolation. tau = 0: zero-order hold; -T/2: a
  // force sampled at t_k; T: a synchronous bus that applies it at the next SYNC.
  static constexpr int kShiftLo = -2, kShiftHi = 6;
  Eigen::MatrixXd force_at_shift; // 3R x (kShiftHi - kShiftLo + 1): g times the filtered force delayed n periods
  double delay = 0.0;             // s: the alignment the residual uses
  double delay_model = 0.0;       // s: the model's own actuation_delay
  // A quantity given at every whole shift (columns kShiftLo..kShiftHi, as
  // force_at_shift or anything linear in it) at tau (s): linear between whole
  // periods dt (s), tau clamped to the range.
  [[nodiscard]] static Eigen::VectorXd at_delay(const Eigen::MatrixXd& at_shift, double tau, double dt);
  // g F filtered and delayed by tau (s), 3 rows per kept row; and its derivative in tau (N/s).
  [[nodiscard]] Eigen::VectorXd force_delayed(double tau) const;
  [[nodiscard]] Eigen::VectorXd force_delay_slope(double tau) const;
  // Re-align the residual (and the rows' filtered forces) to tau (s).
  void set_delay(double tau);
  Eigen::MatrixXd base;           // columns of the base parameters (N per unit)
  std::vector<BaseParameter> base_params;
  Vec3 drive_gain = Vec3::Ones();

  // What the acceleration estimate did.
  std::string accel_source;       // "measured a1..a3", "velocity (1st derivative)", ...
  Vec3 velocity_noise = Vec3::Zero();   // estimated white noise of v (m/s)
  Vec3 position_noise = Vec3::Zero();   // estimated white noise of d (m)
  Vec3 accel_noise = Vec3::Zero();      // noise the estimate adds at each row (m/s^2)
  Vec3 v_hat_noise = Vec3::Zero();      // noise of the per-sample velocity v_hat (m/s)
  Vec3 force_noise = Vec3::Zero();      // the same through the inertia (N)
  int half_width = 0;             // kernel half width (samples)
  int stride = 0;
  SgKernel smooth_state;          // filter of the effect columns (continuous forces, per sample)
  SgKernel smooth_force;          // filter of the commanded force (held over each sample interval)
  SgKernel accel_kernel;          // the kernel that made the acceleration (its noise dominates)
  std::vector<std::string> warnings;

  [[nodiscard]] int rows() const noexcept { return static_cast<int>(sample.size()); }
  // The state-side filter applied to a per-sample quantity of one axis, at the kept rows:
  // value(k, axis) is called for every sample k in the windows. Returns 3R rows, zero
  // except on `axis`.
  template <class F>
  Eigen::VectorXd filter_axis(int axis, F&& value) const {
    Eigen::VectorXd out = Eigen::VectorXd::Zero(3 * rows());
    if (rows() == 0) return out;
    const int m = smooth_state.half_width;
    const int k0 = sample.front() - m, k1 = sample.back() + m;
    std::vector<double> buf(static_cast<std::size_t>(k1 - k0 + 1));
    // Each sample once (windows overlap), skipping gaps no window covers.
    std::vector<char> need(buf.size(), 0);
    for (int k : sample)
      for (int j = -m; j <= m; ++j) need[static_cast<std::size_t>(k + j - k0)] = 1;
    for (int k = k0; k <= k1; ++k)
      if (need[static_cast<std::size_t>(k - k0)]) buf[static_cast<std::size_t>(k - k0)] = value(k, axis);
    for (int r = 0; r < rows(); ++r)
      out(3 * r + axis) = smooth_state.apply(&buf[static_cast<std::size_t>(sample[r] - k0)]);
    return out;
  }
  // Column of parameter j of a per-axis dynamic effect (effect_force_gradient), filtered.
  // Near rest, where sgn_eps and the Stribeck bell bend within the noise of
  // v_hat, the value is the expectation over that noise (regression
  // calibration): evaluating a sharp function at a noisy velocity would
  // attenuate its fitted amplitude.
  [[nodiscard]] Eigen::VectorXd effect_column(const ctl::DynamicEffect& e, int j) const;
  // actuator_inertia's column: the actuator's own acceleration d_dd on `axis`
  // (a_columns, already filtered, free of the residual's noise), m/s^2.
  [[nodiscard]] Eigen::VectorXd actuator_acceleration_column(int axis) const;
  // The effect's force itself, filtered.
  [[nodiscard]] Eigen::VectorXd effect_force_column(const ctl::DynamicEffect& e) const;
  // The force of user effects (table, expression) at the rows, 3 per row:
  // filtered per sample as the library effects are, or, for a formula that
  // reads a1..a3, evaluated at the rows' filtered state (no per-sample
  // acceleration exists; second order in the motion within a kernel width).
  [[nodiscard]] Eigen::VectorXd user_force_column(const std::vector<ctl::UserEffect>& effects) const;
  // Column of a force-gain change on `axis`: -g F, F predicted from before the
  // row's window (the instrument, f_predicted), and the same with the row's own
  // filtered force (which shares the residual's noise).
  [[nodiscard]] Eigen::VectorXd force_gain_column(int axis) const;
  [[nodiscard]] Eigen::VectorXd force_gain_column_logged(int axis) const;
};

// Build the residual and the base columns. Throws Error naming the file and
// line for data the model cannot follow (outside the workspace), and refuses
// too few samples, non-increasing time and other unusable input.
MotionProblem prepare_motion(const io::MotionData& data, const ctl::Machine& model,
                             const MotionOptions& options = {});

}  // namespace cpm::ident
