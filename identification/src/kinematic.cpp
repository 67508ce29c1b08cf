// SPDX-License-Identifier: Apache-2.0
// The kinematic problem (stage 1, read; stage 3's linear problem): the data,
// the residual of the model as given, the base calibrated at the model's own
// effects, the residual's sensitivity to each axis' effective displacement.
#include "cpm/identification/kinematic.hpp"

#include <algorithm>
#include <cmath>

#include "kinematic_internal.hpp"
#include "cpm/kinematics/kinematic_effects.hpp"

namespace cpm::ident {

namespace kinematic_detail {

std::string where(const KinematicProblem& P, int j) {
  const int line = j < static_cast<int>(P.line.size()) ? P.line[static_cast<std::size_t>(j)] : 0;
  return P.data_file + (line > 0 ? ":" + std::to_string(line) : " (sample " + std::to_string(j + 1) + ")");
}

KinematicEffects combine(const KinematicEffects& own, const KinematicEffects& extra) {
  KinematicEffects e = own;
  for (int i = 0; i < 3; ++i) {
    const auto& x = extra[i];
    auto& o = e[i];
    o.backlash += x.backlash;
    if (x.cyclic_amplitude != 0.0) {
      o.cyclic_amplitude = x.cyclic_amplitude;
      o.cyclic_wavelength = x.cyclic_wavelength;
      o.cyclic_phase = x.cyclic_phase;
    }
    o.guide_ka += x.guide_ka;
    o.guide_kb += x.guide_kb;
    o.twist += x.twist;
    if (x.thermal_expansion != 0.0) {
      o.thermal_expansion = x.thermal_expansion;
      o.thermal_time_constant = x.thermal_time_constant;
    }
    o.actuator_scale += x.actuator_scale;
  }
  return e;
}

namespace {

std::array<kin::LimbPlane, 3> planes_from_vector(const Eigen::VectorXd& x) {
  std::array<kin::LimbPlane, 3> pl{};
  for (int i = 0; i < 3; ++i) {
    pl[i].normal = cal::normal_from_tilts(i, x(4 * i), x(4 * i + 1));
    pl[i].scale = x(4 * i + 2);
    pl[i].offset = x(4 * i + 3);
  }
  return pl;
}

Eigen::VectorXd vector_from_planes(const std::array<kin::LimbPlane, 3>& pl) {
  Eigen::VectorXd x(12);
  for (int i = 0; i < 3; ++i) {
    double ta = 0, tb = 0;
    cal::tilts_from_normal(i, pl[i].normal, ta, tb);
    x.segment<4>(4 * i) << ta, tb, pl[i].scale, pl[i].offset;
  }
  return x;
}

}  // namespace

kin::KinematicModel frame_model(const KinematicProblem& P, const Eigen::VectorXd& x, const KinematicEffects& eff) {
  kin::KinematicModel m = P.given;
  m.planes = P.kind == "ballbar" ? cal::ballbar_frame_planes(cal::BallbarParameters::from_vector(x))
                                 : planes_from_vector(x);
  m.effects = eff;
  return m;
}

Eigen::VectorXd frame_residual(const KinematicProblem& P, const kin::KinematicModel& m, const Vec3& dq, double dl,
                               int axis, double shift) {
  Eigen::VectorXd r(P.rows());
  for (int j = 0; j < P.samples(); ++j) {
    Vec3 d = P.d[static_cast<std::size_t>(j)];
    if (axis >= 0) d[axis] += shift;
    Vec3 p;
    if (Status st = kin::forward(m, d, P.inputs[static_cast<std::size_t>(j)], p); !st)
      throw Error(where(P, j) + ": the model cannot follow these readings: " + describe(st));
    if (P.kind == "ballbar")
      r(j) = (p - (P.pivot + dq)).norm() - (P.length[static_cast<std::size_t>(j)] + dl);
    else
      r.segment<3>(3 * j) = p - P.p[static_cast<std::size_t>(j)];
  }
  return r;
}

void split_ballbar(const KinematicProblem& P, const Eigen::VectorXd& x, Vec3& dq, double& dl) {
  dq.setZero();
  dl = 0.0;
  if (P.kind != "ballbar") return;
  const cal::BallbarParameters b = cal::BallbarParameters::from_vector(x);
  dq = b.dq;
  dl = b.dl;
}

Eigen::VectorXd effect_difference(const KinematicProblem& P, kin::KinematicEffectType t, int axis, int param,
                                  double eps) {
  Vec3 dq;
  double dl;
  split_ballbar(P, P.base_value, dq, dl);
  auto at = [&](double v) {
    KinematicEffects x{};
    std::array<double, 3> vals{0, 0, 0};
    vals[static_cast<std::size_t>(param)] = v;
    kin::set_params(x[axis], t, vals);
    return frame_residual(P, frame_model(P, P.base_value, combine(P.given.effects, x)), dq, dl);
  };
  return (at(eps) - at(-eps)) / (2.0 * eps);
}

}  // namespace kinematic_detail

using namespace kinematic_detail;

// ---------------------------------------------------------------------------
// The problem

kin::KinematicModel KinematicProblem::model_of(const Eigen::VectorXd& x, const KinematicEffects& effects) const {
  kin::KinematicModel m = given;
  m.effects = effects;
  if (kind == "ballbar") return cal::ballbar_to_machine(cal::BallbarParameters::from_vector(x), pivot, m);
  m.planes = planes_from_vector(x);
  return m;
}

Eigen::VectorXd KinematicProblem::residual_of(const Eigen::VectorXd& x, const KinematicEffects& extra) const {
  Vec3 dq;
  double dl;
  split_ballbar(*this, x, dq, dl);
  return frame_residual(*this, frame_model(*this, x, combine(given.effects, extra)), dq, dl);
}

Eigen::VectorXd KinematicProblem::residual_of_model(const kin::KinematicModel& m) const {
  Eigen::VectorXd r = frame_residual(*this, m, Vec3::Zero(), 0.0);
  // An uncalibrated bar: its offset is not the machine's; compare shapes.
  if (kind == "ballbar" && with_dl && r.size()) r.array() -= r.mean();
  return r;
}

KinematicSpan span_of(const KinematicProblem& P) {
  KinematicSpan s;
  for (int j = 0; j < P.samples(); ++j) {
    const auto& in = P.inputs[static_cast<std::size_t>(j)];
    for (int i = 0; i < 3; ++i) {
      s.lo[i] = std::min(s.lo[i], P.d[static_cast<std::size_t>(j)][i]);
      s.hi[i] = std::max(s.hi[i], P.d[static_cast<std::size_t>(j)][i]);
      (in.dir[i] > 0 ? s.n_plus : s.n_minus)[i]++;
    }
    s.t0 = std::min(s.t0, in.t);
    s.t1 = std::max(s.t1, in.t);
  }
  return s;
}

// ---------------------------------------------------------------------------
// Stage 1: read

namespace {

// The columns of the file every kind has (dir, t, run) and where it came from.
void read_common(KinematicProblem& P, const io::CommonColumns& extra, const io::FileInfo& info) {
  P.data_file = info.path.empty() ? std::string("data") : info.path;
  P.line = info.line_of_row;
  P.warnings = info.warnings;
  P.run = extra.run;
  const std::size_t n = P.d.size();
  P.has_dir = extra.dir.size() == n && n > 0;
  P.has_time = extra.t.size() == n && n > 0;
  P.inputs.assign(n, kin::KinematicInputs{});
  for (std::size_t j = 0; j < n; ++j) {
    if (P.has_dir) P.inputs[j].dir = extra.dir[j];
    if (P.has_time) P.inputs[j].t = extra.t[j];
  }
}

}  // namespace

KinematicProblem kinematic_detail::read_problem(const io::DataSet& data, const kin::KinematicModel& model) {
  model.validate();
  KinematicProblem P;
  P.given = model;
  if (const auto* b = std::get_if<io::BallbarData>(&data)) {
    P.kind = "ballbar";
    P.per_sample = 1;
    P.d = b->d;
    P.length = b->length;
    P.pivot = b->pivot;
    P.with_dl = !b->length_offset_known;
    read_common(P, b->extra, b->info);
  } else if (const auto* p = std::get_if<io::PositionData>(&data)) {
    P.kind = "position";
    P.per_sample = 3;
    P.d = p->d;
    P.p = p->p;
    P.sigma_declared = p->sigma;
    read_common(P, p->extra, p->info);
  } else {
    throw Error("the kinematic diagnosis reads ball-bar and position data; this is a motion log");
  }
  if (P.d.empty()) throw Error(P.data_file + ": no data rows");
  return P;
}

KinematicProblem read_kinematic(const io::DataSet& data, const kin::KinematicModel& model) {
  KinematicProblem P = read_problem(data, model);
  P.residual_given = P.residual_of_model(P.given);
  return P;
}

// ---------------------------------------------------------------------------
// Stage 1: the base calibrated at the model's own effects

namespace {

// Effective displacements of the model's own effects: what calibration fits.
std::vector<Vec3> effective_displacements(const KinematicProblem& P) {
  const std::size_t n = P.d.size();
  std::vector<Vec3> dt(n);
  for (std::size_t j = 0; j < n; ++j)
    for (int i = 0; i < 3; ++i)
      dt[j][i] = kin::effective_displacement(P.given.effects[i], P.d[j][i], P.inputs[j].dir[i], P.inputs[j].t);
  return dt;
}

// Kim's eta fitted on the ball-bar lengths; its residual r and Jacobian J there.
void calibrate_ballbar(KinematicProblem& P, const std::vector<Vec3>& dt, cal::VecX& r, cal::MatX& J) {
  cal::BallbarOptions o;
  o.length_offset_known = !P.with_dl;
  // A circular test (one plane) cannot determine the out-of-plane
  // parameters: calibrate what it determines, keep the rest as the model has it.
  o.partial = true;
  P.ballbar_fit = cal::fit_ballbar(P.given, dt, P.length, P.pivot, o);
  P.base_value = P.ballbar_fit->params.vector(P.with_dl);
  P.base_names = cal::ballbar_parameter_names(P.with_dl);
  P.base_units = cal::ballbar_parameter_units(P.with_dl);
  cal::ballbar_residuals(P.base_value, P.given.d0, dt, P.length, P.pivot, r, &J);
  for (const auto& w : P.ballbar_fit->warnings) P.notes.push_back("calibration: " + w);
}

// The 12 plane parameters fitted on the platform positions; residual r and Jacobian J there.
void calibrate_positions(KinematicProblem& P, const std::vector<Vec3>& dt, cal::VecX& r, cal::MatX& J) {
  cal::PositionOptions o;
  o.sigma = P.sigma_declared;
  P.position_fit = cal::fit_positions(P.given, dt, P.p, o);
  P.base_value = vector_from_planes(P.position_fit->model.planes);
  P.base_names = cal::position_parameter_names();
  P.base_units = cal::position_parameter_units();
  cal::position_residuals(P.position_fit->model.planes, P.given.d0, dt, P.p, r, &J);
  for (const auto& w : P.position_fit->warnings) P.notes.push_back("calibration: " + w);
}

// d residual / d d~_i at the calibrated base: central differences through
// the full forward kinematics.
Eigen::MatrixXd axis_sensitivity(const KinematicProblem& P) {
  Eigen::MatrixXd S(P.rows(), 3);
  Vec3 dq;
  double dl;
  split_ballbar(P, P.base_value, dq, dl);
  const kin::KinematicModel fm = frame_model(P, P.base_value, P.given.effects);
  const double h = 1e-6;
  for (int i = 0; i < 3; ++i)
    S.col(i) = (frame_residual(P, fm, dq, dl, i, h) - frame_residual(P, fm, dq, dl, i, -h)) / (2 * h);
  return S;
}

}  // namespace

KinematicProblem prepare_kinematic(const io::DataSet& data, const kin::KinematicModel& model) {
  KinematicProblem P = read_kinematic(data, model);
  const std::vector<Vec3> dt = effective_displacements(P);
  cal::VecX r;
  cal::MatX J;
  if (P.kind == "ballbar")
    calibrate_ballbar(P, dt, r, J);
  else
    calibrate_positions(P, dt, r, J);
  P.base_map = Eigen::MatrixXd::Identity(J.cols(), J.cols());
  if (P.ballbar_fit && P.ballbar_fit->determined.size()) P.base_map = P.ballbar_fit->determined;
  P.base = J * P.base_map;
  P.residual = P.residual_of(P.base_value, {});
  P.sensitivity = axis_sensitivity(P);
  return P;
}

// ---------------------------------------------------------------------------
// Stage 3: the linear problem of the base refit

constexpr double kKinematicResolution = 1e-9;  // m

LinearProblem kinematic_linear_problem(const KinematicProblem& P) {
  LinearProblem L;
  const int N = P.rows();
  // The engine explains y by its columns (y = X theta + noise); with the
  // residual r = model - measurement and columns dr/dtheta, a change theta
  // of the model removes X theta from r when y = -r (measurement - model).
  L.y = -P.residual;
  L.B = P.base;
  L.base_names = P.base_names;
  L.base_units = P.base_units;
  for (Eigen::Index k = 0; k < P.base_value.size(); ++k) L.base_values.push_back(P.base_value(k));
  L.nuisance.assign(L.base_names.size(), 0);
  // Equal weights (one instrument); the scale cancels in every test.
  const double s = std::max(Engine::rms(P.residual), 1e-12);
  L.w = Eigen::VectorXd::Constant(N, 1.0 / s);
  // Resolution: 1 nm. Below any instrument's, and above what linearising
  // µm-sized effects at the calibrated point leaves (their square over the
  // bar length: (4 µm)^2 / 0.1 m = 0.2 nm); exact data then do not name an
  // effect on rounding.
  L.floor_variance = (kKinematicResolution / s) * (kKinematicResolution / s);
  L.series.resize(static_cast<std::size_t>(N));
  for (int r = 0; r < N; ++r) L.series[static_cast<std::size_t>(r)] = r % P.per_sample;
  L.n_series = P.per_sample;
  return L;
}

}  // namespace cpm::ident
