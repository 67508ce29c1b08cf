// SPDX-License-Identifier: Apache-2.0
// Stage 2, columns per effect: the kinematic effect table. Each kinematic
// effect of docs/effects.md has one entry: how its columns are built, how its
// nonlinear parameter is searched, how its values are read from a joint fit,
// and what separates it from the base and from other effects.
//
// Effects that act through the effective displacement d~_i (backlash, cyclic
// error, thermal drift, actuator scale) have columns S_i(row) * dd~_i/dtheta;
// effects on the normals or offsets (guide angular error, limb twist) central
// differences of the full residual.
#include <algorithm>
#include <cmath>
#include <complex>
#include <numbers>

#include "effect_search.hpp"
#include "kinematic_internal.hpp"

namespace cpm::ident {

using namespace kinematic_detail;
using detail::hcat;
using kin::KinematicEffectType;

namespace {

constexpr double kTwoPi = 2.0 * std::numbers::pi;
// Another wavelength whose fit is within this much of the best by BIC (at
// the rows' count; "not worth more than a bare mention") fits alike: the
// data do not determine the wavelength.
constexpr double kAliasBic = 2.0;

// The wavenumber (1/m) that leaves the least RSS, and whether another fits alike.
struct WavenumberSearch {
  double k = 0.0;
  bool determined = true;
};
WavenumberSearch search_cyclic(const KinematicProblem& P, const Engine& E, int axis, double kmin, double kmax,
                               double dk);

using Ctx = KinematicCandidateContext;

void mark_not_identifiable(const Ctx& x, CandidateResult& c, const std::string& why) {
  c.identifiable = false;
  c.note = why;
  c.rss = x.E.rss_base();
  c.residual_after = x.E.base_fit().residual;
  c.fitted = Eigen::VectorXd::Zero(x.E.rows());
  c.columns = Eigen::MatrixXd(x.E.rows(), 0);
  for (int j = 0; j < x.info.n_params; ++j)
    c.params.push_back({x.info.params[j].name, x.info.params[j].unit, 0.0, -1.0, false});
}

// Why these data cannot show the effect at all (empty: they can).
std::string refusal(const Ctx& x, KinematicEffectType type) {
  if (x.info.needs_direction && !x.P.has_dir) return "needs the direction each axis last moved (columns dir1, dir2, dir3)";
  if (x.info.needs_time && !x.P.has_time) return "needs the time of each sample (column t)";
  if (kin::get_params(x.P.given.effects[x.axis], type) != std::array<double, 3>{0, 0, 0}) return "already in the model";
  return {};
}

// The parameter's largest physical size.
double largest(const kin::KinematicEffectParameter& p) { return std::max(std::fabs(p.lower), std::fabs(p.upper)); }

// Whether these data can see column j of an effect at all: the part of it
// outside the base span, at the parameter's largest physical size, changes
// them by at least 3 noise standard deviations (resolution included). A
// circle in one plane cannot see what tilts out of it: there the fit would
// return a wild number with a meaningless standard error.
bool visible(const Engine& E, const Eigen::MatrixXd& X, int j, double bound) {
  const double noise_unit = std::sqrt(1.0 + E.problem().floor_variance);
  const Eigen::MatrixXd Xp = E.project_off_base(X.col(j));
  return Xp.norm() * bound >= 3.0 * noise_unit;
}

std::string base_advice(const KinematicProblem& P, BaseSeparation how, const std::string& base_name, int axis) {
  const std::string ax = axis >= 0 ? "axis " + std::to_string(axis + 1) : "the axes";
  if (how != BaseSeparation::both_directions && base_name == "dl" && P.with_dl) how = BaseSeparation::is_base_scale;
  switch (how) {
    case BaseSeparation::both_directions:
      return "approach the poses from both directions on " + ax + " (dir" + std::to_string(axis + 1) +
             " = +1 and -1 at the same poses)";
    case BaseSeparation::is_base_scale:
      if (P.kind == "ballbar" && P.with_dl)
        return "measure with a second bar radius, or a bar calibrated against a length standard "
               "(length_offset_known = true)";
      return "nothing: the calibration fits each axis' scale c_i, which is this effect";
    case BaseSeparation::other_times:
      return "repeat poses at other times (a longer or a second run, another warm-up state)";
    case BaseSeparation::spread_poses: break;
  }
  return P.kind == "ballbar" ? "spread the poses over more of the hemisphere, with a second bar radius"
                             : "spread the poses over more of the workspace";
}

// The candidate's statistics from the fit of its columns X with the base
// (the base's own when the fit is degenerate), its parameters (values, and
// standard errors from the Jacobian jac at the fitted point) and the base after.
void record_fit(const Ctx& x, CandidateResult& c, const Eigen::MatrixXd& X, const JointFit& f, const Eigen::MatrixXd& jac,
                const std::vector<double>& values, bool degenerate) {
  const Engine& E = x.E;
  c.columns = X;
  c.rss = degenerate ? E.rss_base() : f.rss;
  c.n_eff = degenerate ? E.base_fit().n_eff : f.n_eff;
  c.residual_after = degenerate ? E.base_fit().residual : f.residual;
  c.fitted = degenerate ? Eigen::VectorXd::Zero(E.rows()) : Eigen::VectorXd(X * f.beta);
  const Eigen::MatrixXd cov =
      degenerate ? Eigen::MatrixXd() : E.covariance(jac, f, E.base_rank() + static_cast<int>(jac.cols()), true);
  for (int j = 0; j < x.info.n_params; ++j) {
    const double se = j < cov.rows() ? std::sqrt(std::max(0.0, cov(j, j))) : -1.0;
    c.params.push_back({x.info.params[j].name, x.info.params[j].unit, degenerate ? 0.0 : values[static_cast<std::size_t>(j)],
                        se, false});
  }
  const KinematicProblem& P = x.P;
  for (std::size_t b = 0; b < P.base_names.size(); ++b)
    c.base_after.push_back({P.base_names[b], P.base_units[b],
                            P.base_value(static_cast<Eigen::Index>(b)) + (P.base_map * f.base_delta)(static_cast<Eigen::Index>(b)),
                            -1.0, false});
}

// Finish a candidate from the fit of its columns X: seen at all, recorded,
// confounded with the base, told apart from it.
void finish(const Ctx& x, CandidateResult& c, const Eigen::MatrixXd& X, const JointFit& f, const Eigen::MatrixXd& jac,
            const std::vector<double>& values) {
  const auto separation = kinematic_fitter(x.info.type)->separation;
  bool any_visible = false, any_column = false;
  for (Eigen::Index j = 0; j < X.cols(); ++j) {
    any_column |= X.col(j).norm() > 0.0;
    const int param = x.info.n_params == X.cols() ? static_cast<int>(j) : 0;
    any_visible |= visible(x.E, X, static_cast<int>(j), largest(x.info.params[static_cast<std::size_t>(param)]));
  }
  // A fit that failed (the column in the base span, or nothing) keeps the
  // base's residual; the confounding below still says with what and how to
  // separate them. A column outside the span but too small to matter is
  // simply not seen.
  const char* unseen_note = "these data cannot see it: even at its largest physical size its part that the "
                            "calibrated base cannot take up changes them by less than 3 noise standard deviations";
  if (!any_column) return mark_not_identifiable(x, c, unseen_note);
  const bool unseen = !any_visible;
  const bool degenerate = unseen || !f.full_rank || !f.beta.allFinite() || !f.residual.allFinite();
  record_fit(x, c, X, f, jac, values, degenerate);
  const Eigen::VectorXd share = x.E.base_share(X);
  const Eigen::MatrixXd cosb = x.E.base_cosines(X);
  const std::string with = detail::most_alike_base(cosb, 0, x.P.base_names);
  c.confounded = detail::base_confounders(share, cosb, x.P.base_names, [&](const std::string& name) {
    return base_advice(x.P, separation, name, x.axis);
  });
  // Kinematic data are precise (a bar to 0.3 µm against effects of
  // microns): a column mostly in the base span can still be measured by
  // the part outside it, whose size the standard error reflects. Only a
  // column (numerically) inside the span cannot be told apart.
  const bool in_span = !share.allFinite() || share.minCoeff() > 1.0 - 1e-6;
  if (in_span || (degenerate && !unseen)) {
    c.identifiable = false;
    c.note = "in these data it cannot be told apart from the calibrated base" +
             (with.empty() ? std::string() : " (parameter " + with + ")") + ": " +
             base_advice(x.P, separation, with, x.axis);
  } else if (unseen) {
    c.identifiable = false;
    c.note = unseen_note;
  }
}

// The fit of one or more linear columns with the base, the coefficients as the values.
void fit_linear(const Ctx& x, CandidateResult& c, const Eigen::MatrixXd& X) {
  const JointFit f = x.E.fit(X);
  std::vector<double> values(static_cast<std::size_t>(X.cols()));
  for (Eigen::Index j = 0; j < X.cols(); ++j) values[static_cast<std::size_t>(j)] = f.beta(j);
  finish(x, c, X, f, X, values);
}

// ---------------------------------------------------------------------------
// The fitters

void fit_backlash(const Ctx& x, CandidateResult& c) {
  const Eigen::MatrixXd X = hcat({displacement_column(
      x.P, x.axis, [&](int j) { return -0.5 * x.P.inputs[static_cast<std::size_t>(j)].dir[x.axis]; })});
  const JointFit f = x.E.fit(X);
  const double b = f.beta(0);
  finish(x, c, X, f, X, {b});
  if (b < 0.0) {
    c.params[0].value = 0.0;
    c.params[0].at_bound = true;
    c.rss = x.E.rss_base();
    c.residual_after = x.E.base_fit().residual;
    c.fitted.setZero();
    c.note = "the best fit is a negative lost motion (" + fmt(b * 1e6) + " µm, unphysical); held at 0";
  }
}

// d(a sin(2 pi d / lambda + phi)) / d(a, lambda, phi) as displacement columns.
Eigen::MatrixXd cyclic_error_jacobian(const KinematicProblem& P, int axis, double a, double lambda, double phi) {
  auto d = [&](int j) { return P.d[static_cast<std::size_t>(j)][axis]; };
  return hcat({displacement_column(P, axis, [&](int j) { return std::sin(kTwoPi * d(j) / lambda + phi); }),
               displacement_column(P, axis, [&](int j) {
                 return -a * std::cos(kTwoPi * d(j) / lambda + phi) * kTwoPi * d(j) / (lambda * lambda);
               }),
               displacement_column(P, axis, [&](int j) { return a * std::cos(kTwoPi * d(j) / lambda + phi); })});
}

// The wavenumbers a cyclic error on the axis is searched over: [kmin, kmax]
// (wavelengths of the parameter's bounds, at most 2/3 of the stroke) at
// spacing dk (a quarter cycle over the stroke); kmax <= 0 when the stroke is
// too short to see a period.
struct WaveRange {
  double stroke = 0.0, kmin = 0.0, kmax = 0.0, dk = 0.0;
};

WaveRange wave_range(const Ctx& x) {
  WaveRange w;
  w.stroke = x.span.hi[x.axis] - x.span.lo[x.axis];
  const double lmin = x.info.params[1].lower, lmax = std::min(x.info.params[1].upper, w.stroke / 1.5);
  if (lmax <= lmin * 1.5) return w;
  w.kmin = 1.0 / lmax;
  w.kmax = 1.0 / lmin;
  w.dk = 1.0 / (4.0 * w.stroke);
  return w;
}

// Whether these data determine the wavelength (an axis seen at six heights
// only fits a sine of almost any wavelength alike): said in the note.
void note_wavelength(CandidateResult& c, bool determined) {
  const std::string said = "its wavelength is not determined by these data";
  const auto at = c.note.find(said);
  c.searched_determined = determined;
  if (determined && at != std::string::npos) c.note.erase(at > 2 ? at - 2 : at);
  if (determined || at != std::string::npos) return;
  c.note += (c.note.empty() ? "" : "; ") + said + ": others fit alike (on an axis seen at a few positions, its aliases)";
}

void fit_cyclic_error(const Ctx& x, CandidateResult& c) {
  const WaveRange w = wave_range(x);
  if (w.kmax <= 0.0)
    return mark_not_identifiable(x, c, "axis " + std::to_string(x.axis + 1) + " covers " + fmt(w.stroke * 1e3) +
                                           " mm only: too little to see a periodic error");
  const WavenumberSearch ws = search_cyclic(x.P, x.E, x.axis, w.kmin, w.kmax, w.dk);
  const double bk = ws.k;
  const Eigen::MatrixXd X = cyclic_error_columns(x.P, x.axis, bk);
  const JointFit f = x.E.fit(X);
  // a sin(x + phi) = (a cos phi) sin x + (a sin phi) cos x
  const double a = std::hypot(f.beta(0), f.beta(1)), phi = std::atan2(f.beta(1), f.beta(0));
  const double lambda = 1.0 / bk;
  finish(x, c, X, f, cyclic_error_jacobian(x.P, x.axis, a, lambda, phi), {a, lambda, phi});
  c.trials = std::max(1.0, w.stroke * (w.kmax - w.kmin));
  note_wavelength(c, ws.determined);
}

void fit_guide_angular_error(const Ctx& x, CandidateResult& c) {
  // Two tilts; a pose set may see one only (a circle in the plane of the
  // other axes sees no tilt toward the third): fit what it sees, say so.
  const auto& in = x.info;
  const Eigen::MatrixXd both = hcat({effect_difference(x.P, in.type, x.axis, 0, 1e-4),
                                     effect_difference(x.P, in.type, x.axis, 1, 1e-4)});
  const bool va = visible(x.E, both, 0, largest(in.params[0])), vb = visible(x.E, both, 1, largest(in.params[1]));
  if (va == vb) return fit_linear(x, c, both);
  const int j = va ? 0 : 1;
  const Eigen::MatrixXd X = hcat({both.col(j)});
  const JointFit f = x.E.fit(X);
  finish(x, c, X, f, X, {f.beta(0), 0.0});
  if (c.identifiable && c.params.size() == 2) {
    if (j == 1) std::swap(c.params[0], c.params[1]);
    for (int k = 0; k < 2; ++k) c.params[static_cast<std::size_t>(k)].name = in.params[k].name;
    c.params[static_cast<std::size_t>(1 - j)].value = 0.0;
    c.params[static_cast<std::size_t>(1 - j)].std_error = -1.0;
    c.n_params = 1;
    c.note = "these data cannot see the tilt " + std::string(in.params[1 - j].name) + ": fitted " + in.params[j].name +
             " only";
  }
}

void fit_limb_twist(const Ctx& x, CandidateResult& c) {
  fit_linear(x, c, hcat({effect_difference(x.P, x.info.type, x.axis, 0, 1e-4)}));
}

// d(e d (1 - exp(-t / tau))) / d(e, tau) as displacement columns.
Eigen::MatrixXd thermal_drift_jacobian(const KinematicProblem& P, int axis, double e, double tau) {
  return hcat({thermal_drift_column(P, axis, tau), displacement_column(P, axis, [&](int j) {
                 const auto u = static_cast<std::size_t>(j);
                 const double t = P.inputs[u].t;
                 return -e * P.d[u][axis] * std::exp(-t / tau) * t / (tau * tau);
               })});
}

// The time constants a thermal drift is searched over: [T/30, 10 T] within
// the parameter's bounds, T the time covered.
struct TauRange {
  double lo = 0.0, hi = 0.0;
};

TauRange tau_range(const Ctx& x) {
  const KinematicSpan& sp = x.span;
  const double T = sp.t1 - std::max(0.0, std::min(sp.t0, sp.t1));
  return {std::max(x.info.params[1].lower, (sp.t1 - sp.t0) / 30.0), std::min(x.info.params[1].upper, 10.0 * T)};
}

void fit_thermal_drift(const Ctx& x, CandidateResult& c) {
  const KinematicSpan& sp = x.span;
  if (!(sp.t1 > sp.t0)) return mark_not_identifiable(x, c, "all samples have the same time");
  const auto [lo, hi] = tau_range(x);
  const double tau = search_thermal_time_constant(x.P, x.E, x.axis, lo, hi);
  const Eigen::MatrixXd X = hcat({thermal_drift_column(x.P, x.axis, tau)});
  const JointFit f = x.E.fit(X);
  const double e = f.beta(0);
  finish(x, c, X, f, thermal_drift_jacobian(x.P, x.axis, e, tau), {e, tau});
  c.trials = std::max(1.0, std::log(hi / lo) / std::log(3.0));
  if (c.identifiable && tau >= 0.99 * hi)
    c.note = "tau at the top of the search (" + fmt(hi) + " s): the data see a linear drift";
}

void fit_actuator_scale(const Ctx& x, CandidateResult& c) {
  fit_linear(x, c, hcat({displacement_column(x.P, x.axis, [&](int j) { return x.P.d[static_cast<std::size_t>(j)][x.axis]; })}));
  // The scale is c_i of the base: report c_i - 1 (what a nominal-only
  // model would call actuator_scale).
  const int ci = x.P.kind == "ballbar" ? std::array<int, 3>{0, 1, 3}[static_cast<std::size_t>(x.axis)] : 4 * x.axis + 2;
  c.params[0].value = x.P.base_value(ci) - 1.0;
  c.params[0].std_error = -1.0;
  c.rss = x.E.rss_base();
  c.residual_after = x.E.base_fit().residual;
  c.fitted.setZero();
  c.identifiable = false;
  c.note = "absorbed by the calibrated base: the scale c" + std::to_string(x.axis + 1) +
           " is this effect (s = c - 1 shown; to put it in the model, calibrate: cpm calibrate)";
}

// ---------------------------------------------------------------------------
// Values from a joint fit of several effects

// Linear columns: the coefficients are the parameters.
void linear_joint_values(const JointFit& fit, int at, const Eigen::MatrixXd& cov, CandidateResult& c,
                         std::array<double, 3>& v) {
  for (int j = 0; j < static_cast<int>(c.columns.cols()); ++j) {
    const auto u = static_cast<std::size_t>(j);
    v[u] = fit.beta(at + j);
    c.params[u].value = v[u];
    c.params[u].std_error = std::sqrt(std::max(0.0, cov(at + j, at + j)));
  }
}

void backlash_joint_values(const JointFit& fit, int at, const Eigen::MatrixXd& cov, CandidateResult& c,
                           std::array<double, 3>& v) {
  linear_joint_values(fit, at, cov, c, v);
  if (v[0] < 0.0)
    throw Error("backlash" + std::string(" on axis ") + std::to_string(c.axis + 1) + " fits negative (" + fmt(v[0] * 1e6) +
                " µm): these data show no lost motion there");
}

// Sine and cosine coefficients -> amplitude and phase; the wavelength stays
// where the search put it.
void cyclic_joint_values(const JointFit& fit, int at, const Eigen::MatrixXd&, CandidateResult& c,
                         std::array<double, 3>& v) {
  const double bs = fit.beta(at), bc = fit.beta(at + 1);
  v = {std::hypot(bs, bc), c.params[1].value, std::atan2(bc, bs)};
  c.params[0].value = v[0];
  c.params[2].value = v[2];
}

// The expansion; the time constant stays where the search put it.
void thermal_joint_values(const JointFit& fit, int at, const Eigen::MatrixXd& cov, CandidateResult& c,
                          std::array<double, 3>& v) {
  v = {fit.beta(at), c.params[1].value, 0.0};
  c.params[0].value = v[0];
  c.params[0].std_error = std::sqrt(std::max(0.0, cov(at, at)));
}

// ---------------------------------------------------------------------------
// Searched again beside the effects chosen before

// The candidate at new columns X: its parameters `values` fitted with the
// others (fb, on `beside`), their standard errors from the Jacobian jac
// there; the figures of the effect alone with the base at the new columns.
void take_beside(const Ctx& x, const Engine& beside, CandidateResult& c, const Eigen::MatrixXd& X, const JointFit& fb,
                 const Eigen::MatrixXd& jac, const std::array<double, 3>& values) {
  const Eigen::MatrixXd cov = beside.covariance(jac, fb, beside.base_rank() + static_cast<int>(jac.cols()), true);
  for (int j = 0; j < x.info.n_params && j < static_cast<int>(c.params.size()); ++j) {
    const auto u = static_cast<std::size_t>(j);
    c.params[u].value = values[u];
    c.params[u].std_error = j < cov.rows() ? std::sqrt(std::max(0.0, cov(j, j))) : -1.0;
  }
  c.columns = X;
  const JointFit fa = x.E.fit(X);
  c.rss = fa.rss;
  c.n_eff = fa.n_eff;
  c.residual_after = fa.residual;
  c.fitted = X * fa.beta;
  const double given_rms = Engine::rms(x.P.residual_given);
  detail::score_candidate(c, x.E, x.E.rss_base(), c.n_params, x.E.base_rank() + c.n_params, given_rms * given_rms);
}

void search_cyclic_beside(const Ctx& x, const Engine& beside, CandidateResult& c) {
  const WaveRange w = wave_range(x);
  if (w.kmax <= 0.0 || c.columns.cols() != 2) return;
  const WavenumberSearch ws = search_cyclic(x.P, beside, x.axis, w.kmin, w.kmax, w.dk);
  note_wavelength(c, ws.determined);
  const double k = ws.k;
  const Eigen::MatrixXd X = cyclic_error_columns(x.P, x.axis, k);
  if (!(beside.rss(X) < beside.rss(c.columns))) return;
  const JointFit fb = beside.fit(X);
  const double a = std::hypot(fb.beta(0), fb.beta(1)), phi = std::atan2(fb.beta(1), fb.beta(0));
  take_beside(x, beside, c, X, fb, cyclic_error_jacobian(x.P, x.axis, a, 1.0 / k, phi), {a, 1.0 / k, phi});
}

void search_thermal_beside(const Ctx& x, const Engine& beside, CandidateResult& c) {
  if (!(x.span.t1 > x.span.t0) || c.columns.cols() != 1) return;
  const auto [lo, hi] = tau_range(x);
  const double tau = search_thermal_time_constant(x.P, beside, x.axis, lo, hi);
  const Eigen::MatrixXd X = hcat({thermal_drift_column(x.P, x.axis, tau)});
  if (!(beside.rss(X) < beside.rss(c.columns))) return;
  const JointFit fb = beside.fit(X);
  take_beside(x, beside, c, X, fb, thermal_drift_jacobian(x.P, x.axis, fb.beta(0), tau), {fb.beta(0), tau, 0.0});
}

// The table: one entry per kinematic effect type, in the order of
// kin::KinematicEffectType (the diagnosis evaluates them in this order).
constexpr std::array<KinematicEffectFitter, kin::kKinematicEffectTypes> kFitters = {{
    {KinematicEffectType::backlash, fit_backlash, backlash_joint_values, {true, false, false},
     BaseSeparation::both_directions, nullptr},
    {KinematicEffectType::cyclic_error, fit_cyclic_error, cyclic_joint_values, {false, false, true},
     BaseSeparation::spread_poses, search_cyclic_beside},
    {KinematicEffectType::guide_angular_error, fit_guide_angular_error, linear_joint_values, {false, false, false},
     BaseSeparation::spread_poses, nullptr},
    {KinematicEffectType::limb_twist, fit_limb_twist, linear_joint_values, {false, false, false},
     BaseSeparation::spread_poses, nullptr},
    {KinematicEffectType::thermal_drift, fit_thermal_drift, thermal_joint_values, {false, true, false},
     BaseSeparation::other_times, search_thermal_beside},
    {KinematicEffectType::actuator_scale, fit_actuator_scale, linear_joint_values, {false, false, false},
     BaseSeparation::is_base_scale, nullptr},
}};

constexpr bool one_entry_per_type_in_order() {
  for (int t = 0; t < kin::kKinematicEffectTypes; ++t) {
    const auto& f = kFitters[static_cast<std::size_t>(t)];
    if (static_cast<int>(f.type) != t || f.evaluate == nullptr || f.joint_values == nullptr) return false;
  }
  return true;
}
static_assert(one_entry_per_type_in_order(), "the kinematic effect table needs one entry per effect type, in type order");

}  // namespace

const KinematicEffectFitter* kinematic_fitter(kin::KinematicEffectType type) noexcept {
  for (const auto& f : kFitters)
    if (f.type == type && f.evaluate && f.joint_values) return &f;
  return nullptr;
}

// ---------------------------------------------------------------------------
// Columns and searches

Eigen::MatrixXd cyclic_error_columns(const KinematicProblem& P, int axis, double k) {
  return hcat({displacement_column(P, axis, [&](int j) { return std::sin(kTwoPi * k * P.d[static_cast<std::size_t>(j)][axis]); }),
               displacement_column(P, axis, [&](int j) { return std::cos(kTwoPi * k * P.d[static_cast<std::size_t>(j)][axis]); })});
}

Eigen::VectorXd thermal_drift_column(const KinematicProblem& P, int axis, double tau) {
  return displacement_column(P, axis, [&](int j) {
    const auto u = static_cast<std::size_t>(j);
    return P.d[u][axis] * (1.0 - std::exp(-P.inputs[u].t / tau));
  });
}

namespace {

// RSS of y on two columns a, b (all weighted and off the base): least squares
// by the 2x2 normal equations; on one column when the two are (numerically)
// parallel, as the engine's rank detection does.
double two_column_rss(const Eigen::VectorXd& a, const Eigen::VectorXd& b, const Eigen::VectorXd& y) {
  const double g11 = a.squaredNorm(), g22 = b.squaredNorm(), g12 = a.dot(b), c1 = a.dot(y), c2 = b.dot(y);
  const double yy = y.squaredNorm(), det = g11 * g22 - g12 * g12;
  if (det > 1e-12 * g11 * g22) return yy - (g22 * c1 * c1 - 2.0 * g12 * c1 * c2 + g11 * c2 * c2) / det;
  if (g11 >= g22) return g11 > 0.0 ? yy - c1 * c1 / g11 : yy;
  return yy - c2 * c2 / g22;
}

// The RSS E leaves with cyclic_error's columns at each wavenumber kmin + q dk
// (q < K). The search runs once per candidate and again beside every choice
// of the selection: each row's phase is advanced by a rotation per step (set
// afresh every 64) instead of a sine and a cosine per row and wavenumber.
std::vector<double> cyclic_grid_rss(const KinematicProblem& P, const Engine& E, int axis, double kmin, double dk,
                                    int K) {
  const int N = P.rows();
  std::vector<std::complex<double>> z(static_cast<std::size_t>(N)), turn(static_cast<std::size_t>(N));
  auto d = [&](int r) { return P.d[static_cast<std::size_t>(P.sample_of_row(r))][axis]; };
  for (int r = 0; r < N; ++r) turn[static_cast<std::size_t>(r)] = std::polar(1.0, kTwoPi * dk * d(r));
  const Eigen::VectorXd y = E.project_off_base(E.problem().y);
  Eigen::MatrixXd X(N, 2);
  std::vector<double> out(static_cast<std::size_t>(K));
  for (int q = 0; q < K; ++q) {
    for (int r = 0; r < N; ++r) {
      auto& zr = z[static_cast<std::size_t>(r)];
      zr = q % 64 == 0 ? std::polar(1.0, kTwoPi * (kmin + q * dk) * d(r)) : zr * turn[static_cast<std::size_t>(r)];
      X(r, 0) = P.sensitivity(r, axis) * zr.imag();
      X(r, 1) = P.sensitivity(r, axis) * zr.real();
    }
    const Eigen::MatrixXd Xp = E.project_off_base(X);
    out[static_cast<std::size_t>(q)] = two_column_rss(Xp.col(0), Xp.col(1), y);
  }
  return out;
}

WavenumberSearch search_cyclic(const KinematicProblem& P, const Engine& E, int axis, double kmin, double kmax,
                               double dk) {
  auto rss = [&](double k) { return E.rss(cyclic_error_columns(P, axis, k)); };
  const int K = static_cast<int>((kmax - kmin) / dk) + 1;
  const std::vector<double> grid = cyclic_grid_rss(P, E, axis, kmin, dk, K);
  const std::vector<int> minima = detail::lowest_local_minima(grid, 3);
  WavenumberSearch w;
  w.k = detail::refine_grid_minima(rss, minima, grid, kmin, dk, kmin, kmax, 14, kmin);
  if (minima.size() >= 2) {
    const double fr = E.floor_rss();
    const double g0 = grid[static_cast<std::size_t>(minima[0])], g1 = grid[static_cast<std::size_t>(minima[1])];
    w.determined = E.rows() * std::log((g1 + fr) / (g0 + fr)) >= kAliasBic;
  }
  return w;
}

}  // namespace

double search_cyclic_wavenumber(const KinematicProblem& P, const Engine& E, int axis, double kmin, double kmax,
                                double dk) {
  return search_cyclic(P, E, axis, kmin, kmax, dk).k;
}

double search_thermal_time_constant(const KinematicProblem& P, const Engine& E, int axis, double lo, double hi) {
  auto rss = [&](double log_tau) { return E.rss(hcat({thermal_drift_column(P, axis, std::exp(log_tau))})); };
  return std::exp(detail::grid_then_golden(rss, std::log(lo), std::log(hi), 16, 14, std::log(hi)));
}

// ---------------------------------------------------------------------------
// A candidate

CandidateResult evaluate_kinematic_candidate(const KinematicProblem& P, const Engine& E, const std::string& effect,
                                             int axis, const DiagnoseOptions& opt) {
  const auto type = kin::kinematic_effect_from_name(effect);
  if (!type) throw Error("unknown kinematic effect '" + effect + "'");
  if (axis < 0 || axis > 2) throw Error(effect + ": needs an axis 1..3");
  const KinematicEffectFitter* fitter = kinematic_fitter(*type);
  if (!fitter) throw Error(effect + ": the kinematic effect table has no fitter for it");
  const Ctx x{P, E, axis, kin::info(*type), span_of(P)};
  CandidateResult c;
  c.effect = effect;
  c.axis = axis;
  c.n_params = x.info.n_params;
  if (const std::string why = refusal(x, *type); !why.empty())
    mark_not_identifiable(x, c, why);
  else
    fitter->evaluate(x, c);
  (void)opt;
  return c;
}

}  // namespace cpm::ident
