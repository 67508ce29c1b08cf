#include "cpm/identification/motion.hpp"

#include <algorithm>
#include <cmath>
#include <sstream>

#include "cpm/identification/stats.hpp"

namespace cpm::ident {
namespace {

std::string where(const io::MotionData& data, int k) {
  std::ostringstream os;
  os << (data.info.path.empty() ? "motion log" : data.info.path);
  if (k >= 0 && k < static_cast<int>(data.info.line_of_row.size()))
    os << ":" << data.info.line_of_row[k];
  else
    os << " (sample " << k + 1 << ")";
  return os.str();
}

bool kinematics_is_affine(const kin::KinematicModel& m) {
  if (m.has_twist()) return false;
  for (const auto& e : m.effects)
    if (e.any()) return false;
  return true;
}

// White-noise sigma of a series from what a zero-phase smoother removes,
// robust to the few samples where the motion itself is sharp.
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

}  // namespace

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
  return filter_axis(i, [&](int k, int ax) {
    return noise_expectation([&](double vel) { return ctl::effect_force_gradient(e, j, d_hat[k][ax], vel); },
                             v_hat[k][ax], v_hat_noise[ax]);
  });
}

Eigen::VectorXd MotionProblem::effect_force_column(const ctl::DynamicEffect& e) const {
  return filter_axis(e.axis, [&](int k, int ax) {
    return noise_expectation([&](double vel) { return ctl::effect_force(e, d_hat[k][ax], vel); }, v_hat[k][ax],
                             v_hat_noise[ax]);
  });
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

Eigen::VectorXd MotionProblem::force_delayed(double tau) const {
  const double x = std::clamp(tau / dt, double(kShiftLo), double(kShiftHi)) - kShiftLo;
  const int n = std::min(static_cast<int>(std::floor(x)), kShiftHi - kShiftLo - 1);
  const double phi = x - n;
  return (1.0 - phi) * force_at_shift.col(n) + phi * force_at_shift.col(n + 1);
}

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

MotionProblem prepare_motion(const io::MotionData& data, const ctl::Machine& model,
                             const MotionOptions& opt) {
  opt.validate();
  const int n = static_cast<int>(data.t.size());
  const std::string name = data.info.path.empty() ? "motion log" : data.info.path;
  if (data.d.size() != data.t.size() || data.v.size() != data.t.size() ||
      data.f.size() != data.t.size() || (!data.a.empty() && data.a.size() != data.t.size()))
    throw Error(name + ": columns of different lengths");
  if (n < 10)
    throw Error(name + ": too few samples (" + std::to_string(n) +
                ") to estimate accelerations and fit anything");
  MotionProblem P;
  // Sample period: the median step; a step far from it (or a new run) starts a segment.
  std::vector<double> steps;
  for (int k = 1; k < n; ++k) {
    const double h = data.t[k] - data.t[k - 1];
    const bool same_run = data.run.empty() || data.run[k] == data.run[k - 1];
    if (same_run && !(h > 0.0))
      throw Error(where(data, k) + ": time does not increase (t = " + std::to_string(data.t[k]) +
                  " s after " + std::to_string(data.t[k - 1]) + " s)");
    if (same_run) steps.push_back(h);
  }
  if (steps.empty()) throw Error(name + ": no two consecutive samples in the same run");
  P.dt = median(steps);
  const double fs = 1.0 / P.dt;
  const int m = std::max(2, static_cast<int>(std::lround(opt.half_window * fs)));
  if (opt.order >= 2 * m + 1)
    throw Error(name + ": sample rate " + std::to_string(fs) + " Hz is too low for a " +
                std::to_string(opt.half_window * 1e3) + " ms filter");
  P.half_width = m;
  P.stride = opt.stride > 0 ? opt.stride : m;
  P.t_sample = data.t;
  P.f_sample = data.f;
  P.line.assign(n, 0);
  for (int k = 0; k < n && k < static_cast<int>(data.info.line_of_row.size()); ++k)
    P.line[k] = data.info.line_of_row[k];
  P.segment_end.assign(n, n);
  {
    int start = 0;
    for (int k = 1; k <= n; ++k) {
      const bool cut = k == n || (!data.run.empty() && data.run[k] != data.run[k - 1]) ||
                       std::fabs((data.t[k] - data.t[k - 1]) - P.dt) > 0.25 * P.dt;
      if (cut) {
        for (int q = start; q < k; ++q) P.segment_end[q] = k;
        ++P.segments;
        if (k < n && (data.run.empty() || data.run[k] == data.run[k - 1])) {
          std::ostringstream os;
          os << where(data, k) << ": sampling gap of " << (data.t[k] - data.t[k - 1]) * 1e3
             << " ms (period " << P.dt * 1e3 << " ms); the log is split there";
          P.warnings.push_back(os.str());
        }
        start = k;
      }
    }
  }

  // Kernels: state estimate at each sample (offset 0); filter of both sides
  // at the rows (force at 0, state at +1/2).
  const SgKernel s0 = savitzky_golay(m, opt.order, 0, 0.0);
  const SgKernel d1_0 = savitzky_golay(m, opt.order, 1, 0.0);
  const SgKernel sh = savitzky_golay(m, opt.order, 0, 0.5);
  const SgKernel d1h = savitzky_golay(m, opt.order, 1, 0.5);
  const SgKernel d2h = savitzky_golay(m, opt.order, 2, 0.5);
  P.accel_kernel = d1h;

  // Noise of the logged positions and velocities, per axis.
  std::vector<double> x(n);
  for (int i = 0; i < 3; ++i) {
    for (int k = 0; k < n; ++k) x[k] = data.d[k][i];
    P.position_noise[i] = smoother_noise(x, s0);
    for (int k = 0; k < n; ++k) x[k] = data.v[k][i];
    P.velocity_noise[i] = smoother_noise(x, s0);
  }
  const bool measured = !data.a.empty();
  // Velocity estimate and acceleration source: whichever adds less noise.
  bool v_from_d = false, a_from_d = false;
  Vec3 acc_noise_v, acc_noise_d, vel_noise_v, vel_noise_d;
  for (int i = 0; i < 3; ++i) {
    vel_noise_v[i] = P.velocity_noise[i] * s0.noise_gain();
    vel_noise_d[i] = P.position_noise[i] * d1_0.noise_gain() * fs;
    acc_noise_v[i] = P.velocity_noise[i] * d1h.noise_gain() * fs;
    acc_noise_d[i] = P.position_noise[i] * d2h.noise_gain() * fs * fs;
  }
  if (opt.accel == MotionOptions::Accel::position) a_from_d = v_from_d = true;
  else if (opt.accel == MotionOptions::Accel::automatic) {
    a_from_d = acc_noise_d.sum() < acc_noise_v.sum();
    v_from_d = vel_noise_d.sum() < vel_noise_v.sum();
  }
  if (measured) {
    P.accel_source = "measured (a1..a3), filtered like the force";
    P.accel_noise.setZero();
  } else if (a_from_d) {
    P.accel_kernel = d2h;
    P.accel_source = "2nd derivative of the positions (zero-phase Savitzky-Golay)";
    P.accel_noise = acc_noise_d;
  } else {
    P.accel_source = "1st derivative of the velocities (zero-phase Savitzky-Golay)";
    P.accel_noise = acc_noise_v;
  }
  // Both sides of the equation through the same weights: the force side
  // through those with which the acceleration estimate sums the interval
  // accelerations of the zero-order hold, the effects (continuous forces)
  // through their trapezoid version. Measured accelerations are samples of
  // their own: a smoother at the force's sample and half a sample later.
  if (measured) {
    P.smooth_force = s0;
    P.smooth_state = sh;
  } else {
    P.smooth_force = zoh_force_kernel(P.accel_kernel, a_from_d ? 2 : 1);
    P.smooth_state = zoh_state_kernel(P.smooth_force);
  }

  // Per-sample state estimate (inside each segment, m samples from its ends).
  // The velocity at a sample feeds terms nonlinear in it (sgn, the Stribeck
  // bell) that are filtered afterwards: a short kernel keeps the sharp bend
  // at a reversal (the long one rounds it and biased a Stribeck fit by 1-2 %),
  // and the noise it leaves is averaged by the filter that follows.
  const int ms = std::min(m, 3);
  const SgKernel s_short = savitzky_golay(ms, std::min(opt.order, 2 * ms), 0, 0.0);
  const SgKernel d1_short = savitzky_golay(ms, std::min(opt.order, 2 * ms), 1, 0.0);
  bool vs_from_d = false;  // which short estimate is less noisy
  {
    double nv = 0.0, nd = 0.0;
    for (int i = 0; i < 3; ++i) {
      nv += P.velocity_noise[i] * s_short.noise_gain();
      nd += P.position_noise[i] * d1_short.noise_gain() * fs;
    }
    vs_from_d = opt.accel == MotionOptions::Accel::position || (opt.accel == MotionOptions::Accel::automatic && nd < nv);
    for (int i = 0; i < 3; ++i)
      P.v_hat_noise[i] = vs_from_d ? P.position_noise[i] * d1_short.noise_gain() * fs
                                   : P.velocity_noise[i] * s_short.noise_gain();
  }
  // First sample of each sample's segment (a walk back per sample made this quadratic in n).
  std::vector<int> segment_start(static_cast<std::size_t>(n), 0);
  for (int k = 1; k < n; ++k)
    segment_start[k] = P.segment_end[k - 1] == P.segment_end[k] ? segment_start[k - 1] : k;
  P.d_hat.assign(n, Vec3::Zero());
  P.v_hat.assign(n, Vec3::Zero());
  for (int k = 0; k < n; ++k) {
    const int seg_end = P.segment_end[k];
    const int seg_start = segment_start[k];
    const int kc = std::clamp(k, seg_start + m, seg_end - 1 - m);
    if (kc < seg_start + m) {  // segment shorter than the kernel: raw values
      P.d_hat[k] = data.d[k];
      P.v_hat[k] = data.v[k];
      continue;
    }
    for (int i = 0; i < 3; ++i) {
      // Near a segment end the polynomial of the last full window is evaluated off-centre.
      const double off = k - kc;
      if (off == 0.0) {
        P.d_hat[k][i] = s0.apply(&data.d[kc][i], 3);
        P.v_hat[k][i] = vs_from_d ? d1_short.apply(&data.d[kc][i], 3) * fs : s_short.apply(&data.v[kc][i], 3);
      } else {
        const SgKernel so = savitzky_golay(m, opt.order, 0, off);
        const SgKernel d1o = savitzky_golay(m, opt.order, 1, off);
        P.d_hat[k][i] = so.apply(&data.d[kc][i], 3);
        P.v_hat[k][i] = v_from_d ? d1o.apply(&data.d[kc][i], 3) * fs : so.apply(&data.v[kc][i], 3);
      }
    }
  }

  // The force-gain instrument's samples (motion.hpp, f_past): a cubic through
  // `past_n` samples on each side of the row's window, ending `past_gap`
  // before the earliest force any shift reads and starting `future_gap` after
  // the latest.
  const int past_n = std::max(8, 2 * m);
  P.past_samples = past_n;
  P.past_gap = m + MotionProblem::kShiftHi + 1;
  P.future_gap = m - MotionProblem::kShiftLo + 1;
  const int past = past_n;
  // Kept rows: full windows of both passes inside a segment.
  {
    int start = 0;
    while (start < n) {
      const int end = P.segment_end[start];
      // The force is also read shifted by kShiftLo..kShiftHi samples (alignment).
      const int lo = std::max(2 * m, m + MotionProblem::kShiftHi) + past;
      const int hi = std::max(2 * m, m - MotionProblem::kShiftLo + 1) + past;
      for (int k = start + lo; k + hi < end; k += P.stride) P.sample.push_back(k);
      start = end;
    }
  }
  const int R = static_cast<int>(P.sample.size());
  if (R < opt.min_rows) {
    std::ostringstream os;
    os << name << ": too few samples: " << n << " samples at " << fs << " Hz give " << R
       << " usable rows after the " << 2 * m + 1 << "-sample acceleration filter (need at least "
       << opt.min_rows << "; about " << (opt.min_rows * P.stride + 4 * m + 2 * past) * P.dt
       << " s of motion in one piece)";
    throw Error(os.str());
  }
  P.t.resize(R);
  P.d.resize(R);
  P.v.resize(R);
  P.a.resize(R);
  P.f.resize(R);
  P.drive_gain = model.drive_gain();
  P.f_predicted.resize(R);
  P.f_past.setZero(3 * R, 4);
  // Least-squares cubic through u = -(gap + n - 1) .. -gap and future_gap .. future_gap + n - 1
  // (u: samples from the row's sample k).
  std::vector<int> around;
  for (int j = 0; j < past_n; ++j) around.push_back(-(P.past_gap + past_n - 1) + j);
  for (int j = 0; j < past_n; ++j) around.push_back(P.future_gap + j);
  Eigen::MatrixXd around_fit;
  {
    Eigen::MatrixXd V(static_cast<Eigen::Index>(around.size()), 4);
    for (std::size_t j = 0; j < around.size(); ++j) {
      const double u = around[j];
      V.row(static_cast<Eigen::Index>(j)) << 1.0, u, u * u, u * u * u;
    }
    around_fit = (V.transpose() * V).ldlt().solve(V.transpose());  // 4 x 2n
  }
  P.force_at_shift.resize(3 * R, MotionProblem::kShiftHi - MotionProblem::kShiftLo + 1);
  P.a_columns.resize(R);
  const int ml = 4 * m;
  // The columns' acceleration: 4x longer, so its noise shares ~1/64 of the
  // residual's; twice the degree, so that it still follows what the closed
  // loop puts into the motion near its bandwidth (5-10 Hz) when the model is
  // off (at degree 4 a 0.4 kg payload left 2.3x the leftover of exact columns).
  const int oc = std::min(2 * opt.order, 2 * ml);
  const SgKernel sh_long = savitzky_golay(ml, oc, 0, 0.5);
  const SgKernel d1h_long = savitzky_golay(ml, oc, 1, 0.5);
  const SgKernel d2h_long = savitzky_golay(ml, oc, 2, 0.5);
  for (int r = 0; r < R; ++r) {
    const int k = P.sample[r];
    P.t[r] = data.t[k] + 0.5 * P.dt;
    for (int i = 0; i < 3; ++i) {
      P.d[r][i] = sh.apply(&data.d[k][i], 3);
      P.v[r][i] = v_from_d ? d1h.apply(&data.d[k][i], 3) * fs : sh.apply(&data.v[k][i], 3);
      if (measured) P.a[r][i] = sh.apply(&data.a[k][i], 3);
      else if (a_from_d) P.a[r][i] = d2h.apply(&data.d[k][i], 3) * fs * fs;
      else P.a[r][i] = d1h.apply(&data.v[k][i], 3) * fs;
      P.f[r][i] = P.smooth_force.apply(&data.f[k][i], 3);
      for (int shift = MotionProblem::kShiftLo; shift <= MotionProblem::kShiftHi; ++shift)
        P.force_at_shift(3 * r + i, shift - MotionProblem::kShiftLo) =
            model.drive_gain()[i] * P.smooth_force.apply(&data.f[k - shift][i], 3);
    }
    const int seg_start = segment_start[k];
    const bool fits = k - ml >= seg_start && k + ml < P.segment_end[k];
    for (int i = 0; i < 3; ++i) {
      for (std::size_t j = 0; j < around.size(); ++j)
        P.f_past.row(3 * r + i) += around_fit.col(static_cast<Eigen::Index>(j)).transpose() * data.f[k + around[j]][i];
      if (!fits) P.a_columns[r][i] = P.a[r][i];
      else if (measured) P.a_columns[r][i] = sh_long.apply(&data.a[k][i], 3);
      else if (a_from_d) P.a_columns[r][i] = d2h_long.apply(&data.d[k][i], 3) * fs * fs;
      else P.a_columns[r][i] = d1h_long.apply(&data.v[k][i], 3) * fs;
    }
  }

  // The model and its base columns: dynamics is linear in A, B, C, E, so
  // each column is the difference to a machine with that constant + 1.
  const ctl::MachineModel& mm = model.model();
  std::vector<ctl::Machine> unit;
  for (int c = 0; c < 4; ++c) {
    ctl::MachineModel u = mm;
    std::vector<double> dv(4, 0.0);
    dv[c] = 1.0;
    ctl::add_effect(u, "inertia_error", -1, dv);
    unit.emplace_back(u);
  }
  const char* names[4] = {"A", "B", "C", "E"};
  const char* units[4] = {"kg", "kg m^2", "N m", "N"};
  const double vals[4] = {model.inertia().A, model.inertia().B, model.inertia().C, model.inertia().E};
  for (int c = 0; c < 4; ++c) P.base_params.push_back({names[c], units[c], vals[c], -1, c});
  const int n_eff = mm.effects.size();
  for (int e = 0; e < n_eff; ++e) {
    const ctl::DynamicEffect& ef = mm.effects[e];
    const ctl::DynamicEffectInfo& in = ctl::info(ef.type);
    if (ef.type == ctl::DynamicEffectType::force_gain) {
      P.base_params.push_back({ef.label() + "." + in.params[0].name, in.params[0].unit, ef.param[0], e, 0});
      continue;
    }
    if (!in.per_axis) continue;  // payload, inertia error: inside A..E
    for (int j = 0; j < in.n_params; ++j)
      if (!in.params[j].nonlinear)
        P.base_params.push_back({ef.label() + "." + in.params[j].name, in.params[j].unit, ef.param[j], e, j});
  }
  // Nuisance: the plane parameters a motion log is sensitive to. A tilted
  // plane normal couples the axes (J^T) and, with an offset, moves the pose
  // at which gravity and inertia are evaluated (offsets alone move it by
  // tenths of a mm: too little to matter, and nearly collinear with the drive
  // gains, so they are left out); Kim-sized errors of a model
  // that was not calibrated leave a structured force residual of the size
  // of the noise. The plane scales are left out: on motion data they are
  // the drive gain (force_gain), which the diagnosis must be able to name.
  const int n_model_base = static_cast<int>(P.base_params.size());
  std::vector<ctl::Machine> pert;
  std::vector<double> pert_step;
  for (int i = 0; i < 3 && opt.nuisance == MotionOptions::Nuisance::coupling; ++i)
    for (int j = 0; j < 3; ++j)
      if (i != j)
        P.base_params.push_back({"coupling[" + std::to_string(i + 1) + "<-" + std::to_string(j + 1) + "]", "1", 0.0,
                                 -1, 3 * i + j, true});
  for (int i = 0; i < 3 && opt.nuisance == MotionOptions::Nuisance::tilt; ++i) {
    const Vec3 u = mm.kinematics.planes[i].normal;
    for (int t = 0; t < 2; ++t) {
      const Vec3 e = Vec3::Unit((i + 1 + t) % 3);
      const Vec3 tang = (e - e.dot(u) * u).normalized();
      ctl::MachineModel q = mm;
      const double h = 1e-4;
      q.kinematics.planes[i].normal = (u + h * tang).normalized();
      pert.emplace_back(q);
      pert_step.push_back(h);
      BaseParameter bp{"plane" + std::to_string(i + 1) + ".tilt_" + "xyz"[(i + 1 + t) % 3], "rad", 0.0, -1, 0, true};
      P.base_params.push_back(bp);
    }
    ctl::MachineModel q = mm;
    const double h = 1e-4;
    q.kinematics.planes[i].offset += h;
    pert.emplace_back(q);
    pert_step.push_back(h);
    P.base_params.push_back({"plane" + std::to_string(i + 1) + ".offset", "m", 0.0, -1, 0, true});
  }
  const int nb = static_cast<int>(P.base_params.size());
  P.base.setZero(3 * R, nb);
  P.platform_force.resize(R);
  P.residual.setZero(3 * R);

  // Kinematic inputs of each row: direction each axis last moved, time.
  std::vector<kin::KinematicInputs> kin_in(R);
  {
    std::array<std::int8_t, 3> dir{+1, +1, +1};
    int last_k = 0;
    for (int r = 0; r < R; ++r) {
      const int k = P.sample[r];
      for (; last_k <= k; ++last_k)
        for (int i = 0; i < 3; ++i) {
          if (P.v_hat[last_k][i] > 1e-6) dir[i] = +1;
          if (P.v_hat[last_k][i] < -1e-6) dir[i] = -1;
        }
      kin_in[r].dir = dir;
      kin_in[r].t = P.t[r];
    }
  }
  // The rigid-body actuator force of a machine at every row, with the
  // accelerations `acc`; for the model itself (`primary`) also the A..E
  // columns (the dynamics is linear in them: each column is the difference
  // to a machine with that constant + 1). The residual is evaluated with the
  // row accelerations P.a, every column with P.a_columns (see motion.hpp).
  auto rigid = [&](const ctl::Machine& mach, const std::vector<Vec3>& acc, bool primary, Eigen::VectorXd& out) {
    out.resize(3 * R);
    const bool affine = kinematics_is_affine(mach.kinematics());
    for (int r = 0; r < R; ++r) {
      const int k = P.sample[r];
      ctl::TaskState ts;
      Status s = mach.task_state(P.d[r], P.v[r], kin_in[r], ts);
      Vec3 p_dd = ts.J * acc[r];
      if (s && !affine) {
        // p_dd = J a + (d/dt J) v: the second directional derivative of p(d) along v.
        const double vn = P.v[r].norm();
        if (vn > 1e-9) {
          const double h = 1e-4 / vn;  // 0.1 mm along the motion
          Vec3 pp, pm;
          const Status s1 = kin::forward(mach.kinematics(), P.d[r] + h * P.v[r], kin_in[r], pp);
          const Status s2 = kin::forward(mach.kinematics(), P.d[r] - h * P.v[r], kin_in[r], pm);
          if (s1 && s2) p_dd += (pp - 2.0 * ts.p + pm) / (h * h);
          else s = s1 ? s2 : s1;
        }
      }
      Vec3 F0;
      if (s) s = mach.inverse_dynamics(ts.p, ts.p_dot, p_dd, F0);
      if (!s) {
        std::ostringstream os;
        os << where(data, k) << ": the model cannot follow the logged motion at d = ("
           << P.d[r].x() * 1e3 << ", " << P.d[r].y() * 1e3 << ", " << P.d[r].z() * 1e3
           << ") mm: " << describe(s);
        throw Error(os.str());
      }
      out.segment<3>(3 * r) = ts.J.transpose() * F0;
      if (!primary) continue;
      P.platform_force[r] = F0;
      if (opt.nuisance == MotionOptions::Nuisance::coupling)
        for (int b = n_model_base; b < static_cast<int>(P.base_params.size()); ++b)
          P.base(3 * r + P.base_params[b].param / 3, b) = F0[P.base_params[b].param % 3];
      for (int c = 0; c < 4; ++c) {
        Vec3 Fc;
        unit[c].inverse_dynamics(ts.p, ts.p_dot, p_dd, Fc);
        P.base.block<3, 1>(3 * r, c) = ts.J.transpose() * (Fc - F0);
      }
    }
  };
  Eigen::VectorXd F_model, F_columns;
  rigid(model, P.a, false, F_model);
  rigid(model, P.a_columns, true, F_columns);
  P.model_force = F_model;
  for (std::size_t q = 0; q < pert.size(); ++q) {
    Eigen::VectorXd Fq;
    try {
      rigid(pert[q], P.a_columns, false, Fq);
    } catch (const Error&) {
      continue;  // a perturbed machine that cannot follow: leave its column at zero
    }
    P.base.col(n_model_base + static_cast<int>(q)) = (Fq - F_columns) / pert_step[q];
  }
  // The model's own additive effects and their linear parameters.
  for (int e = 0; e < n_eff; ++e) {
    const ctl::DynamicEffect& ef = mm.effects[e];
    if (ef.axis < 0 || ef.type == ctl::DynamicEffectType::force_gain) continue;
    P.model_force += P.effect_force_column(ef);
  }
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
  // Noise the acceleration estimate adds to the force, through the diagonal of M.
  for (int i = 0; i < 3; ++i) P.force_noise[i] = 2.0 * model.inertia().A * P.accel_noise[i];
  return P;
}

}  // namespace cpm::ident
