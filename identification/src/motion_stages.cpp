// SPDX-License-Identifier: Apache-2.0
// The stages of prepare_motion (motion_stages.hpp).
#include "motion_stages.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <sstream>

#include "cpm/identification/stats.hpp"

namespace cpm::ident::motion_stages {

std::string log_name(const io::MotionData& data) {
  return data.info.path.empty() ? "motion log" : data.info.path;
}

std::string where(const io::MotionData& data, int k) {
  std::ostringstream os;
  os << log_name(data);
  if (k >= 0 && k < static_cast<int>(data.info.line_of_row.size()))
    os << ":" << data.info.line_of_row[k];
  else
    os << " (sample " << k + 1 << ")";
  return os.str();
}

// ---- Stage 1: sampling ----------------------------------------------------

namespace {

// The regressor columns' acceleration kernel, in half widths of the row's (filter_kept_rows).
constexpr int kColumnKernelLength = 6;

void check_columns(const io::MotionData& data) {
  const int n = static_cast<int>(data.t.size());
  const std::string name = log_name(data);
  if (data.d.size() != data.t.size() || data.v.size() != data.t.size() ||
      data.f.size() != data.t.size() || (!data.a.empty() && data.a.size() != data.t.size()))
    throw Error(name + ": columns of different lengths");
  if (n < 10)
    throw Error(name + ": too few samples (" + std::to_string(n) +
                ") to estimate accelerations and fit anything");
}

bool same_run(const io::MotionData& data, int k) { return data.run.empty() || data.run[k] == data.run[k - 1]; }

// The median step within runs; time must increase within a run.
double sample_period(const io::MotionData& data) {
  const int n = static_cast<int>(data.t.size());
  std::vector<double> steps;
  for (int k = 1; k < n; ++k) {
    const double h = data.t[k] - data.t[k - 1];
    if (same_run(data, k) && !(h > 0.0))
      throw Error(where(data, k) + ": time does not increase (t = " + std::to_string(data.t[k]) +
                  " s after " + std::to_string(data.t[k - 1]) + " s)");
    if (same_run(data, k)) steps.push_back(h);
  }
  if (steps.empty()) throw Error(log_name(data) + ": no two consecutive samples in the same run");
  return median(steps);
}

// A step far from the period (or a new run) starts a segment.
void split_segments(const io::MotionData& data, Sampling& S) {
  const int n = static_cast<int>(data.t.size());
  S.segment_end.assign(n, n);
  int start = 0;
  for (int k = 1; k <= n; ++k) {
    const bool cut = k == n || !same_run(data, k) || std::fabs((data.t[k] - data.t[k - 1]) - S.dt) > 0.25 * S.dt;
    if (!cut) continue;
    for (int q = start; q < k; ++q) S.segment_end[q] = k;
    ++S.segments;
    if (k < n && same_run(data, k)) {
      std::ostringstream os;
      os << where(data, k) << ": sampling gap of " << (data.t[k] - data.t[k - 1]) * 1e3
         << " ms (period " << S.dt * 1e3 << " ms); the log is split there";
      S.warnings.push_back(os.str());
    }
    start = k;
  }
  // First sample of each sample's segment (a walk back per sample made this quadratic in n).
  S.segment_start.assign(static_cast<std::size_t>(n), 0);
  for (int k = 1; k < n; ++k)
    S.segment_start[k] = S.segment_end[k - 1] == S.segment_end[k] ? S.segment_start[k - 1] : k;
}

}  // namespace

Sampling read_sampling(const io::MotionData& data) {
  check_columns(data);
  Sampling S;
  S.dt = sample_period(data);
  split_segments(data, S);
  return S;
}

int kernel_half_width(const io::MotionData& data, double dt, const MotionOptions& opt) {
  const double fs = 1.0 / dt;
  const int m = std::max(2, static_cast<int>(std::lround(opt.half_window * fs)));
  if (opt.order >= 2 * m + 1)
    throw Error(log_name(data) + ": sample rate " + std::to_string(fs) + " Hz is too low for a " +
                std::to_string(opt.half_window * 1e3) + " ms filter");
  return m;
}

// ---- Stage 2: noise and acceleration source ----------------------------------

HalfSampleKernels HalfSampleKernels::make(int half_width, int order) {
  return {savitzky_golay(half_width, order, 0, 0.5), savitzky_golay(half_width, order, 1, 0.5),
          savitzky_golay(half_width, order, 2, 0.5)};
}

double smoother_noise(const std::vector<double>& x, const SgKernel& s) {
  const int m = s.half_width;
  const int n = static_cast<int>(x.size());
  if (n < 2 * m + 3) return 0.0;
  std::vector<double> dev;
  dev.reserve(static_cast<std::size_t>(n - 2 * m));
  for (int k = m; k < n - m; ++k) dev.push_back(std::fabs(x[k] - s.apply(&x[k])));
  const double h0 = s.h[m];
  return 1.4826 * median(std::move(dev)) / std::sqrt(std::max(1e-6, 1.0 - h0));
}

namespace {

// Noise of the logged positions and velocities, per axis.
void measure_noise(const io::MotionData& data, AccelerationEstimate& A) {
  const int n = static_cast<int>(data.t.size());
  std::vector<double> x(n);
  for (int i = 0; i < 3; ++i) {
    for (int k = 0; k < n; ++k) x[k] = data.d[k][i];
    A.position_noise[i] = smoother_noise(x, A.at_sample);
    for (int k = 0; k < n; ++k) x[k] = data.v[k][i];
    A.velocity_noise[i] = smoother_noise(x, A.at_sample);
  }
}

// Velocity estimate and acceleration source: whichever adds less noise.
void pick_source(bool measured, double dt, const MotionOptions& opt, AccelerationEstimate& A) {
  const double fs = 1.0 / dt;
  bool a_from_d = false;
  Vec3 acc_noise_v, acc_noise_d, vel_noise_v, vel_noise_d;
  for (int i = 0; i < 3; ++i) {
    vel_noise_v[i] = A.velocity_noise[i] * A.at_sample.noise_gain();
    vel_noise_d[i] = A.position_noise[i] * A.d1_at_sample.noise_gain() * fs;
    acc_noise_v[i] = A.velocity_noise[i] * A.half.d1.noise_gain() * fs;
    acc_noise_d[i] = A.position_noise[i] * A.half.d2.noise_gain() * fs * fs;
  }
  if (opt.accel == MotionOptions::Accel::position) a_from_d = A.velocity_from_positions = true;
  else if (opt.accel == MotionOptions::Accel::automatic) {
    a_from_d = acc_noise_d.sum() < acc_noise_v.sum();
    A.velocity_from_positions = vel_noise_d.sum() < vel_noise_v.sum();
  }
  A.accel_kernel = A.half.d1;
  if (measured) {
    A.source = AccelerationEstimate::Source::measured;
    A.text = "measured (a1..a3), filtered like the force";
    A.accel_noise.setZero();
  } else if (a_from_d) {
    A.source = AccelerationEstimate::Source::position;
    A.accel_kernel = A.half.d2;
    A.text = "2nd derivative of the positions (zero-phase Savitzky-Golay)";
    A.accel_noise = acc_noise_d;
  } else {
    A.source = AccelerationEstimate::Source::velocity;
    A.text = "1st derivative of the velocities (zero-phase Savitzky-Golay)";
    A.accel_noise = acc_noise_v;
  }
}

}  // namespace

AccelerationEstimate choose_acceleration(const io::MotionData& data, double dt, int half_width,
                                         const MotionOptions& opt) {
  // Kernels: state estimate at each sample (offset 0); filter of both sides
  // at the rows (force at 0, state at +1/2).
  AccelerationEstimate A;
  A.half_width = half_width;
  A.at_sample = savitzky_golay(half_width, opt.order, 0, 0.0);
  A.d1_at_sample = savitzky_golay(half_width, opt.order, 1, 0.0);
  A.half = HalfSampleKernels::make(half_width, opt.order);
  measure_noise(data, A);
  const bool measured = !data.a.empty();
  pick_source(measured, dt, opt, A);
  // Both sides of the equation through the same weights: the force side
  // through those with which the acceleration estimate sums the interval
  // accelerations of the zero-order hold, the effects (continuous forces)
  // through their trapezoid version. Measured accelerations are samples of
  // their own: a smoother at the force's sample and half a sample later.
  if (measured) {
    A.smooth_force = A.at_sample;
    A.smooth_state = A.half.smooth;
  } else {
    A.smooth_force = zoh_force_kernel(A.accel_kernel, A.source == AccelerationEstimate::Source::position ? 2 : 1);
    A.smooth_state = zoh_state_kernel(A.smooth_force);
  }
  return A;
}

double acceleration_at(const io::MotionData& data, const AccelerationEstimate& A, const HalfSampleKernels& h,
                       double dt, int k, int i) {
  const double fs = 1.0 / dt;
  switch (A.source) {
    case AccelerationEstimate::Source::measured: return h.smooth.apply(&data.a[k][i], 3);
    case AccelerationEstimate::Source::position: return h.d2.apply(&data.d[k][i], 3) * fs * fs;
    case AccelerationEstimate::Source::velocity: break;
  }
  return h.d1.apply(&data.v[k][i], 3) * fs;
}

// ---- Stage 3: per-sample state ----------------------------------------------------

namespace {

// The short kernels of the per-sample velocity, and which of them (the
// smoothed velocity or the positions' derivative) is less noisy.
struct ShortKernels {
  SgKernel smooth, d1;
  bool velocity_from_positions = false;
};

ShortKernels short_kernels(const AccelerationEstimate& A, double dt, const MotionOptions& opt, Vec3& v_hat_noise) {
  const double fs = 1.0 / dt;
  const int ms = std::min(A.half_width, 3);
  ShortKernels K{savitzky_golay(ms, std::min(opt.order, 2 * ms), 0, 0.0),
                 savitzky_golay(ms, std::min(opt.order, 2 * ms), 1, 0.0)};
  double nv = 0.0, nd = 0.0;
  for (int i = 0; i < 3; ++i) {
    nv += A.velocity_noise[i] * K.smooth.noise_gain();
    nd += A.position_noise[i] * K.d1.noise_gain() * fs;
  }
  K.velocity_from_positions =
      opt.accel == MotionOptions::Accel::position || (opt.accel == MotionOptions::Accel::automatic && nd < nv);
  for (int i = 0; i < 3; ++i)
    v_hat_noise[i] = K.velocity_from_positions ? A.position_noise[i] * K.d1.noise_gain() * fs
                                               : A.velocity_noise[i] * K.smooth.noise_gain();
  return K;
}

}  // namespace

SampleStates estimate_sample_states(const io::MotionData& data, const Sampling& S, const AccelerationEstimate& A,
                                    const MotionOptions& opt) {
  // Per-sample state estimate (inside each segment, m samples from its ends).
  // The velocity at a sample feeds terms nonlinear in it (sgn, the Stribeck
  // bell) that are filtered afterwards: a short kernel keeps the sharp bend
  // at a reversal (the long one rounds it and biased a Stribeck fit by 1-2 %),
  // and the noise it leaves is averaged by the filter that follows.
  const int n = static_cast<int>(data.t.size());
  const int m = A.half_width;
  const double fs = 1.0 / S.dt;
  SampleStates X;
  const ShortKernels K = short_kernels(A, S.dt, opt, X.v_hat_noise);
  X.d_hat.assign(n, Vec3::Zero());
  X.v_hat.assign(n, Vec3::Zero());
  for (int k = 0; k < n; ++k) {
    const int seg_start = S.segment_start[k];
    const int kc = std::clamp(k, seg_start + m, S.segment_end[k] - 1 - m);
    if (kc < seg_start + m) {  // segment shorter than the kernel: raw values
      X.d_hat[k] = data.d[k];
      X.v_hat[k] = data.v[k];
      continue;
    }
    // Near a segment end the polynomial of the last full window is evaluated
    // off-centre (with the full-width kernels and the rows' velocity source).
    const double off = k - kc;
    if (off == 0.0) {
      for (int i = 0; i < 3; ++i) {
        X.d_hat[k][i] = A.at_sample.apply(&data.d[kc][i], 3);
        X.v_hat[k][i] = K.velocity_from_positions ? K.d1.apply(&data.d[kc][i], 3) * fs
                                                  : K.smooth.apply(&data.v[kc][i], 3);
      }
      continue;
    }
    const SgKernel so = savitzky_golay(m, opt.order, 0, off);
    const SgKernel d1o = savitzky_golay(m, opt.order, 1, off);
    for (int i = 0; i < 3; ++i) {
      X.d_hat[k][i] = so.apply(&data.d[kc][i], 3);
      X.v_hat[k][i] = A.velocity_from_positions ? d1o.apply(&data.d[kc][i], 3) * fs : so.apply(&data.v[kc][i], 3);
    }
  }
  return X;
}

// ---- Stage 4: kept rows ---------------------------------------------------------

ForceInstrument force_instrument(int half_width) {
  // The force-gain instrument's samples (motion.hpp, f_past): a cubic through
  // `samples` on each side of the row's window, ending `past_gap` before the
  // earliest force any shift reads and starting `future_gap` after the latest.
  const int m = half_width;
  ForceInstrument I;
  I.samples = std::max(8, 2 * m);
  I.past_gap = m + MotionProblem::kShiftHi + 1;
  I.future_gap = m - MotionProblem::kShiftLo + 1;
  // Least-squares cubic through u = -(gap + n - 1) .. -gap and future_gap .. future_gap + n - 1
  // (u: samples from the row's sample k).
  for (int j = 0; j < I.samples; ++j) I.around.push_back(-(I.past_gap + I.samples - 1) + j);
  for (int j = 0; j < I.samples; ++j) I.around.push_back(I.future_gap + j);
  Eigen::MatrixXd V(static_cast<Eigen::Index>(I.around.size()), 4);
  for (std::size_t j = 0; j < I.around.size(); ++j) {
    const double u = I.around[j];
    V.row(static_cast<Eigen::Index>(j)) << 1.0, u, u * u, u * u * u;
  }
  I.fit = (V.transpose() * V).ldlt().solve(V.transpose());  // 4 x 2n
  return I;
}

std::vector<int> kept_samples(const Sampling& S, int half_width, int stride, int instrument_samples) {
  // Kept rows: full windows of both passes inside a segment. The force is
  // also read shifted by kShiftLo..kShiftHi samples (alignment).
  const int m = half_width;
  const int n = static_cast<int>(S.segment_end.size());
  const int lo = std::max(2 * m, m + MotionProblem::kShiftHi) + instrument_samples;
  const int hi = std::max(2 * m, m - MotionProblem::kShiftLo + 1) + instrument_samples;
  std::vector<int> sample;
  for (int start = 0; start < n; start = S.segment_end[start])
    for (int k = start + lo; k + hi < S.segment_end[start]; k += stride) sample.push_back(k);
  return sample;
}

namespace {

// Row r at sample k: the state half a sample later, the acceleration, the
// filtered force and the force at every whole shift.
void filter_row(const io::MotionData& data, const AccelerationEstimate& A, int k, int r, MotionProblem& P) {
  const double fs = 1.0 / P.dt;
  const HalfSampleKernels& h = A.half;
  P.t[r] = data.t[k] + 0.5 * P.dt;
  for (int i = 0; i < 3; ++i) {
    P.d[r][i] = h.smooth.apply(&data.d[k][i], 3);
    P.v[r][i] = A.velocity_from_positions ? h.d1.apply(&data.d[k][i], 3) * fs : h.smooth.apply(&data.v[k][i], 3);
    P.a[r][i] = acceleration_at(data, A, h, P.dt, k, i);
    P.f[r][i] = P.smooth_force.apply(&data.f[k][i], 3);
    for (int shift = MotionProblem::kShiftLo; shift <= MotionProblem::kShiftHi; ++shift)
      P.force_at_shift(3 * r + i, shift - MotionProblem::kShiftLo) =
          P.drive_gain[i] * P.smooth_force.apply(&data.f[k - shift][i], 3);
  }
}

}  // namespace

void check_enough_rows(const io::MotionData& data, const MotionProblem& P, int instrument_samples,
                       const MotionOptions& opt) {
  const int R = P.rows();
  if (R >= opt.min_rows) return;
  const int n = static_cast<int>(data.t.size());
  const int m = P.half_width;
  std::ostringstream os;
  os << log_name(data) << ": too few samples: " << n << " samples at " << 1.0 / P.dt << " Hz give " << R
     << " usable rows after the " << 2 * m + 1 << "-sample acceleration filter (need at least " << opt.min_rows
     << "; about " << (opt.min_rows * P.stride + 4 * m + 2 * instrument_samples) * P.dt
     << " s of motion in one piece)";
  throw Error(os.str());
}

void filter_kept_rows(const io::MotionData& data, const Sampling& S, const AccelerationEstimate& A,
                      const ForceInstrument& instrument, const MotionOptions& opt, MotionProblem& P) {
  const int R = P.rows();
  P.t.resize(R);
  P.d.resize(R);
  P.v.resize(R);
  P.a.resize(R);
  P.f.resize(R);
  P.f_predicted.resize(R);
  P.f_past.setZero(3 * R, 4);
  P.force_at_shift.resize(3 * R, MotionProblem::kShiftHi - MotionProblem::kShiftLo + 1);
  P.a_columns.resize(R);
  const int ml = kColumnKernelLength * A.half_width;
  // The columns' acceleration: 6x longer, so that it shares little of the
  // residual's noise. Of encoder noise, differentiated, it shares ~(1/6)^3; of
  // a disturbance force in the plant, which is real acceleration that both
  // estimates average, about 1/6: at 4x, logs at 250 Hz with 0.3 N of
  // disturbance per period attenuated a refitted inertia enough that drive
  // gains on x and y (-8 %, -5 %) were named beside a real inertia error; at
  // 6x, none in 136 such logs. Twice the degree, so that it still follows
  // what the closed loop puts into the motion near its bandwidth (5-10 Hz)
  // when the model is off (at degree 4 a 0.4 kg payload left 2.3x the
  // leftover of exact columns).
  const HalfSampleKernels longer = HalfSampleKernels::make(ml, std::min(2 * opt.order, 2 * ml));
  for (int r = 0; r < R; ++r) {
    const int k = P.sample[r];
    filter_row(data, A, k, r, P);
    const bool fits = k - ml >= S.segment_start[k] && k + ml < S.segment_end[k];
    for (int i = 0; i < 3; ++i) {
      for (std::size_t j = 0; j < instrument.around.size(); ++j)
        P.f_past.row(3 * r + i) +=
            instrument.fit.col(static_cast<Eigen::Index>(j)).transpose() * data.f[k + instrument.around[j]][i];
      P.a_columns[r][i] = fits ? acceleration_at(data, A, longer, P.dt, k, i) : P.a[r][i];
    }
  }
}

// ---- Stage 5: base columns -----------------------------------------------------

std::vector<BaseParameter> model_base_parameters(const ctl::Machine& model) {
  std::vector<BaseParameter> params;
  const char* names[4] = {"A", "B", "C", "E"};
  const char* units[4] = {"kg", "kg m^2", "N m", "N"};
  const double vals[4] = {model.inertia().A, model.inertia().B, model.inertia().C, model.inertia().E};
  for (int c = 0; c < 4; ++c) params.push_back({names[c], units[c], vals[c], -1, c});
  const ctl::MachineModel& mm = model.model();
  const int n_eff = mm.effects.size();
  for (int e = 0; e < n_eff; ++e) {
    const ctl::DynamicEffect& ef = mm.effects[e];
    const ctl::DynamicEffectInfo& in = ctl::info(ef.type);
    if (ef.type == ctl::DynamicEffectType::force_gain) {
      params.push_back({ef.label() + "." + in.params[0].name, in.params[0].unit, ef.param[0], e, 0});
      continue;
    }
    if (!in.per_axis) continue;  // payload, inertia error: inside A..E
    for (int j = 0; j < in.n_params; ++j)
      if (!in.params[j].nonlinear)
        params.push_back({ef.label() + "." + in.params[j].name, in.params[j].unit, ef.param[j], e, j});
  }
  return params;
}

std::vector<Perturbation> nuisance_parameters(const ctl::MachineModel& mm, MotionOptions::Nuisance kind,
                                              std::vector<BaseParameter>& params) {
  // Nuisance: the plane parameters a motion log is sensitive to. A tilted
  // plane normal couples the axes (J^T) and, with an offset, moves the pose
  // at which gravity and inertia are evaluated (offsets alone move it by
  // tenths of a mm: too little to matter, and nearly collinear with the drive
  // gains, so they are left out); Kim-sized errors of a model
  // that was not calibrated leave a structured force residual of the size
  // of the noise. The plane scales are left out: on motion data they are
  // the drive gain (force_gain), which the diagnosis must be able to name.
  std::vector<Perturbation> pert;
  for (int i = 0; i < 3 && kind == MotionOptions::Nuisance::coupling; ++i)
    for (int j = 0; j < 3; ++j)
      if (i != j)
        params.push_back({"coupling[" + std::to_string(i + 1) + "<-" + std::to_string(j + 1) + "]", "1", 0.0, -1,
                          3 * i + j, true});
  constexpr double h = 1e-4;  // rad, m
  for (int i = 0; i < 3 && kind == MotionOptions::Nuisance::tilt; ++i) {
    const Vec3 u = mm.kinematics.planes[i].normal;
    for (int t = 0; t < 2; ++t) {
      const Vec3 e = Vec3::Unit((i + 1 + t) % 3);
      const Vec3 tang = (e - e.dot(u) * u).normalized();
      ctl::MachineModel q = mm;
      q.kinematics.planes[i].normal = (u + h * tang).normalized();
      pert.push_back({ctl::Machine(q), h});
      params.push_back({"plane" + std::to_string(i + 1) + ".tilt_" + "xyz"[(i + 1 + t) % 3], "rad", 0.0, -1, 0, true});
    }
    ctl::MachineModel q = mm;
    q.kinematics.planes[i].offset += h;
    pert.push_back({ctl::Machine(q), h});
    params.push_back({"plane" + std::to_string(i + 1) + ".offset", "m", 0.0, -1, 0, true});
  }
  return pert;
}

std::vector<kin::KinematicInputs> row_kinematic_inputs(const MotionProblem& P) {
  std::vector<kin::KinematicInputs> kin_in(static_cast<std::size_t>(P.rows()));
  std::array<std::int8_t, 3> dir{+1, +1, +1};
  int last_k = 0;
  for (int r = 0; r < P.rows(); ++r) {
    const int k = P.sample[r];
    for (; last_k <= k; ++last_k)
      for (int i = 0; i < 3; ++i) {
        if (P.v_hat[last_k][i] > 1e-6) dir[i] = +1;
        if (P.v_hat[last_k][i] < -1e-6) dir[i] = -1;
      }
    kin_in[r].dir = dir;
    kin_in[r].t = P.t[r];
  }
  return kin_in;
}

namespace {

bool kinematics_is_affine(const kin::KinematicModel& m) {
  if (m.has_twist()) return false;
  for (const auto& e : m.effects)
    if (e.any()) return false;
  return true;
}

// The rigid body of `mach` at state (d, v) with actuator accelerations `acc`.
Status rigid_body_row(const ctl::Machine& mach, bool affine, const Vec3& d, const Vec3& v, const Vec3& acc,
                      const kin::KinematicInputs& in, RigidBodyRow& out) {
  Status s = mach.task_state(d, v, in, out.ts);
  out.p_dd = out.ts.J * acc;
  if (s && !affine) {
    // p_dd = J a + (d/dt J) v: the second directional derivative of p(d) along v.
    const double vn = v.norm();
    if (vn > 1e-9) {
      const double h = 1e-4 / vn;  // 0.1 mm along the motion
      Vec3 pp, pm;
      const Status s1 = kin::forward(mach.kinematics(), d + h * v, in, pp);
      const Status s2 = kin::forward(mach.kinematics(), d - h * v, in, pm);
      if (s1 && s2) out.p_dd += (pp - 2.0 * out.ts.p + pm) / (h * h);
      else s = s1 ? s2 : s1;
    }
  }
  if (s) s = mach.inverse_dynamics(out.ts.p, out.ts.p_dot, out.p_dd, out.platform_force);
  return s;
}

}  // namespace

Eigen::VectorXd rigid_body_force(const ctl::Machine& machine, const io::MotionData& data, const MotionProblem& P,
                                 const std::vector<kin::KinematicInputs>& kin_in, const std::vector<Vec3>& acc,
                                 const std::function<void(int, const RigidBodyRow&)>& each_row) {
  const int R = P.rows();
  Eigen::VectorXd out(3 * R);
  const bool affine = kinematics_is_affine(machine.kinematics());
  for (int r = 0; r < R; ++r) {
    RigidBodyRow row;
    const Status s = rigid_body_row(machine, affine, P.d[r], P.v[r], acc[r], kin_in[r], row);
    if (!s) {
      std::ostringstream os;
      os << where(data, P.sample[r]) << ": the model cannot follow the logged motion at d = ("
         << P.d[r].x() * 1e3 << ", " << P.d[r].y() * 1e3 << ", " << P.d[r].z() * 1e3 << ") mm: " << describe(s);
      throw Error(os.str());
    }
    out.segment<3>(3 * r) = row.ts.J.transpose() * row.platform_force;
    if (each_row) each_row(r, row);
  }
  return out;
}

namespace {

// The model's own row: its platform force, the coupling nuisance columns (the
// platform force itself) and the A..E columns, each the difference to a
// machine with that constant + 1 (the dynamics is linear in them).
void model_row_columns(const std::vector<ctl::Machine>& unit, int n_model_base, bool coupling, int r,
                       const RigidBodyRow& row, MotionProblem& P) {
  const Vec3& F0 = row.platform_force;
  P.platform_force[r] = F0;
  if (coupling)
    for (int b = n_model_base; b < static_cast<int>(P.base_params.size()); ++b)
      P.base(3 * r + P.base_params[b].param / 3, b) = F0[P.base_params[b].param % 3];
  for (int c = 0; c < 4; ++c) {
    Vec3 Fc;
    unit[c].inverse_dynamics(row.ts.p, row.ts.p_dot, row.p_dd, Fc);
    P.base.block<3, 1>(3 * r, c) = row.ts.J.transpose() * (Fc - F0);
  }
}

// The model's own additive effects in its force, the alignment the model
// states, and the columns of the effects' linear parameters (base_params 4..).
void add_model_effects(const ctl::Machine& model, int n_model_base, MotionProblem& P) {
  const ctl::MachineModel& mm = model.model();
  const int n_eff = mm.effects.size();
  for (int e = 0; e < n_eff; ++e) {
    const ctl::DynamicEffect& ef = mm.effects[e];
    // force_gain scales the command; actuator_inertia is in the rigid body's M already.
    if (ef.axis < 0 || ef.type == ctl::DynamicEffectType::force_gain ||
        ef.type == ctl::DynamicEffectType::actuator_inertia)
      continue;
    P.model_force += P.effect_force_column(ef);
  }
  // The user effects of the model file (docs/effects.md, "Effects you add").
  if (model.has_user_effects()) P.model_force += P.user_force_column(mm.user_effects);
  // The force acts as the model says it does (its own actuation_delay), until
  // the alignment stage (align.hpp) estimates it from the data.
  P.delay_model = model.actuation_delay();
  P.set_delay(std::clamp(P.delay_model, MotionProblem::kShiftLo * P.dt, MotionProblem::kShiftHi * P.dt));
  for (int b = 4; b < n_model_base; ++b) {
    const BaseParameter& bp = P.base_params[b];
    const ctl::DynamicEffect& ef = mm.effects[bp.effect];
    if (ef.type == ctl::DynamicEffectType::force_gain)
      P.base.col(b) = P.force_gain_column(ef.axis) / (1.0 + ef.param[0]);
    else
      P.base.col(b) = P.effect_column(ef, bp.param);
  }
}

}  // namespace

std::vector<ctl::Machine> unit_inertia_machines(const ctl::MachineModel& mm) {
  std::vector<ctl::Machine> unit;
  for (int c = 0; c < 4; ++c) {
    ctl::MachineModel u = mm;
    std::vector<double> dv(4, 0.0);
    dv[c] = 1.0;
    ctl::add_effect(u, "inertia_error", -1, dv);
    unit.emplace_back(u);
  }
  return unit;
}

void add_base_columns(const io::MotionData& data, const ctl::Machine& model, const MotionOptions& opt,
                      MotionProblem& P) {
  const std::vector<ctl::Machine> unit = unit_inertia_machines(model.model());
  P.base_params = model_base_parameters(model);
  const int n_model_base = static_cast<int>(P.base_params.size());
  const std::vector<Perturbation> pert = nuisance_parameters(model.model(), opt.nuisance, P.base_params);
  const int R = P.rows();
  P.base.setZero(3 * R, static_cast<Eigen::Index>(P.base_params.size()));
  P.platform_force.resize(R);
  P.residual.setZero(3 * R);
  const std::vector<kin::KinematicInputs> kin_in = row_kinematic_inputs(P);
  // The residual is evaluated with the row accelerations P.a, every column
  // with P.a_columns (see motion.hpp).
  P.model_force = rigid_body_force(model, data, P, kin_in, P.a);
  const bool coupling = opt.nuisance == MotionOptions::Nuisance::coupling;
  const Eigen::VectorXd F_columns =
      rigid_body_force(model, data, P, kin_in, P.a_columns, [&](int r, const RigidBodyRow& row) {
        model_row_columns(unit, n_model_base, coupling, r, row, P);
      });
  for (std::size_t q = 0; q < pert.size(); ++q) {
    Eigen::VectorXd Fq;
    try {
      Fq = rigid_body_force(pert[q].machine, data, P, kin_in, P.a_columns);
    } catch (const Error&) {
      continue;  // a perturbed machine that cannot follow: leave its column at zero
    }
    P.base.col(n_model_base + static_cast<int>(q)) = (Fq - F_columns) / pert[q].step;
  }
  add_model_effects(model, n_model_base, P);
  // Noise the acceleration estimate adds to the force, through the diagonal of M.
  for (int i = 0; i < 3; ++i) P.force_noise[i] = 2.0 * model.inertia().A * P.accel_noise[i];
}

}  // namespace cpm::ident::motion_stages
