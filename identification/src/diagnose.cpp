// SPDX-License-Identifier: Apache-2.0
// The motion diagnosis as its straight list of stages (diagnose.hpp): read,
// align, columns (candidates.cpp), ranking (decide.cpp), selection
// (select.cpp), outside the library (outside.cpp), the one-way ambiguity, the
// delay candidate, structure.
#include "cpm/identification/diagnose.hpp"

#include <algorithm>
#include <cmath>
#include <sstream>

#include "candidates.hpp"
#include "internal.hpp"
#include "cpm/identification/align.hpp"
#include "cpm/identification/stats.hpp"
#include "cpm/identification/structure.hpp"
#include "cpm/kinematics/kinematic_effects.hpp"

namespace cpm::ident {
namespace {

// Resolution of the force residual, as a share of each axis' commanded-force RMS.
constexpr double kMotionResolution = 2e-4;

std::string axis_label(int axis) { return axis >= 0 ? "[axis " + std::to_string(axis + 1) + "]" : ""; }

// The measurement that would tell two candidates apart, from what their
// forces depend on (the library's depends_on).
std::string separate_advice(const CandidateResult& a, const CandidateResult& b,
                            const detail::AxisExcitation& x) {
  const ctl::DynamicEffectInfo &ia = detail::library_row(a.effect), &ib = detail::library_row(b.effect);
  const ctl::EffectDependence da = ia.depends_on, db = ib.depends_on;
  const int ax = a.axis >= 0 ? a.axis : b.axis;
  const std::string axis_text = ax >= 0 ? "axis " + std::to_string(ax + 1) : "the axes";
  const bool one_direction = ax >= 0 && x.one_way[ax];
  // Both act through the force, one on every axis (a payload, an inertia
  // error), the other on one axis only (a drive gain).
  const bool rotor = ia.type == ctl::DynamicEffectType::actuator_inertia || ib.type == ctl::DynamicEffectType::actuator_inertia;
  if (da.force && db.force && ia.per_axis != ib.per_axis)
    return std::string("accelerate the other axes harder (a payload or an inertia error acts on every axis, ") +
           (rotor ? "a rotor's inertia" : "a drive gain") + " only on " + axis_text + ")";
  // A drive gain and a rotor's inertia on one axis: only the gain scales a force that is not inertia.
  if (da.force && db.force && rotor)
    return "hold " + axis_text + " against a steady force (on z the weight) or run it at a steady feed against its "
           "friction: a drive gain scales that force, a rotor's inertia adds none without acceleration";
  if (da.direction != db.direction && one_direction)
    return "move " + axis_text + " in both directions";
  if ((da.direction && db.direction) || (da.speed != db.speed))
    return "run " + axis_text + " at another feed (a different speed)";
  if (da.position != db.position)
    return "cover a longer stroke or another position range on " + axis_text;
  if (da.force || db.force) return "repeat with another payload or other accelerations";
  return "measure with other speeds, both directions and another payload";
}

// Autocorrelation of white noise filtered by the kernel h, at every lag (samples).
std::vector<double> kernel_autocorrelation(const SgKernel& kernel) {
  const auto& h = kernel.h;
  double den = 0.0;
  for (double x : h) den += x * x;
  std::vector<double> rho(h.size(), 0.0);
  for (std::size_t lag = 0; lag < h.size() && den > 0.0; ++lag) {
    double num = 0.0;
    for (std::size_t j = 0; j + lag < h.size(); ++j) num += h[j] * h[j + lag];
    rho[lag] = num / den;
  }
  return rho;
}

// An axis whose residual stays above this multiple of its floor after the
// effects named is not explained (a note; null logs of the independent
// generator sit at 0.97-1.01).
constexpr double kExplainedRatio = 1.25;

// Below this the rows' noise counts as uncorrelated (the honest floor's lags).
constexpr double kWhiteCorrelation = 0.05;

// Second differences of white noise filtered by the acceleration kernel h are
// not those of white noise: their variance relative to white noise's, from
// the kernel's own autocorrelation at the row spacing.
double filtered_difference_variance(const SgKernel& kernel, int stride) {
  const std::vector<double> rho = kernel_autocorrelation(kernel);
  auto at = [&](int lag) { return lag < static_cast<int>(rho.size()) ? rho[static_cast<std::size_t>(lag)] : 0.0; };
  return (6.0 - 8.0 * at(stride) + 2.0 * at(2 * stride)) / 6.0;
}

}  // namespace

namespace detail {
// Fill the statistics of a fitted candidate.
void score_candidate(CandidateResult& c, const Engine& E, double rss_parent, int q, int k_total,
           double baseline_ms) {
  c.k_total = k_total;
  c.rms_after = Engine::rms(c.residual_after);
  c.explained = baseline_ms > 0.0 ? std::clamp(1.0 - c.rms_after * c.rms_after / baseline_ms, 0.0, 1.0) : 0.0;
  const double base_ms = E.rows() ? Engine::rms(E.base_fit().residual) : 0.0;
  c.explained_beyond_base =
      base_ms > 0.0 ? std::clamp(1.0 - c.rms_after * c.rms_after / (base_ms * base_ms), 0.0, 1.0) : 0.0;
  if (!c.identifiable || q <= 0 || c.rss <= 0.0) {
    c.f_stat = 0.0;
    c.p_value = 1.0;
    c.delta_bic = 0.0;
    return;
  }
  const NestedTest t = E.nested(rss_parent, c.rss, q, k_total, c.n_eff);
  c.f_stat = t.f_stat;
  c.p_value = t.p_value;
  c.delta_bic = t.delta_bic;
}

}  // namespace detail

std::string CandidateResult::label() const { return effect + axis_label(axis); }

void check_effect_for_kind(const std::string& effect, const std::string& kind) {
  const bool dyn = ctl::dynamic_effect_from_name(effect).has_value();
  const bool kinem = kin::kinematic_effect_from_name(effect).has_value();
  if (!dyn && !kinem)
    throw Error("unknown effect '" + effect +
                "' (the names are those of docs/effects.md, e.g. coulomb_friction, cogging, backlash)");
  if (kind == "motion" && kinem)
    throw Error(effect + " is a kinematic effect (it changes where the platform is, not the force): a motion "
                "log (kind = motion) cannot show it; measure ball-bar lengths or positions");
  if ((kind == "ballbar" || kind == "position") && dyn)
    throw Error(effect + " is a dynamic effect (a force): " + kind +
                " data cannot show it; record a motion log (kind = motion) with the commanded forces");
}

namespace {

// L with the base columns whose nuisance flag is `nuisance` only.
LinearProblem base_columns_where(const LinearProblem& L, bool nuisance) {
  LinearProblem N = L;
  std::vector<int> keep;
  for (std::size_t b = 0; b < L.nuisance.size(); ++b)
    if ((L.nuisance[b] != 0) == nuisance) keep.push_back(static_cast<int>(b));
  N.B.resize(L.B.rows(), static_cast<Eigen::Index>(keep.size()));
  N.base_names.clear();
  N.base_units.clear();
  N.base_values.clear();
  N.nuisance.clear();
  for (std::size_t q = 0; q < keep.size(); ++q) {
    N.B.col(static_cast<Eigen::Index>(q)) = L.B.col(keep[q]);
    N.base_names.push_back(L.base_names[static_cast<std::size_t>(keep[q])]);
    N.base_units.push_back(L.base_units[static_cast<std::size_t>(keep[q])]);
    N.base_values.push_back(L.base_values[static_cast<std::size_t>(keep[q])]);
    N.nuisance.push_back(nuisance ? 1 : 0);
  }
  return N;
}

}  // namespace

LinearProblem nuisance_only(const LinearProblem& L) { return base_columns_where(L, true); }

LinearProblem without_nuisance(const LinearProblem& L) { return base_columns_where(L, false); }

LinearProblem motion_linear_problem(const MotionProblem& P, Vec3* axis_noise) {
  LinearProblem L;
  const int N = 3 * P.rows();
  L.y = P.residual;
  L.B = P.base;
  for (const auto& b : P.base_params) {
    L.base_names.push_back(b.name);
    L.base_units.push_back(b.unit);
    L.base_values.push_back(b.value);
    L.nuisance.push_back(b.nuisance ? 1 : 0);
  }
  L.series.resize(N);
  for (int r = 0; r < N; ++r) L.series[r] = r % 3;
  L.n_series = 3;
  L.w = Eigen::VectorXd::Ones(N);
  // Per-axis noise from the base refit's residual (second differences: slow
  // structure and isolated steps do not count as noise).
  const Engine e0(L);
  const Eigen::VectorXd& r0 = e0.base_fit().residual;
  Vec3 sigma;
  for (int i = 0; i < 3; ++i) {
    std::vector<double> s;
    for (int r = 0; r < P.rows(); ++r) s.push_back(r0(3 * r + i));
    sigma[i] = noise_from_differences(s);
  }
  const double f = filtered_difference_variance(P.accel_kernel, P.stride);
  if (f > 0.1) sigma /= std::sqrt(f);
  const double floor = sigma.maxCoeff();
  const double rms_all = Engine::rms(r0);
  // The residual's own resolution: on noise-free logs the filtering of terms
  // nonlinear in the state and the linearised plane nuisance leave a few
  // 1e-5 to 1e-4 of the commanded force (a Kim-sized plane-error truth:
  // 4e-5 N; a 0.4 kg payload: 4e-4 N; a 4 N Stribeck breakaway: 2e-3 N),
  // and they leak from the loaded z axis into x and y: one scale for all axes.
  double f2 = 0.0;
  for (int r = 0; r < P.rows(); ++r) f2 += P.f[r].squaredNorm();
  const Vec3 resolution = Vec3::Constant(kMotionResolution * std::sqrt(f2 / std::max(1, 3 * P.rows())));
  for (int i = 0; i < 3; ++i)
    sigma[i] = std::max({sigma[i], resolution[i], 1e-3 * floor, 1e-9 * rms_all, 1e-12});
  for (int r = 0; r < N; ++r) L.w(r) = 1.0 / sigma[r % 3];
  double fv = 0.0;
  for (int i = 0; i < 3; ++i) fv += (resolution[i] / sigma[i]) * (resolution[i] / sigma[i]);
  L.floor_variance = fv / 3.0;
  if (axis_noise) *axis_noise = sigma;
  return L;
}

namespace {

bool is_kind(const std::string& effect, detail::CandidateKind kind) {
  return detail::candidate_fitting(effect).kind == kind;
}

// The parameters of every effect chosen, fitted on what the other chosen
// effects leave (their contributions from the joint fit), with the base
// refitted only when the selection chose to refit it (inertia_error): the
// numbers then belong to the model the verdict describes.
void refine_chosen(Diagnosis& D, const Engine& E, const MotionProblem& P, const ctl::MachineModel& model,
                   const DiagnoseOptions& opt) {
  using detail::CandidateKind;
  const std::vector<int> found = D.found();
  bool base_in = false;
  for (int j : found) base_in |= is_kind(D.candidates[static_cast<std::size_t>(j)].effect, CandidateKind::base_refit);
  LinearProblem L = base_in ? E.problem() : nuisance_only(E.problem());
  const Eigen::VectorXd y0 = L.y;
  for (int j : found) {
    CandidateResult& c = D.candidates[static_cast<std::size_t>(j)];
    if (is_kind(c.effect, CandidateKind::base_refit) || is_kind(c.effect, CandidateKind::alignment)) continue;
    L.y = y0;
    for (int l : found)
      if (l != j && D.candidates[static_cast<std::size_t>(l)].fitted.size() == L.y.size())
        L.y -= D.candidates[static_cast<std::size_t>(l)].fitted;
    const CandidateResult r = evaluate_dynamic_candidate(P, Engine(L), model, c.effect, c.axis, opt);
    if (r.params.size() == c.params.size()) c.params = r.params;
  }
}

// The alignment as a candidate of its own: actuation_delay with tau = the
// delay the model is missing, scored against the model as given at the
// alignment it may take without it (within T/2 of its own delay).
CandidateResult delay_candidate(const Diagnosis& D, const Engine& E, const DiagnoseOptions& opt) {
  const Alignment& A = D.alignment;
  const ctl::DynamicEffectInfo& in = ctl::info(ctl::DynamicEffectType::actuation_delay);
  CandidateResult c;
  c.effect = in.name;
  c.axis = -1;
  c.refits_base = true;
  c.n_params = 1;
  c.trials = A.trials;
  c.n_eff = A.n_eff;
  c.params.push_back({in.params[0].name, in.params[0].unit, A.missing(), A.std_error, false});
  const double n = A.n_eff;
  c.rss = A.rss_at_tau;
  c.rms_after = Engine::rms(E.base_fit().residual);
  c.explained_beyond_base = A.rss_at_reference > 0.0 ? std::clamp(1.0 - A.rss_at_tau / A.rss_at_reference, 0.0, 1.0) : 0.0;
  c.explained = c.explained_beyond_base;
  const NestedTest t = E.nested(A.rss_at_reference, A.rss_at_tau, 1, E.base_rank() + 1, n);
  c.f_stat = t.f_stat;
  c.p_value = t.p_value;
  c.delta_bic = t.delta_bic;
  c.p_adjusted = std::min(1.0, c.p_value * c.trials * static_cast<double>(D.candidates.size() + 1));
  // Beyond T/2 by more than 3 standard errors: a sampling convention cannot explain it.
  const bool beyond = A.beyond_sampling() && (A.std_error < 0.0 || A.missing() - 0.5 * A.period > 3.0 * A.std_error);
  c.significant = beyond && c.p_adjusted < opt.alpha && c.delta_bic < 0.0;
  c.identifiable = true;
  if (!A.determined)
    c.note = "not determined: the fit still improves at an end of the searched range (" +
             std::to_string(MotionProblem::kShiftLo) + " to " + std::to_string(MotionProblem::kShiftHi) +
             " periods); on this trajectory a delay cannot be told from a phase, an inertia or viscous friction: "
             "run a multi-frequency experiment to measure it";
  else if (!A.beyond_sampling())
    c.note = "within half a period of the model's alignment: how the data were sampled (" + A.convention() + ")";
  c.score = c.significant ? -1e300 : 0.0;
  return c;
}

// Stage "the delay candidate": named first when significant and beyond T/2:
// every other effect was fitted on the aligned residual, so the delay is the
// premise of the rest of the verdict.
void name_missing_delay(Diagnosis& D, const Engine& E, const DiagnoseOptions& opt) {
  CandidateResult c = delay_candidate(D, E, opt);
  if (!c.significant) {
    D.candidates.push_back(std::move(c));
    return;
  }
  // First in the ranking and in the verdict.
  D.candidates.insert(D.candidates.begin(), std::move(c));
  std::vector<int> found;
  if (D.verdict >= 0) found.push_back(D.verdict + 1);
  for (int j : D.also) found.push_back(j + 1);
  D.verdict = 0;
  D.also = found;
  const Alignment& A = D.alignment;
  std::ostringstream os;
  os.precision(3);
  os << "missing: actuation_delay (tau = " << detail::human_value(D.candidates[0].params[0]) << ": the force acts "
     << A.tau / A.period << " sample periods after t_k, the model says " << A.model_tau / A.period << ")";
  const std::string rest = D.verdict_text.rfind("missing: ", 0) == 0 ? D.verdict_text.substr(9) : std::string();
  if (found.empty()) os << ". Nothing else is missing";
  D.verdict_text = os.str() + (found.empty() ? std::string() : "; " + rest);
}

using EffectsFound = std::vector<std::pair<std::string, int>>;  // name, axis (0..2, -1)

// The alignment with the effects found so far fitted jointly (their columns
// join the base), and the structure outside the library found beside them:
// an effect or a force left out would pull the delay towards itself (a 2 N
// bump at 250 Hz moved a zero-order hold to 0.5 periods, and what the
// misalignment left on z was named viscous friction).
Alignment align_with(const MotionProblem& Pa, const ctl::MachineModel& model, const EffectsFound& effects,
                     const DiagnoseOptions& opt, const std::vector<StructureFinding>& outside = {}) {
  LinearProblem L = detail::with_structure(alignment_linear_problem(Pa), outside, Pa);
  if (!effects.empty()) {
    const Engine E1(motion_linear_problem(Pa));  // the candidates' own base (their names index it)
    for (const auto& [name, axis] : effects) {
      const detail::CandidateFitting& row = detail::candidate_fitting(name);
      // Inside the base / the alignment itself / always fitted with it.
      if (row.kind == detail::CandidateKind::base_refit || row.kind == detail::CandidateKind::alignment ||
          row.in_alignment_columns)
        continue;
      const CandidateResult c = evaluate_dynamic_candidate(Pa, E1, model, name, axis, opt);
      if (c.columns.cols() == 0) continue;
      const Eigen::Index nb = L.B.cols();
      L.B.conservativeResize(Eigen::NoChange, nb + c.columns.cols());
      L.B.rightCols(c.columns.cols()) = c.columns;
      for (Eigen::Index j = 0; j < c.columns.cols(); ++j) {
        L.base_names.push_back(c.label());
        L.base_units.push_back("");
        L.base_values.push_back(0.0);
        L.nuisance.push_back(0);
      }
    }
  }
  return estimate_alignment(Pa, Engine(std::move(L)));
}

EffectsFound effects_found(const Diagnosis& D) {
  EffectsFound found;
  for (int j : D.found())
    found.emplace_back(D.candidates[static_cast<std::size_t>(j)].effect, D.candidates[static_cast<std::size_t>(j)].axis);
  return found;
}

// Stage "read": the residual of the model as given, at the alignment.
Diagnosis read_motion(const io::MotionData& data, const ctl::Machine& model, const DiagnoseOptions& opt,
                      const Alignment& alignment) {
  Diagnosis D;
  D.data_file = data.info.path;
  D.samples = static_cast<int>(data.t.size());
  D.motion = prepare_motion(data, model, opt.motion);
  D.alignment = alignment;
  D.motion.set_delay(alignment.tau);
  D.warnings = D.motion.warnings;
  for (const auto& w : data.info.warnings) D.warnings.push_back(w);
  return D;
}

// The residual's size before any fit, per axis, after the base refit, and its noise.
void record_baseline(Diagnosis& D, const Engine& E) {
  const MotionProblem& P = D.motion;
  D.rows = E.rows();
  D.baseline_rms = Engine::rms(P.residual);
  D.baseline_max = P.residual.cwiseAbs().maxCoeff();
  for (int i = 0; i < 3; ++i) {
    double s = 0.0;
    for (int r = 0; r < P.rows(); ++r) s += P.residual(3 * r + i) * P.residual(3 * r + i);
    D.baseline_axis_rms[i] = std::sqrt(s / P.rows());
  }
  D.base_refit_rms = Engine::rms(E.base_fit().residual);
  D.noise_floor = std::sqrt(D.axis_noise.squaredNorm() / 3.0);
}

// Stage "columns": every dynamic effect (or those asked for) on every axis,
// fitted and scored against its parent.
void evaluate_candidates(Diagnosis& D, const Engine& E, const ctl::MachineModel& model, const DiagnoseOptions& opt) {
  const double baseline_ms = D.baseline_rms * D.baseline_rms;
  for (const auto& [name, axis] : detail::candidate_list(opt)) {
    CandidateResult c = evaluate_dynamic_candidate(D.motion, E, model, name, axis, opt);
    detail::score_by_kind(c, E, baseline_ms);
    D.candidates.push_back(std::move(c));
  }
}

// Stage "selection" (select.cpp), then each effect chosen refitted on what the others leave.
// The honest floor: per axis the white part of the final residual, from its
// high band: second differences of the rows along time, at lags where the
// filter that made the rows no longer correlates their noise (neighbouring
// rows share part of their window: at lag 1 the kernel's own correction
// assumes the force and the acceleration share one filter, and left the floor
// 8-10 % low on null logs of the independent generator). A smooth force, an
// effect or a structure barely reaches these differences; the floor is never
// the residual's own RMS.
void measure_noise_floor(Diagnosis& D) {
  const MotionProblem& P = D.motion;
  const int R = P.rows();
  if (R < 20 || D.residual_final.size() != 3 * R) return;
  const std::vector<double> rho = kernel_autocorrelation(P.accel_kernel);
  auto rho_at = [&](int lag) { return lag < static_cast<int>(rho.size()) ? rho[static_cast<std::size_t>(lag)] : 0.0; };
  int L0 = 1;
  while (L0 < 8 && std::fabs(rho_at(L0 * P.stride)) > kWhiteCorrelation) ++L0;
  for (int i = 0; i < 3; ++i) {
    std::vector<double> s(static_cast<std::size_t>(R));
    double ss = 0.0;
    for (int r = 0; r < R; ++r) {
      s[static_cast<std::size_t>(r)] = D.residual_final(3 * r + i);
      ss += s[static_cast<std::size_t>(r)] * s[static_cast<std::size_t>(r)];
    }
    // Two lags beyond the correlation, their variances averaged, each
    // corrected for what correlation is left at its lag.
    double v = 0.0;
    for (int L = L0; L <= L0 + 1; ++L) {
      const double f = (6.0 - 8.0 * rho_at(L * P.stride) + 2.0 * rho_at(2 * L * P.stride)) / 6.0;
      const double n = noise_from_differences(s, L);
      v += 0.5 * n * n / std::max(f, 0.1);
    }
    D.axis_floor[i] = std::sqrt(v);
    D.axis_residual_rms[i] = std::sqrt(ss / R);
  }
  // The floor the verdict and the loop compare against (the weights keep axis_noise).
  D.noise_floor = std::sqrt(D.axis_floor.squaredNorm() / 3.0);

  D.noise_floor_source = "residual high band";
  D.noise_floor_text = "the noise floor from the residual's high band: second differences of each axis' residual along time at lags " +
                         std::to_string(L0) + " and " + std::to_string(L0 + 1) +
                         " rows (1.4826 MAD / sqrt 6), beyond the correlation of the rows' filter";
}

// Beside structure outside the library the alignment is estimated with that
// structure fitted on its axis, which takes part of the axis' delay signature
// (the force's slope) with it, so the alignment is less certain; and a
// misalignment on an axis that moves nearly sinusoidally reads as viscous
// friction there (the slope is the jerk, about -omega^2 times the velocity).
// A hump of v1 on axis 2 at 250 Hz moved the alignment 0.72 ms (two of its
// standard errors) from the log without it and left b = 0.23 +- 0.057 N s/m on
// axis 2, which the log without the hump gives too at that alignment. So a
// one-parameter effect is judged with the alignment's standard error carried
// into its value (its change per unit delay, fitted beside the others chosen),
// at the selection's own level over the family of candidates: empty when it
// stays significant, else why it is not a missing effect of its own.
std::string within_alignment_uncertainty(const Diagnosis& D, const Engine& E, const CandidateResult& c,
                                         const DiagnoseOptions& opt) {
  const double st = D.alignment.std_error;
  if (!(st > 0.0) || c.params.size() != 1 || c.columns.cols() != 1 || c.columns.rows() != E.rows()) return {};
  const Eigen::VectorXd slope = D.motion.force_delay_slope(D.motion.delay);
  if (slope.size() != E.rows()) return {};
  // The chosen effects' columns, c's first; base refitted as the selection did.
  Eigen::MatrixXd X = c.columns;
  bool base_in = false;
  for (int j : D.found()) {
    const CandidateResult& o = D.candidates[static_cast<std::size_t>(j)];
    if (detail::is_base_refit(o.effect)) base_in = true;
    else if (&o != &c && !o.held_out && !detail::is_alignment(o.effect) && o.columns.rows() == E.rows())
      X = detail::hstack(X, o.columns);
  }
  LinearProblem L = E.problem();
  L.y = slope;
  const JointFit per_delay = Engine(std::move(L)).fit(X, base_in);
  if (!per_delay.full_rank || per_delay.beta.size() < 1) return {};
  const ParamEstimate& p = c.params[0];
  const double from_alignment = std::fabs(per_delay.beta(0)) * st;  // parameter units
  const double se = std::hypot(std::max(0.0, p.std_error), from_alignment);
  if (!(se > 0.0)) return {};
  const double z = std::fabs(p.value) / se;
  const double p_adjusted = 2.0 * normal_tail(z) * static_cast<double>(D.candidates.size());
  if (p_adjusted < opt.alpha) return {};
  std::ostringstream os;
  os.precision(2);
  os << "within what the alignment's uncertainty (" << st * 1e3 << " ms) leaves on its axis: " << p.name << " "
     << detail::fmt(p.value, 3) << " ± " << detail::fmt(se, 2) << " " << p.unit << " with it, not significant";
  return os.str();
}

// An effect whose refit beside the others goes to 0 (its bound) explains
// nothing there and is never named: it is held at 0, which keeps it out of the
// selection (selection_terms), and the selection is run again without it
// (Coulomb and Stribeck friction on z behind a delay: Stribeck and viscous
// friction had been named "missing" with the value 0).
//
// Beside structure outside the library, an effect whose refit there comes out
// with a value no missing effect has, or with a parameter the data do not
// determine (detail::not_missing_beside_outside), is fitting part of that
// structure, not a missing effect of its own: it is held out likewise and
// said as partial with its value (a hump in v1 on a circle: a -4.3 kg rotor
// inertia, a -25 N/m spring at its rest-position bound and a -90 % drive gain).
void select_effects(Diagnosis& D, const Engine& E, const ctl::MachineModel& model, const DiagnoseOptions& opt) {
  for (int pass = 0; pass < 8; ++pass) {
    detail::select_motion_effects(D, E, opt);
    refine_chosen(D, E, D.motion, model, opt);
    bool held = false;
    for (int j : D.found()) {
      CandidateResult& c = D.candidates[static_cast<std::size_t>(j)];
      if (c.params.empty() || detail::is_alignment(c.effect)) continue;
      if (c.params[0].value == 0.0) {
        c.params[0].at_bound = true;
        held = true;
      } else if (!D.outside_library.empty()) {
        std::string why = detail::not_missing_beside_outside(c);
        if (why.empty()) why = within_alignment_uncertainty(D, E, c, opt);
        if (!why.empty()) {
          c.held_out = true;
          D.partial_unphysical.push_back({c.effect, c.axis, c.params, std::move(why)});
          held = true;
        }
      }
    }
    if (!held) break;
  }
  measure_noise_floor(D);  // of what the effects chosen leave: the floor the verdict states
  detail::verdict_text_motion(D);
}

// Stage "outside the library" (outside.cpp): strong structure left leads the
// verdict, and the selection is redone with it fitted beside the library.
// Rescanned after each reselection (a narrow bump leaves some of itself
// beside the bin that describes it), three rounds at most; then only the
// findings that stay strong with the others fitted are kept.
void look_outside_library(Diagnosis& D, const Engine& E, const ctl::MachineModel& model, const DiagnoseOptions& opt) {
  std::vector<std::string> before;  // the effects named before any structure was fitted beside them
  for (int j : D.found()) before.push_back(D.candidates[static_cast<std::size_t>(j)].label());
  std::optional<Engine> Es;
  // Structure in what the model as given leaves that beats the library effects on its axis.
  if (std::vector<StructureFinding> early = detail::structure_that_beats_library(D, E, opt); !early.empty()) {
    D.outside_library = std::move(early);
    Es.emplace(detail::with_structure(E.problem(), D.outside_library, D.motion));
    for (auto& c : D.candidates) c.alternatives.clear();
    select_effects(D, *Es, model, opt);
  }
  for (int round = 0; round < 3; ++round) {
    const std::vector<StructureFinding> more = detail::strong_structure(D, D.motion, opt);
    if (more.empty()) break;
    D.outside_library.insert(D.outside_library.end(), more.begin(), more.end());
    Es.emplace(detail::with_structure(E.problem(), D.outside_library, D.motion));
    for (auto& c : D.candidates) c.alternatives.clear();
    select_effects(D, *Es, model, opt);
  }
  if (Es) {
    std::vector<StructureFinding> kept = detail::confirmed_outside_library(D, E, opt);
    if (kept.size() < D.outside_library.size()) {
      D.outside_library = std::move(kept);
      Es.emplace(detail::with_structure(E.problem(), D.outside_library, D.motion));
      for (auto& c : D.candidates) c.alternatives.clear();
      // Nothing outside left: what was held out beside it is judged as any effect again.
      if (D.outside_library.empty()) {
        for (auto& c : D.candidates) c.held_out = false;
        D.partial_unphysical.clear();
      }
      select_effects(D, *Es, model, opt);
    }
  }
  // Those no longer named beside the structure explained part of it.
  if (!D.outside_library.empty())
    for (const std::string& b : before) {
      bool still = false;
      for (int j : D.found()) still |= D.candidates[static_cast<std::size_t>(j)].label() == b;
      if (!still) D.partial.push_back(b);
    }
  detail::lead_with_outside_library(D);
}

// Effects named that leave an axis well above its floor have not explained it: a note.
void note_unexplained_axes(Diagnosis& D) {
  // Effects named that leave an axis well above its floor have not explained it.
  if (!D.found().empty() && D.outside_library.empty())
    for (int i = 0; i < 3; ++i)
      if (D.axis_floor[i] > 0.0 && D.axis_residual_rms[i] > kExplainedRatio * D.axis_floor[i]) {
        std::ostringstream os;
        os.precision(3);
        os << "axis " << i + 1 << ": the residual stays " << D.axis_residual_rms[i] / D.axis_floor[i]
           << " x its noise floor after the effects named: they do not explain all of it, and the scan locates "
              "no structure in the rest";
        D.notes.push_back(os.str());
      }
}

bool steady_on_one_way_axis(const std::string& effect) {
  return detail::candidate_fitting(effect).steady_on_one_way_axis;
}

// Stage "the one-way ambiguity": Coulomb friction on an axis that moved one
// way only is a constant force: what a tilted plane puts into the weight,
// what a force-gain error makes of a nearly steady force, what a distant
// spring pulls. The fit may prefer one of them, but these data cannot name
// the cause: say so.
void note_one_way_ambiguity(Diagnosis& D, const detail::AxisExcitation& ex) {
  if (D.verdict < 0) return;
  CandidateResult& v = D.candidates[static_cast<std::size_t>(D.verdict)];
  if (v.axis < 0 || !ex.one_way[static_cast<std::size_t>(v.axis)] || !steady_on_one_way_axis(v.effect)) return;
  const std::string ax = std::to_string(v.axis + 1);
  std::vector<std::string> alts;  // the other steady forces, by name
  for (int t = 0; t < ctl::kDynamicEffectTypes; ++t) {
    const ctl::DynamicEffectInfo& in = ctl::info(static_cast<ctl::DynamicEffectType>(t));
    if (in.per_axis && steady_on_one_way_axis(in.name) && v.effect != in.name)
      alts.push_back(std::string(in.name) + "[axis " + ax + "]");
  }
  std::sort(alts.begin(), alts.end());
  D.ambiguous = true;
  D.verdict_text += ". Axis " + ax + " moved one way only: a steady force on it cannot be told apart between " +
                    v.label();
  for (const auto& a : alts) D.verdict_text += ", " + a;
  D.verdict_text += " and a tilted plane's share of the weight; to separate, move axis " + ax + " in both directions";
  for (const auto& c : D.candidates)
    if (c.axis == v.axis && steady_on_one_way_axis(c.effect) && c.label() != v.label()) {
      bool dup = false;
      for (const auto& o : v.confounded) dup |= o.with == c.label();
      if (!dup) v.confounded.push_back({c.label(), c.effect, c.axis, 0.0, "move axis " + ax + " in both directions"});
    }
}

void note_unidentifiable_base(Diagnosis& D, const Engine& E) {
  if (E.unidentifiable_base().empty()) return;
  std::string names;
  for (int j : E.unidentifiable_base()) names += (names.empty() ? "" : ", ") + D.motion.base_params[j].name;
  D.notes.push_back("these data cannot determine the base parameter(s) " + names +
                    "; they are kept at the model's values");
}

// The diagnosis at one alignment, stage by stage.
Diagnosis diagnose_aligned(const io::MotionData& data, const ctl::Machine& model, const DiagnoseOptions& opt,
                           const Alignment& alignment) {
  Diagnosis D = read_motion(data, model, opt, alignment);
  const Engine E(motion_linear_problem(D.motion, &D.axis_noise));
  record_baseline(D, E);
  evaluate_candidates(D, E, model.model(), opt);
  // Stage "ranking" (decide.cpp): significance, confounding between candidates.
  const detail::AxisExcitation ex = detail::excitation(D.motion);
  detail::rank_and_confound(D, E, opt, [&ex](const CandidateResult& a, const CandidateResult& b) {
    return separate_advice(a, b, ex);
  });
  select_effects(D, E, model.model(), opt);
  look_outside_library(D, E, model.model(), opt);
  note_one_way_ambiguity(D, ex);
  note_unidentifiable_base(D, E);
  name_missing_delay(D, E, opt);
  if (opt.structure_search) D.structure = find_motion_structure(D.motion, D.residual_final, D.axis_noise);
  note_unexplained_axes(D);
  return D;
}

}  // namespace

Diagnosis diagnose_motion(const io::MotionData& data, const ctl::Machine& model,
                          const DiagnoseOptions& opt) {
  for (const auto& e : opt.effects) check_effect_for_kind(e, "motion");
  // Stage "align" (align.hpp): when the logged force acts, first with the
  // base alone, then again with the effects the diagnosis found and the
  // structure outside the library it fitted beside them; when that
  // moves it beyond its noise the diagnosis is redone there.
  const MotionProblem Pa = alignment_problem(data, model, opt.motion);
  Alignment A = align_with(Pa, model.model(), {}, opt);
  Diagnosis D = diagnose_aligned(data, model, opt, A);
  // A large effect left out pulls the alignment (a 4 N Stribeck spike moved
  // it to the end of the range); the effects found at a wrong alignment are
  // partly wrong too: iterate until the alignment settles within its noise.
  for (int pass = 0; pass < 3; ++pass) {
    const EffectsFound found = effects_found(D);
    if (found.empty() && D.outside_library.empty()) break;
    const Alignment A2 = align_with(Pa, model.model(), found, opt, D.outside_library);
    if (std::fabs(A2.tau - A.tau) <= std::max(0.05 * A.period, 2.0 * std::max(0.0, A2.std_error))) break;
    A = A2;
    D = diagnose_aligned(data, model, opt, A);
  }
  return D;
}

}  // namespace cpm::ident
