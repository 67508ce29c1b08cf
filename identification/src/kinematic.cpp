#include "cpm/identification/kinematic.hpp"

#include <algorithm>
#include <cmath>
#include <numbers>
#include <sstream>

#include "internal.hpp"
#include "cpm/kinematics/kinematic_effects.hpp"

namespace cpm::ident {
namespace {

using kin::KinematicEffectType;
constexpr double kTwoPi = 2.0 * std::numbers::pi;

std::string fmt(double v, int prec = 3) {
  std::ostringstream os;
  os.precision(prec);
  os << v;
  return os.str();
}

std::string where(const KinematicProblem& P, int j) {
  const int line = j < static_cast<int>(P.line.size()) ? P.line[static_cast<std::size_t>(j)] : 0;
  return P.data_file + (line > 0 ? ":" + std::to_string(line) : " (sample " + std::to_string(j + 1) + ")");
}

// The model's own effects plus `extra` (the candidate's), per limb.
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

// The model in the frame of the base parameters (ball-bar frame or machine frame).
kin::KinematicModel frame_model(const KinematicProblem& P, const Eigen::VectorXd& x, const KinematicEffects& eff) {
  kin::KinematicModel m = P.given;
  m.planes = P.kind == "ballbar" ? cal::ballbar_frame_planes(cal::BallbarParameters::from_vector(x))
                                 : planes_from_vector(x);
  m.effects = eff;
  return m;
}

// Residual (model - measurement) of `m` in the base frame; ball-bar with the
// pivot q + dq and the bar offset dl; `shift` added to axis `axis` of every reading.
Eigen::VectorXd residual_impl(const KinematicProblem& P, const kin::KinematicModel& m, const Vec3& dq, double dl,
                              int axis = -1, double shift = 0.0) {
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

struct Span {
  Vec3 lo = Vec3::Constant(1e300), hi = Vec3::Constant(-1e300);
  double t0 = 1e300, t1 = -1e300;
  std::array<int, 3> n_plus{}, n_minus{};
};
Span span_of(const KinematicProblem& P) {
  Span s;
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

// Column of a displacement-type change g_j on axis i: S_i(row) * g(sample).
template <class G>
Eigen::VectorXd displacement_column(const KinematicProblem& P, int axis, G&& g) {
  Eigen::VectorXd c(P.rows());
  for (int r = 0; r < P.rows(); ++r) c(r) = P.sensitivity(r, axis) * g(P.sample_of_row(r));
  return c;
}

Eigen::MatrixXd hcat(std::initializer_list<Eigen::VectorXd> cols) {
  Eigen::MatrixXd X(cols.begin()->size(), static_cast<Eigen::Index>(cols.size()));
  Eigen::Index j = 0;
  for (const auto& c : cols) X.col(j++) = c;
  return X;
}

// Central difference of the residual at the calibrated base with respect to
// one parameter of an effect on one limb.
Eigen::VectorXd effect_difference(const KinematicProblem& P, KinematicEffectType t, int axis, int param,
                                  double eps) {
  Vec3 dq;
  double dl;
  split_ballbar(P, P.base_value, dq, dl);
  auto at = [&](double v) {
    KinematicEffects x{};
    std::array<double, 3> vals{0, 0, 0};
    vals[static_cast<std::size_t>(param)] = v;
    kin::set_params(x[axis], t, vals);
    return residual_impl(P, frame_model(P, P.base_value, combine(P.given.effects, x)), dq, dl);
  };
  return (at(eps) - at(-eps)) / (2.0 * eps);
}

// What each kinematic effect depends on, for advice on separating two of them.
struct Depends { bool direction, time, periodic, normal; };
Depends depends(const std::string& e) {
  return {e == "backlash", e == "thermal_drift", e == "cyclic_error",
          e == "guide_angular_error" || e == "limb_twist"};
}

std::string base_advice(const KinematicProblem& P, const std::string& effect, const std::string& base_name, int axis) {
  const std::string ax = axis >= 0 ? "axis " + std::to_string(axis + 1) : "the axes";
  if (effect == "backlash")
    return "approach the poses from both directions on " + ax + " (dir" + std::to_string(axis + 1) +
           " = +1 and -1 at the same poses)";
  if (effect == "actuator_scale" || (base_name == "dl" && P.with_dl)) {
    if (P.kind == "ballbar")
      return P.with_dl ? "measure with a second bar radius, or a bar calibrated against a length standard "
                         "(length_offset_known = true)"
                       : "nothing: the calibration fits each axis' scale c_i, which is this effect";
    return "nothing: the calibration fits each axis' scale c_i, which is this effect";
  }
  if (effect == "thermal_drift") return "repeat poses at other times (a longer or a second run, another warm-up state)";
  return P.kind == "ballbar" ? "spread the poses over more of the hemisphere, with a second bar radius"
                             : "spread the poses over more of the workspace";
}

std::string separate_kinematic(const KinematicProblem& P, const Span& sp, const CandidateResult& a,
                               const CandidateResult& b) {
  const Depends da = depends(a.effect), db = depends(b.effect);
  const int ax = a.axis >= 0 ? a.axis : b.axis;
  const std::string axis_text = ax >= 0 ? "axis " + std::to_string(ax + 1) : "the axes";
  if (da.direction != db.direction) {
    const bool one = ax >= 0 && (sp.n_plus[ax] == 0 || sp.n_minus[ax] == 0);
    return one ? "approach the poses on " + axis_text + " from both directions"
               : "approach the same poses on " + axis_text + " from both directions (pairs of readings)";
  }
  if (da.time != db.time) return "repeat the poses at another time (another warm-up state) or in another order";
  if (da.periodic != db.periodic)
    return "measure along " + axis_text + " at a finer spacing (steps shorter than a quarter wavelength)";
  if (P.kind == "ballbar") return "measure with a second bar radius and poses spread over the whole hemisphere";
  return "spread the poses over more of the workspace";
}

}  // namespace

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
  return residual_impl(*this, frame_model(*this, x, combine(given.effects, extra)), dq, dl);
}

Eigen::VectorXd KinematicProblem::residual_of_model(const kin::KinematicModel& m) const {
  Eigen::VectorXd r = residual_impl(*this, m, Vec3::Zero(), 0.0);
  // An uncalibrated bar: its offset is not the machine's; compare shapes.
  if (kind == "ballbar" && with_dl && r.size()) r.array() -= r.mean();
  return r;
}

namespace {

KinematicProblem read_problem(const io::DataSet& data, const kin::KinematicModel& model) {
  model.validate();
  KinematicProblem P;
  P.given = model;
  const io::CommonColumns* extra = nullptr;
  const io::FileInfo* info = nullptr;
  if (const auto* b = std::get_if<io::BallbarData>(&data)) {
    P.kind = "ballbar";
    P.per_sample = 1;
    P.d = b->d;
    P.length = b->length;
    P.pivot = b->pivot;
    P.with_dl = !b->length_offset_known;
    extra = &b->extra;
    info = &b->info;
  } else if (const auto* p = std::get_if<io::PositionData>(&data)) {
    P.kind = "position";
    P.per_sample = 3;
    P.d = p->d;
    P.p = p->p;
    P.sigma_declared = p->sigma;
    extra = &p->extra;
    info = &p->info;
  } else {
    throw Error("the kinematic diagnosis reads ball-bar and position data; this is a motion log");
  }
  P.data_file = info->path.empty() ? std::string("data") : info->path;
  P.line = info->line_of_row;
  P.warnings = info->warnings;
  P.run = extra->run;
  const std::size_t n = P.d.size();
  P.has_dir = extra->dir.size() == n && n > 0;
  P.has_time = extra->t.size() == n && n > 0;
  P.inputs.assign(n, kin::KinematicInputs{});
  for (std::size_t j = 0; j < n; ++j) {
    if (P.has_dir) P.inputs[j].dir = extra->dir[j];
    if (P.has_time) P.inputs[j].t = extra->t[j];
  }
  if (n == 0) throw Error(P.data_file + ": no data rows");
  return P;
}

}  // namespace

KinematicProblem read_kinematic(const io::DataSet& data, const kin::KinematicModel& model) {
  KinematicProblem P = read_problem(data, model);
  P.residual_given = P.residual_of_model(P.given);
  return P;
}

KinematicProblem prepare_kinematic(const io::DataSet& data, const kin::KinematicModel& model) {
  KinematicProblem P = read_kinematic(data, model);
  const std::size_t n = P.d.size();
  // Effective displacements of the model's own effects: what calibration fits.
  std::vector<Vec3> dt(n);
  for (std::size_t j = 0; j < n; ++j)
    for (int i = 0; i < 3; ++i)
      dt[j][i] = kin::effective_displacement(P.given.effects[i], P.d[j][i], P.inputs[j].dir[i], P.inputs[j].t);
  cal::VecX r;
  cal::MatX J;
  if (P.kind == "ballbar") {
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
  } else {
    cal::PositionOptions o;
    o.sigma = P.sigma_declared;
    P.position_fit = cal::fit_positions(P.given, dt, P.p, o);
    P.base_value = vector_from_planes(P.position_fit->model.planes);
    P.base_names = cal::position_parameter_names();
    P.base_units = cal::position_parameter_units();
    cal::position_residuals(P.position_fit->model.planes, P.given.d0, dt, P.p, r, &J);
    for (const auto& w : P.position_fit->warnings) P.notes.push_back("calibration: " + w);
  }
  P.base_map = Eigen::MatrixXd::Identity(J.cols(), J.cols());
  if (P.ballbar_fit && P.ballbar_fit->determined.size()) P.base_map = P.ballbar_fit->determined;
  P.base = J * P.base_map;
  P.residual = P.residual_of(P.base_value, {});
  P.sensitivity.resize(P.rows(), 3);
  Vec3 dq;
  double dl;
  split_ballbar(P, P.base_value, dq, dl);
  const kin::KinematicModel fm = frame_model(P, P.base_value, P.given.effects);
  const double h = 1e-6;
  for (int i = 0; i < 3; ++i)
    P.sensitivity.col(i) = (residual_impl(P, fm, dq, dl, i, h) - residual_impl(P, fm, dq, dl, i, -h)) / (2 * h);
  return P;
}

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

// ---------------------------------------------------------------------------
// Candidates

CandidateResult evaluate_kinematic_candidate(const KinematicProblem& P, const Engine& E, const std::string& effect,
                                             int axis, const DiagnoseOptions& opt) {
  CandidateResult c;
  c.effect = effect;
  c.axis = axis;
  const auto type = kin::kinematic_effect_from_name(effect);
  if (!type) throw Error("unknown kinematic effect '" + effect + "'");
  if (axis < 0 || axis > 2) throw Error(effect + ": needs an axis 1..3");
  const kin::KinematicEffectInfo& in = kin::info(*type);
  const int rank = E.base_rank();
  const Span sp = span_of(P);
  c.n_params = in.n_params;
  auto not_identifiable = [&](const std::string& why) {
    c.identifiable = false;
    c.note = why;
    c.rss = E.rss_base();
    c.residual_after = E.base_fit().residual;
    c.fitted = Eigen::VectorXd::Zero(E.rows());
    c.columns = Eigen::MatrixXd(E.rows(), 0);
    for (int j = 0; j < in.n_params; ++j) c.params.push_back({in.params[j].name, in.params[j].unit, 0.0, -1.0, false});
  };
  if (in.needs_direction && !P.has_dir) {
    not_identifiable("needs the direction each axis last moved (columns dir1, dir2, dir3)");
    return c;
  }
  if (in.needs_time && !P.has_time) {
    not_identifiable("needs the time of each sample (column t)");
    return c;
  }
  if (kin::get_params(P.given.effects[axis], *type) != std::array<double, 3>{0, 0, 0}) {
    not_identifiable("already in the model");
    return c;
  }
  const double stroke = sp.hi[axis] - sp.lo[axis];
  // Whether these data can see column j of an effect at all: the part of it
  // outside the base span, at the parameter's largest physical size, changes
  // them by at least 3 noise standard deviations (resolution included). A
  // circle in one plane cannot see what tilts out of it: there the fit would
  // return a wild number with a meaningless standard error.
  const double noise_unit = std::sqrt(1.0 + E.problem().floor_variance);
  auto visible = [&](const Eigen::MatrixXd& X, int j, double bound) {
    const Eigen::MatrixXd Xp = E.project_off_base(X.col(j));
    return Xp.norm() * bound >= 3.0 * noise_unit;
  };
  auto bound_of = [&](int param) { return std::max(std::fabs(in.params[param].lower), std::fabs(in.params[param].upper)); };
  auto finish = [&](const Eigen::MatrixXd& X, const JointFit& f, const Eigen::MatrixXd& jac,
                    const std::vector<double>& values) {
    bool any_visible = false, any_column = false;
    for (Eigen::Index j = 0; j < X.cols(); ++j) {
      any_column |= X.col(j).norm() > 0.0;
      any_visible |= visible(X, static_cast<int>(j), bound_of(in.n_params == X.cols() ? static_cast<int>(j) : 0));
    }
    // A fit that failed (the column in the base span, or nothing) keeps the
    // base's residual; the confounding below still says with what and how to
    // separate them. A column outside the span but too small to matter is
    // simply not seen.
    const char* unseen_note = "these data cannot see it: even at its largest physical size its part that the "
                              "calibrated base cannot take up changes them by less than 3 noise standard deviations";
    if (!any_column) {
      not_identifiable(unseen_note);
      return;
    }
    const bool unseen = !any_visible;
    const bool degenerate = unseen || !f.full_rank || !f.beta.allFinite() || !f.residual.allFinite();
    c.columns = X;
    c.rss = degenerate ? E.rss_base() : f.rss;
    c.n_eff = degenerate ? E.base_fit().n_eff : f.n_eff;
    c.residual_after = degenerate ? E.base_fit().residual : f.residual;
    c.fitted = degenerate ? Eigen::VectorXd::Zero(E.rows()) : Eigen::VectorXd(X * f.beta);
    const Eigen::MatrixXd cov = degenerate ? Eigen::MatrixXd() : E.covariance(jac, f, rank + static_cast<int>(jac.cols()), true);
    for (int j = 0; j < in.n_params; ++j) {
      const double se = j < cov.rows() ? std::sqrt(std::max(0.0, cov(j, j))) : -1.0;
      c.params.push_back({in.params[j].name, in.params[j].unit, degenerate ? 0.0 : values[static_cast<std::size_t>(j)], se, false});
    }
    for (std::size_t b = 0; b < P.base_names.size(); ++b)
      c.base_after.push_back({P.base_names[b], P.base_units[b],
                              P.base_value(static_cast<Eigen::Index>(b)) + (P.base_map * f.base_delta)(static_cast<Eigen::Index>(b)),
                              -1.0, false});
    const Eigen::VectorXd share = E.base_share(X);
    const Eigen::MatrixXd cosb = E.base_cosines(X);
    std::string with;
    for (Eigen::Index j = 0; j < X.cols(); ++j) {
      if (cosb.cols() == 0) break;
      Eigen::Index bi = 0;
      cosb.row(j).cwiseAbs().maxCoeff(&bi);
      const std::string name = P.base_names[static_cast<std::size_t>(bi)];
      if (j == 0) with = name;
      if (share(j) < 0.81) continue;
      bool dup = false;
      for (const auto& o : c.confounded) dup |= o.with == name;
      if (!dup) c.confounded.push_back({name, "", -1, std::sqrt(share(j)), base_advice(P, effect, name, axis)});
    }
    // Kinematic data are precise (a bar to 0.3 µm against effects of
    // microns): a column mostly in the base span can still be measured by
    // the part outside it, whose size the standard error reflects. Only a
    // column (numerically) inside the span cannot be told apart.
    const bool in_span = !share.allFinite() || share.minCoeff() > 1.0 - 1e-6;
    if (in_span || (degenerate && !unseen)) {
      c.identifiable = false;
      c.note = "in these data it cannot be told apart from the calibrated base" +
               (with.empty() ? std::string() : " (parameter " + with + ")") + ": " + base_advice(P, effect, with, axis);
    } else if (unseen) {
      c.identifiable = false;
      c.note = unseen_note;
    }
  };

  switch (*type) {
    case KinematicEffectType::backlash: {
      const Eigen::MatrixXd X =
          hcat({displacement_column(P, axis, [&](int j) { return -0.5 * P.inputs[static_cast<std::size_t>(j)].dir[axis]; })});
      JointFit f = E.fit(X);
      double b = f.beta(0);
      finish(X, f, X, {b});
      if (b < 0.0) {
        c.params[0].value = 0.0;
        c.params[0].at_bound = true;
        c.rss = E.rss_base();
        c.residual_after = E.base_fit().residual;
        c.fitted.setZero();
        c.note = "the best fit is a negative lost motion (" + fmt(b * 1e6) + " µm, unphysical); held at 0";
      }
      break;
    }
    case KinematicEffectType::cyclic_error: {
      const double lmin = in.params[1].lower, lmax = std::min(in.params[1].upper, stroke / 1.5);
      if (lmax <= lmin * 1.5) {
        not_identifiable("axis " + std::to_string(axis + 1) + " covers " + fmt(stroke * 1e3) +
                         " mm only: too little to see a periodic error");
        break;
      }
      auto cols = [&](double k) {
        return hcat({displacement_column(P, axis, [&](int j) { return std::sin(kTwoPi * k * P.d[static_cast<std::size_t>(j)][axis]); }),
                     displacement_column(P, axis, [&](int j) { return std::cos(kTwoPi * k * P.d[static_cast<std::size_t>(j)][axis]); })});
      };
      const double kmin = 1.0 / lmax, kmax = 1.0 / lmin, dk = 1.0 / (4.0 * stroke);
      const int K = static_cast<int>((kmax - kmin) / dk) + 1;
      std::vector<double> rss(static_cast<std::size_t>(K));
      for (int q = 0; q < K; ++q) rss[static_cast<std::size_t>(q)] = E.rss(cols(kmin + q * dk));
      std::vector<int> peaks;
      for (int q = 0; q < K; ++q) {
        const auto u = static_cast<std::size_t>(q);
        if ((q == 0 || rss[u] <= rss[u - 1]) && (q == K - 1 || rss[u] <= rss[u + 1])) peaks.push_back(q);
      }
      std::sort(peaks.begin(), peaks.end(), [&](int a, int b) { return rss[static_cast<std::size_t>(a)] < rss[static_cast<std::size_t>(b)]; });
      if (peaks.size() > 3) peaks.resize(3);
      double best = 1e300, bk = kmin;
      for (int q : peaks) {
        const double k0 = kmin + q * dk;
        double fb = 0.0;
        const double kk = detail::golden([&](double kx) { return E.rss(cols(kx)); }, std::max(kmin, k0 - dk),
                                         std::min(kmax, k0 + dk), 14, fb);
        if (fb < best) { best = fb; bk = kk; }
        if (rss[static_cast<std::size_t>(q)] < best) { best = rss[static_cast<std::size_t>(q)]; bk = k0; }
      }
      const Eigen::MatrixXd X = cols(bk);
      const JointFit f = E.fit(X);
      // a sin(x + phi) = (a cos phi) sin x + (a sin phi) cos x
      const double a = std::hypot(f.beta(0), f.beta(1)), phi = std::atan2(f.beta(1), f.beta(0));
      const double lambda = 1.0 / bk;
      const Eigen::MatrixXd jac = hcat(
          {displacement_column(P, axis, [&](int j) { return std::sin(kTwoPi * P.d[static_cast<std::size_t>(j)][axis] / lambda + phi); }),
           displacement_column(P, axis, [&](int j) {
             const double dj = P.d[static_cast<std::size_t>(j)][axis];
             return -a * std::cos(kTwoPi * dj / lambda + phi) * kTwoPi * dj / (lambda * lambda);
           }),
           displacement_column(P, axis, [&](int j) { return a * std::cos(kTwoPi * P.d[static_cast<std::size_t>(j)][axis] / lambda + phi); })});
      finish(X, f, jac, {a, lambda, phi});
      c.trials = std::max(1.0, stroke * (kmax - kmin));
      break;
    }
    case KinematicEffectType::guide_angular_error: {
      // Two tilts; a pose set may see one only (a circle in the plane of the
      // other axes sees no tilt toward the third): fit what it sees, say so.
      const Eigen::MatrixXd both = hcat({effect_difference(P, *type, axis, 0, 1e-4), effect_difference(P, *type, axis, 1, 1e-4)});
      const bool va = visible(both, 0, bound_of(0)), vb = visible(both, 1, bound_of(1));
      if (va == vb) {
        const JointFit f = E.fit(both);
        finish(both, f, both, {f.beta(0), f.beta(1)});
        break;
      }
      const int j = va ? 0 : 1;
      const Eigen::MatrixXd X = hcat({both.col(j)});
      const JointFit f = E.fit(X);
      finish(X, f, X, {f.beta(0), 0.0});
      if (c.identifiable && c.params.size() == 2) {
        if (j == 1) std::swap(c.params[0], c.params[1]);
        for (int k = 0; k < 2; ++k) c.params[static_cast<std::size_t>(k)].name = in.params[k].name;
        c.params[static_cast<std::size_t>(1 - j)].value = 0.0;
        c.params[static_cast<std::size_t>(1 - j)].std_error = -1.0;
        c.n_params = 1;
        c.note = "these data cannot see the tilt " + std::string(in.params[1 - j].name) + ": fitted " +
                 in.params[j].name + " only";
      }
      break;
    }
    case KinematicEffectType::limb_twist: {
      const Eigen::MatrixXd X = hcat({effect_difference(P, *type, axis, 0, 1e-4)});
      const JointFit f = E.fit(X);
      finish(X, f, X, {f.beta(0)});
      break;
    }
    case KinematicEffectType::thermal_drift: {
      const double T = sp.t1 - std::max(0.0, std::min(sp.t0, sp.t1));
      if (!(sp.t1 > sp.t0)) {
        not_identifiable("all samples have the same time");
        break;
      }
      const double lo = std::max(in.params[1].lower, (sp.t1 - sp.t0) / 30.0), hi = std::min(in.params[1].upper, 10.0 * T);
      auto col = [&](double tau) {
        return displacement_column(P, axis, [&](int j) {
          const auto u = static_cast<std::size_t>(j);
          return P.d[u][axis] * (1.0 - std::exp(-P.inputs[u].t / tau));
        });
      };
      const int G = 16;
      double best = 1e300, bx = std::log(hi);
      const double step = (std::log(hi) - std::log(lo)) / (G - 1);
      for (int g = 0; g < G; ++g) {
        const double x = std::log(lo) + g * step;
        const double v = E.rss(hcat({col(std::exp(x))}));
        if (v < best) { best = v; bx = x; }
      }
      double fb = 0.0;
      const double xr = detail::golden([&](double x) { return E.rss(hcat({col(std::exp(x))})); },
                                       std::max(std::log(lo), bx - step), std::min(std::log(hi), bx + step), 14, fb);
      if (fb < best) bx = xr;
      const double tau = std::exp(bx);
      const Eigen::MatrixXd X = hcat({col(tau)});
      const JointFit f = E.fit(X);
      const double e = f.beta(0);
      const Eigen::MatrixXd jac = hcat({X.col(0), displacement_column(P, axis, [&](int j) {
                                          const auto u = static_cast<std::size_t>(j);
                                          const double t = P.inputs[u].t;
                                          return -e * P.d[u][axis] * std::exp(-t / tau) * t / (tau * tau);
                                        })});
      finish(X, f, jac, {e, tau});
      c.trials = std::max(1.0, std::log(hi / lo) / std::log(3.0));
      if (c.identifiable && tau >= 0.99 * hi)
        c.note = "tau at the top of the search (" + fmt(hi) + " s): the data see a linear drift";
      break;
    }
    case KinematicEffectType::actuator_scale: {
      const Eigen::MatrixXd X =
          hcat({displacement_column(P, axis, [&](int j) { return P.d[static_cast<std::size_t>(j)][axis]; })});
      const JointFit f = E.fit(X);
      finish(X, f, X, {f.beta(0)});
      // The scale is c_i of the base: report c_i - 1 (what a nominal-only
      // model would call actuator_scale).
      const int ci = P.kind == "ballbar" ? std::array<int, 3>{0, 1, 3}[static_cast<std::size_t>(axis)] : 4 * axis + 2;
      c.params[0].value = P.base_value(ci) - 1.0;
      c.params[0].std_error = -1.0;
      c.rss = E.rss_base();
      c.residual_after = E.base_fit().residual;
      c.fitted.setZero();
      c.identifiable = false;
      c.note = "absorbed by the calibrated base: the scale c" + std::to_string(axis + 1) +
               " is this effect (s = c - 1 shown; to put it in the model, calibrate: cpm calibrate)";
      break;
    }
  }
  (void)opt;
  return c;
}

// ---------------------------------------------------------------------------
// actuator_scale at the model as given

namespace {

int column_rank(const Eigen::MatrixXd& A) {
  if (A.cols() == 0) return 0;
  Eigen::MatrixXd As = A;
  for (Eigen::Index j = 0; j < As.cols(); ++j) {
    const double n = As.col(j).norm();
    if (n > 0.0) As.col(j) /= n;
  }
  Eigen::ColPivHouseholderQR<Eigen::MatrixXd> qr(As);
  qr.setThreshold(1e-7);
  return static_cast<int>(qr.rank());
}

// effects.md lists actuator_scale "so that a nominal-only model can name it":
// the calibrated base absorbs a scale (it is c_i), so the scales are judged
// where the model is. H0 = the model as given with only the set-up refitted
// (ball-bar: the pivot; an uncalibrated bar's offset goes with the mean),
// Hs = H0 + the three actuator scales, Hb = the full calibration (the base's
// own nonlinear fit). Scale i is named when Hb adds to Hs nothing significant,
// or less than 1 % of what it explains in all, and scale i is significant
// within Hs. H0 and Hs are fitted by Gauss-Newton on the residual of the given
// model with the scales as its own effects (their definition in effects.md):
// a pivot a millimetre off is too far for one linearisation.
struct GivenFit {
  Eigen::VectorXd y;        // measurement - model at the fitted point (m)
  Eigen::MatrixXd columns;  // d residual / d (set-up, free scales) there
  Vec3 s = Vec3::Zero(), dq = Vec3::Zero();
};

GivenFit fit_at_the_given_model(const KinematicProblem& P, const std::array<bool, 3>& free_scale,
                                const Eigen::VectorXd& w) {
  const int N = P.rows(), ns = P.kind == "ballbar" ? 3 : 0;
  std::vector<int> axes;
  for (int i = 0; i < 3; ++i)
    if (free_scale[static_cast<std::size_t>(i)]) axes.push_back(i);
  GivenFit g;
  auto residual_at = [&](const Vec3& s, const Vec3& dq) {
    kin::KinematicModel m = P.given;
    for (int i = 0; i < 3; ++i) m.effects[i].actuator_scale += s[i];
    Eigen::VectorXd r = residual_impl(P, m, dq, 0.0);
    if (P.kind == "ballbar" && P.with_dl && r.size()) r.array() -= r.mean();
    return r;
  };
  const double h = 1e-6;
  for (int it = 0; it < 5; ++it) {
    const Eigen::VectorXd r = residual_at(g.s, g.dq);
    Eigen::MatrixXd X(N, ns + static_cast<int>(axes.size()));
    for (int k = 0; k < ns; ++k) {
      const Vec3 e = h * Vec3::Unit(k);
      X.col(k) = (residual_at(g.s, g.dq + e) - residual_at(g.s, g.dq - e)) / (2.0 * h);
    }
    for (std::size_t a = 0; a < axes.size(); ++a) {
      const Vec3 e = h * Vec3::Unit(axes[a]);
      X.col(ns + static_cast<int>(a)) = (residual_at(g.s + e, g.dq) - residual_at(g.s - e, g.dq)) / (2.0 * h);
    }
    g.y = -r;
    g.columns = X;
    if (X.cols() == 0) break;
    const Eigen::MatrixXd Xw = w.asDiagonal() * X;
    const Eigen::VectorXd step = Xw.colPivHouseholderQr().solve(w.cwiseProduct(g.y));
    for (int k = 0; k < ns; ++k) g.dq[k] += step(k);
    for (std::size_t a = 0; a < axes.size(); ++a) g.s[axes[a]] += step(ns + static_cast<int>(a));
    if (step.cwiseAbs().maxCoeff() < 1e-12) break;
  }
  g.y = -residual_at(g.s, g.dq);
  return g;
}

void judge_scales_at_the_given_model(const KinematicProblem& P, const DiagnoseOptions& opt,
                                     std::vector<CandidateResult>& candidates) {
  const LinearProblem L = kinematic_linear_problem(P);
  const Eigen::VectorXd w = L.w;
  const int N = P.rows();
  // Statistics on one engine: rows, weights, series and resolution of these data.
  auto engine_for = [&](const GivenFit& g) {
    LinearProblem Lg = L;
    Lg.y = g.y;
    Lg.B = Eigen::MatrixXd(N, 0);
    Lg.base_names.clear();
    Lg.base_units.clear();
    Lg.base_values.clear();
    Lg.nuisance.clear();
    return Engine(std::move(Lg));
  };
  // Only the scales of axes that move (a circle in XY leaves z's scale unseen).
  const Span sp = span_of(P);
  std::array<bool, 3> moving{};
  for (int i = 0; i < 3; ++i) moving[static_cast<std::size_t>(i)] = sp.hi[i] - sp.lo[i] >= 1e-3;
  const int n_moving = static_cast<int>(std::count(moving.begin(), moving.end(), true));
  if (n_moving == 0) return;
  const GivenFit all = fit_at_the_given_model(P, moving, w);
  const GivenFit setup_only = fit_at_the_given_model(P, {false, false, false}, w);
  const Engine EA = engine_for(all), E0 = engine_for(setup_only);
  const double rss_s = EA.rss_given(), rss_0 = E0.rss_given();
  const double rss_b = w.cwiseProduct(P.residual).squaredNorm();  // the full calibration
  const int k_s = column_rank(w.asDiagonal() * all.columns), k_b = column_rank(w.asDiagonal() * P.base);
  const JointFit fa = EA.fit(Eigen::MatrixXd(N, 0), false);
  const NestedTest full = EA.nested(rss_s, std::min(rss_s, rss_b), std::max(1, k_b - k_s), k_b, fa.n_eff);
  const double share_left = rss_0 > rss_b ? std::max(0.0, rss_s - rss_b) / (rss_0 - rss_b) : 1.0;
  const int ns = static_cast<int>(all.columns.cols()) - n_moving;  // set-up columns
  const int k_setup = column_rank(w.asDiagonal() * all.columns.leftCols(ns));
  const bool scales_suffice = k_s == k_setup + n_moving && k_b > k_s && (full.p_value >= opt.alpha || share_left < 0.01);
  // Covariance of the scales at the fitted point (set-up jointly).
  Eigen::MatrixXd cov;
  if (scales_suffice) {
    LinearProblem Lc = L;
    Lc.y = all.y;
    Lc.B = all.columns.leftCols(ns);
    Lc.base_names.assign(static_cast<std::size_t>(ns), "pivot");
    Lc.base_units.assign(static_cast<std::size_t>(ns), "m");
    Lc.base_values.assign(static_cast<std::size_t>(ns), 0.0);
    Lc.nuisance.assign(static_cast<std::size_t>(ns), 0);
    const Engine Ec(std::move(Lc));
    const Eigen::MatrixXd S = all.columns.rightCols(n_moving);
    cov = Ec.covariance(S, Ec.fit(S), k_s, true);
  }
  for (auto& c : candidates) {
    if (c.effect != "actuator_scale" || c.axis < 0 || c.axis > 2) continue;
    if (!moving[static_cast<std::size_t>(c.axis)]) continue;
    if (!scales_suffice) {
      c.note += "; at the model as given the scales alone leave " + fmt(100.0 * share_left, 3) +
                " % of what a full calibration explains (p = " + fmt(full.p_value, 2) + ")";
      continue;
    }
    const int i = c.axis;
    std::array<bool, 3> others = moving;
    others[static_cast<std::size_t>(i)] = false;
    const GivenFit without = fit_at_the_given_model(P, others, w);
    int ci = 0;  // index of scale i among the free ones
    for (int j = 0; j < i; ++j) ci += moving[static_cast<std::size_t>(j)] ? 1 : 0;
    const NestedTest t = EA.nested(engine_for(without).rss_given(), rss_s, 1, k_s, fa.n_eff);
    c.identifiable = true;
    c.refits_base = false;
    c.columns = Eigen::MatrixXd(N, 0);
    c.params.assign(1, {"s", "1", all.s[i], std::sqrt(std::max(0.0, cov(ci, ci))), false});
    c.rss = rss_s;
    c.n_eff = fa.n_eff;
    c.residual_after = all.y;
    c.fitted = -P.residual_given - all.y;
    c.rms_after = Engine::rms(all.y);
    const double given_ms = std::pow(Engine::rms(P.residual_given), 2);
    c.explained = given_ms > 0.0 ? std::clamp(1.0 - c.rms_after * c.rms_after / given_ms, 0.0, 1.0) : 0.0;
    c.explained_beyond_base = 0.0;
    c.n_params = 1;
    c.k_total = k_s;
    c.f_stat = t.f_stat;
    c.p_value = t.p_value;
    c.delta_bic = t.delta_bic;
    c.note = "judged at the model as given: its three actuator scales (and the set-up) explain " +
             fmt(100.0 * (1.0 - share_left), 4) + " % of what a full calibration explains (the rest: p = " +
             fmt(full.p_value, 2) + "); a calibrated model holds it in c" + std::to_string(i + 1);
  }
}

}  // namespace

// ---------------------------------------------------------------------------
// Diagnosis

Diagnosis diagnose_kinematic(std::shared_ptr<const KinematicProblem> Pp, const DiagnoseOptions& opt) {
  const KinematicProblem& P = *Pp;
  for (const auto& e : opt.effects) check_effect_for_kind(e, P.kind);
  Diagnosis D;
  D.kind = P.kind;
  D.units = "m";
  D.data_file = P.data_file;
  D.samples = P.samples();
  D.kinematic = Pp;
  D.warnings = P.warnings;
  D.notes = P.notes;
  const Engine E(kinematic_linear_problem(P));
  D.rows = E.rows();
  D.baseline_rms = Engine::rms(P.residual_given);
  D.baseline_max = P.residual_given.cwiseAbs().maxCoeff();
  for (int k = 0; k < P.per_sample; ++k) {
    double s = 0.0;
    for (int j = 0; j < P.samples(); ++j) s += std::pow(P.residual_given(P.per_sample * j + k), 2);
    D.baseline_axis_rms[k] = std::sqrt(s / P.samples());
  }
  D.base_refit_rms = Engine::rms(E.base_fit().residual);
  const double baseline_ms = D.baseline_rms * D.baseline_rms;
  const int rank = E.base_rank();
  for (int t = 0; t < kin::kKinematicEffectTypes; ++t) {
    const auto& in = kin::info(static_cast<KinematicEffectType>(t));
    if (!opt.effects.empty() && std::find(opt.effects.begin(), opt.effects.end(), in.name) == opt.effects.end())
      continue;
    for (int i = 0; i < 3; ++i) {
      CandidateResult c = evaluate_kinematic_candidate(P, E, in.name, i, opt);
      detail::score_candidate(c, E, E.rss_base(), c.n_params, rank + c.n_params, baseline_ms);
      D.candidates.push_back(std::move(c));
    }
  }
  judge_scales_at_the_given_model(P, opt, D.candidates);
  // Noise floor: the instrument's declared sigma, else the residual sigma of
  // the best description (dof-corrected).
  {
    const double N = E.rows();
    double best = Engine::rms(E.base_fit().residual) * std::sqrt(N / std::max(1.0, N - rank));
    for (const auto& c : D.candidates)
      if (c.identifiable && c.rss > 0.0 && c.rss < E.rss_base())
        best = std::min(best, Engine::rms(c.residual_after) * std::sqrt(N / std::max(1.0, N - c.k_total)));
    D.noise_floor = P.sigma_declared > 0.0 ? P.sigma_declared : best;
    D.axis_noise = Vec3::Constant(D.noise_floor);
  }
  const Span sp = span_of(P);
  detail::rank_and_decide(D, E, opt, [&](const CandidateResult& a, const CandidateResult& b) {
    return separate_kinematic(P, sp, a, b);
  });
  // The base's own confounding: a bar of unknown length against the common scale.
  if (P.ballbar_fit && P.with_dl) {
    const auto& id = P.ballbar_fit->identifiability;
    const int k = id.index("dl");
    if (k >= 0 && id.multiple_correlation.size() > k && id.multiple_correlation[k] > 0.99)
      D.notes.push_back("the bar's length offset dl and the common scale of the three axes (c1, c2, c3 together, "
                        "i.e. actuator_scale on all three axes) cannot be told apart with one bar radius "
                        "(multiple correlation " + fmt(id.multiple_correlation[k], 6) +
                        "): measure with a second bar radius, or calibrate the bar (length_offset_known = true)");
  }
  if (!P.has_dir) D.notes.push_back("no dir1..dir3 columns: direction-dependent effects (backlash) cannot be judged");
  if (!P.has_time) D.notes.push_back("no t column: thermal drift cannot be judged");
  if (opt.structure_search) D.structure = find_kinematic_structure(P, D.residual_final, opt);
  return D;
}

std::vector<StructureFinding> find_kinematic_structure(const KinematicProblem& P0, const Eigen::VectorXd& residual,
                                                       const DiagnoseOptions& opt) {
  std::vector<StructureFinding> out;
  if (residual.size() != P0.rows()) return out;
  KinematicProblem P = P0;
  P.residual = -residual;  // residual_final is measurement - model (the engine's y)
  const Engine E(kinematic_linear_problem(P));
  const Span sp = span_of(P);
  const int rank = E.base_rank();
  auto test = [&](const Eigen::MatrixXd& X, double trials, double& p, Eigen::VectorXd& beta) {
    const JointFit f = E.fit(X);
    const int q = static_cast<int>(X.cols());
    const NestedTest t = E.nested(E.rss_base(), f.rss, q, rank + q, f.n_eff);
    p = std::min(1.0, t.p_value * trials);
    beta = f.beta;
    return t.f_stat > 0.0 && f.full_rank;
  };
  const double family = 3.0 * (2.0 + (P.has_dir ? 1.0 : 0.0)) + (P.has_time ? 1.0 : 0.0);
  DiagnoseOptions o = opt;
  o.structure_search = false;
  for (int i = 0; i < 3; ++i) {
    const std::string coord = "d" + std::to_string(i + 1);
    // Periodic in the axis' position.
    {
      CandidateResult c = evaluate_kinematic_candidate(P, E, "cyclic_error", i, o);
      if (c.identifiable && c.columns.cols() == 2) {
        double p = 1.0;
        Eigen::VectorXd b;
        if (test(c.columns, c.trials * family, p, b) && p < opt.alpha) {
          const double lam = c.params[1].value, a = c.params[0].value;
          out.push_back({"periodic", i, coord, lam, a, 0.0,
                         "a periodic error along axis " + std::to_string(i + 1) + ": wavelength " + fmt(lam * 1e3) +
                             " mm, amplitude " + fmt(a * 1e6) + " µm in its effective displacement (p = " + fmt(p, 2) + ")"});
        }
      }
    }
    // A step at a position: candidate positions at the 10..90 % quantiles.
    {
      std::vector<double> v;
      for (const auto& d : P.d) v.push_back(d[i]);
      std::sort(v.begin(), v.end());
      const int nq = 17;
      double best_p = 1.0, best_at = 0.0, best_b = 0.0;
      for (int q = 0; q < nq; ++q) {
        const double at = v[static_cast<std::size_t>((0.1 + 0.05 * q) * (v.size() - 1))];
        const Eigen::MatrixXd X = hcat({displacement_column(P, i, [&](int j) { return P.d[static_cast<std::size_t>(j)][i] > at ? 1.0 : 0.0; })});
        if (X.col(0).squaredNorm() == 0.0 || E.base_share(X)(0) > 0.995) continue;
        double p = 1.0;
        Eigen::VectorXd b;
        if (test(X, nq * family, p, b) && p < best_p) { best_p = p; best_at = at; best_b = b(0); }
      }
      if (best_p < opt.alpha)
        out.push_back({"step", i, coord, best_at, best_b, 0.0,
                       "a step of " + fmt(best_b * 1e6) + " µm in axis " + std::to_string(i + 1) +
                           "'s effective displacement at d" + std::to_string(i + 1) + " = " + fmt(best_at * 1e3, 4) +
                           " mm (p = " + fmt(best_p, 2) + ")"});
    }
    // Direction dependence.
    if (P.has_dir && sp.n_plus[i] > 0 && sp.n_minus[i] > 0) {
      const Eigen::MatrixXd X =
          hcat({displacement_column(P, i, [&](int j) { return -0.5 * P.inputs[static_cast<std::size_t>(j)].dir[i]; })});
      double p = 1.0;
      Eigen::VectorXd b;
      if (E.base_share(X)(0) < 0.995 && test(X, family, p, b) && p < opt.alpha)
        out.push_back({"direction", i, coord, 0.0, b(0), 0.0,
                       "axis " + std::to_string(i + 1) + " reads " + fmt(b(0) * 1e6) +
                           " µm differently by direction of approach (p = " + fmt(p, 2) + ")"});
    }
  }
  // A drift in time of the measurement itself (e.g. the bar or the instrument warming).
  if (P.has_time && sp.t1 > sp.t0) {
    Eigen::VectorXd col(P.rows());
    for (int r = 0; r < P.rows(); ++r) col(r) = P.inputs[static_cast<std::size_t>(P.sample_of_row(r))].t - sp.t0;
    const Eigen::MatrixXd X = hcat({col});
    double p = 1.0;
    Eigen::VectorXd b;
    if (E.base_share(X)(0) < 0.995 && test(X, family, p, b) && p < opt.alpha)
      out.push_back({"trend", -1, "t", sp.t1 - sp.t0, b(0) * (sp.t1 - sp.t0), 0.0,
                     "a drift in time of " + fmt(b(0) * (sp.t1 - sp.t0) * 1e6) + " µm over the " + fmt(sp.t1 - sp.t0) +
                         " s of the data (p = " + fmt(p, 2) + ")"});
  }
  for (auto& f : out) f.z = 0.0;
  return out;
}

// ---------------------------------------------------------------------------
// Fit

namespace {

io::DataSet subset(const io::DataSet& ds, const std::vector<int>& keep) {
  auto cut_common = [&](const io::CommonColumns& c) {
    io::CommonColumns o;
    for (int j : keep) {
      const auto u = static_cast<std::size_t>(j);
      if (u < c.t.size()) o.t.push_back(c.t[u]);
      if (u < c.dir.size()) o.dir.push_back(c.dir[u]);
      if (u < c.run.size()) o.run.push_back(c.run[u]);
    }
    return o;
  };
  auto cut_info = [&](const io::FileInfo& i) {
    io::FileInfo o = i;
    o.line_of_row.clear();
    for (int j : keep)
      if (static_cast<std::size_t>(j) < i.line_of_row.size()) o.line_of_row.push_back(i.line_of_row[static_cast<std::size_t>(j)]);
    return o;
  };
  if (const auto* b = std::get_if<io::BallbarData>(&ds)) {
    io::BallbarData o = *b;
    o.d.clear();
    o.length.clear();
    for (int j : keep) { o.d.push_back(b->d[static_cast<std::size_t>(j)]); o.length.push_back(b->length[static_cast<std::size_t>(j)]); }
    o.extra = cut_common(b->extra);
    o.info = cut_info(b->info);
    return o;
  }
  const auto& p = std::get<io::PositionData>(ds);
  io::PositionData o = p;
  o.d.clear();
  o.p.clear();
  for (int j : keep) { o.d.push_back(p.d[static_cast<std::size_t>(j)]); o.p.push_back(p.p[static_cast<std::size_t>(j)]); }
  o.extra = cut_common(p.extra);
  o.info = cut_info(p.info);
  return o;
}

double rms_of_model(const io::DataSet& ds, const kin::KinematicModel& m) {
  const KinematicProblem P = read_problem(ds, m);
  return Engine::rms(P.residual_of_model(m));
}

struct JointResult {
  kin::KinematicModel model, base_model;
  std::vector<CandidateResult> effects;
  JointFit fit;
  Eigen::VectorXd base_value;
  KinematicEffects added{};
  Eigen::MatrixXd cov;
};

JointResult joint_fit(const KinematicProblem& P, const std::vector<FitRequest>& req, const DiagnoseOptions& opt) {
  const Engine E(kinematic_linear_problem(P));
  JointResult R;
  std::vector<Eigen::MatrixXd> Xs;
  int ncols = 0;
  for (const auto& r : req) {
    CandidateResult c = evaluate_kinematic_candidate(P, E, r.effect, r.axis, opt);
    if (!c.identifiable || c.columns.cols() == 0)
      throw Error("cannot fit " + c.label() + " on " + P.data_file + ": " + c.note);
    ncols += static_cast<int>(c.columns.cols());
    Xs.push_back(c.columns);
    R.effects.push_back(std::move(c));
  }
  const int per = std::max(1, P.per_sample);
  if (P.samples() * per < E.base_rank() + ncols + 3)
    throw Error("too few samples in " + P.data_file + " to fit " + std::to_string(ncols) + " effect parameter(s) with the " +
                std::to_string(E.base_rank()) + " base parameters (" + std::to_string(P.rows()) + " readings)");
  Eigen::MatrixXd X(E.rows(), ncols);
  int at = 0;
  for (const auto& x : Xs) { X.middleCols(at, x.cols()) = x; at += static_cast<int>(x.cols()); }
  R.fit = E.fit(X);
  if (!R.fit.full_rank) throw Error("the requested effects cannot be told apart from each other in these data");
  R.cov = E.covariance(X, R.fit, E.base_rank() + ncols, true);
  at = 0;
  for (std::size_t k = 0; k < R.effects.size(); ++k) {
    CandidateResult& c = R.effects[k];
    const auto t = *kin::kinematic_effect_from_name(c.effect);
    std::array<double, 3> v = kin::get_params(R.added[c.axis], t);
    auto se = [&](int j) { return std::sqrt(std::max(0.0, R.cov(at + j, at + j))); };
    switch (t) {
      case KinematicEffectType::cyclic_error: {
        const double bs = R.fit.beta(at), bc = R.fit.beta(at + 1);
        v = {std::hypot(bs, bc), c.params[1].value, std::atan2(bc, bs)};
        c.params[0].value = v[0];
        c.params[2].value = v[2];
        break;
      }
      case KinematicEffectType::thermal_drift:
        v = {R.fit.beta(at), c.params[1].value, 0.0};
        c.params[0].value = v[0];
        c.params[0].std_error = se(0);
        break;
      default:
        for (int j = 0; j < static_cast<int>(c.columns.cols()); ++j) {
          v[static_cast<std::size_t>(j)] = R.fit.beta(at + j);
          c.params[static_cast<std::size_t>(j)].value = v[static_cast<std::size_t>(j)];
          c.params[static_cast<std::size_t>(j)].std_error = se(j);
        }
    }
    if (t == KinematicEffectType::backlash && v[0] < 0.0)
      throw Error("backlash" + std::string(" on axis ") + std::to_string(c.axis + 1) + " fits negative (" + fmt(v[0] * 1e6) +
                  " µm): these data show no lost motion there");
    kin::set_params(R.added[c.axis], t, v);
    at += static_cast<int>(c.columns.cols());
  }
  R.base_value = P.base_value + P.base_map * R.fit.base_delta;
  R.model = P.model_of(R.base_value, combine(P.given.effects, R.added));
  R.base_model = P.model_of(P.base_value, P.given.effects);
  R.model.validate();
  return R;
}

}  // namespace

KinematicFit fit_kinematic(const io::DataSet& data, const kin::KinematicModel& model, const std::vector<FitRequest>& req,
                           const DiagnoseOptions& opt, const io::DataSet* holdout, bool cross_validate) {
  if (req.empty()) throw Error("fit: no effect to add");
  const std::string kind = io::kind_name(io::kind_of(data));
  for (const auto& r : req) check_effect_for_kind(r.effect, kind);
  const KinematicProblem P = prepare_kinematic(data, model);
  JointResult J = joint_fit(P, req, opt);
  KinematicFit out;
  out.model = J.model;
  out.effects = J.effects;
  out.on_fit.before = Engine::rms(P.residual_given);
  out.base_only = Engine::rms(P.residual_of_model(J.base_model));
  out.on_fit.after = Engine::rms(P.residual_of_model(J.model));
  for (const auto& c : out.effects)
    for (const auto& p : c.params)
      out.fitted.push_back({"kinematics.limb" + std::to_string(c.axis + 1) + ".effects." + c.effect + "." + p.name, p.unit,
                            0.0, p.value, p.std_error});
  out.notes.push_back("the planes were recalibrated with the effects (" + P.kind + " base: " +
                      std::to_string(P.base_value.size()) + " parameters); calibrated base alone: " +
                      fmt(out.base_only * 1e6) + " µm RMS");
  if (holdout) {
    out.holdout = ErrorFigures{rms_of_model(*holdout, J.base_model), rms_of_model(*holdout, J.model)};
  } else if (cross_validate && P.samples() >= 2 * (static_cast<int>(P.base_value.size()) + 6)) {
    double sb = 0.0, sa = 0.0;
    for (int fold = 0; fold < 2; ++fold) {
      std::vector<int> tr, te;
      for (int j = 0; j < P.samples(); ++j) ((j % 2 == fold) ? tr : te).push_back(j);
      const io::DataSet dtr = subset(data, tr), dte = subset(data, te);
      const KinematicProblem Pt = prepare_kinematic(dtr, model);
      const JointResult Jt = joint_fit(Pt, req, opt);
      sb += std::pow(rms_of_model(dte, Jt.base_model), 2);
      sa += std::pow(rms_of_model(dte, Jt.model), 2);
    }
    out.cross_validation = ErrorFigures{std::sqrt(sb / 2.0), std::sqrt(sa / 2.0)};
  } else if (cross_validate) {
    out.notes.push_back("too few samples for a 2-fold cross-validation");
  }
  return out;
}

}  // namespace cpm::ident
