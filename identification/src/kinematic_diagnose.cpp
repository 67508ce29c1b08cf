// SPDX-License-Identifier: Apache-2.0
// The kinematic diagnosis (kinematic.hpp): stage 4 (every effect of the table
// on every axis, scored alone), stage 5 (verdict: noise floor, ranking and
// confounding shared with the motion side, the forward selection of
// kinematic_select.cpp, notes) and stage 6 (structure in what remains).
#include <algorithm>
#include <cmath>

#include "effect_search.hpp"
#include "internal.hpp"
#include "kinematic_internal.hpp"

namespace cpm::ident {

using namespace kinematic_detail;
using detail::hcat;

namespace {

KinematicSignature signature_of(const std::string& effect) {
  const auto t = kin::kinematic_effect_from_name(effect);
  const KinematicEffectFitter* f = t ? kinematic_fitter(*t) : nullptr;
  return f ? f->signature : KinematicSignature{};
}

// The measurement that would separate two candidates.
std::string separate_kinematic(const KinematicProblem& P, const KinematicSpan& sp, const CandidateResult& a,
                               const CandidateResult& b) {
  const KinematicSignature da = signature_of(a.effect), db = signature_of(b.effect);
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

// Stage 1's figures of the diagnosis: the data and the model as given.
Diagnosis read_figures(const std::shared_ptr<const KinematicProblem>& Pp) {
  const KinematicProblem& P = *Pp;
  Diagnosis D;
  D.kind = P.kind;
  D.units = "m";
  D.data_file = P.data_file;
  D.samples = P.samples();
  D.kinematic = Pp;
  D.warnings = P.warnings;
  D.notes = P.notes;
  D.baseline_rms = Engine::rms(P.residual_given);
  D.baseline_max = P.residual_given.cwiseAbs().maxCoeff();
  for (int k = 0; k < P.per_sample; ++k) {
    double s = 0.0;
    for (int j = 0; j < P.samples(); ++j) s += std::pow(P.residual_given(P.per_sample * j + k), 2);
    D.baseline_axis_rms[k] = std::sqrt(s / P.samples());
  }
  return D;
}

// What the diagnosis cannot judge on these data, and the base's own confounding.
void data_notes(Diagnosis& D, const KinematicProblem& P) {
  // A bar of unknown length against the common scale.
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
}

}  // namespace

std::vector<CandidateResult> evaluate_kinematic_candidates(const KinematicProblem& P, const Engine& E,
                                                           const DiagnoseOptions& opt) {
  const double baseline_rms = Engine::rms(P.residual_given);
  const double baseline_ms = baseline_rms * baseline_rms;
  const int rank = E.base_rank();
  std::vector<CandidateResult> out;
  for (int t = 0; t < kin::kKinematicEffectTypes; ++t) {
    const auto& in = kin::info(static_cast<kin::KinematicEffectType>(t));
    if (!opt.effects.empty() && std::find(opt.effects.begin(), opt.effects.end(), in.name) == opt.effects.end())
      continue;
    for (int i = 0; i < 3; ++i) {
      CandidateResult c = evaluate_kinematic_candidate(P, E, in.name, i, opt);
      detail::score_candidate(c, E, E.rss_base(), c.n_params, rank + c.n_params, baseline_ms);
      out.push_back(std::move(c));
    }
  }
  return out;
}

Diagnosis diagnose_kinematic(std::shared_ptr<const KinematicProblem> Pp, const DiagnoseOptions& opt) {
  const KinematicProblem& P = *Pp;
  for (const auto& e : opt.effects) check_effect_for_kind(e, P.kind);
  Diagnosis D = read_figures(Pp);
  // Stage 3: the base refit.
  const Engine E(kinematic_linear_problem(P));
  D.rows = E.rows();
  D.base_refit_rms = Engine::rms(E.base_fit().residual);
  // Stage 4: every candidate alone.
  D.candidates = evaluate_kinematic_candidates(P, E, opt);
  // Stage 5: selection and verdict.
  const KinematicNoiseFloor floor = kinematic_noise_floor_of(P, E, D.candidates);
  D.noise_floor = floor.value;
  D.noise_floor_source = floor.source;
  D.noise_floor_upper_bound = floor.upper_bound;
  D.noise_floor_text = floor.text;
  D.notes.push_back(floor.text);
  D.axis_noise = Vec3::Constant(D.noise_floor);
  const KinematicSpan sp = span_of(P);
  detail::rank_and_confound(D, E, opt, [&](const CandidateResult& a, const CandidateResult& b) {
    return separate_kinematic(P, sp, a, b);
  });
  select_kinematic_effects(P, E, opt, D);
  data_notes(D, P);
  // The verdict's rule: structure no library effect describes leads it.
  if (opt.structure_search) kinematic_outside_library(P, E, opt, D);
  // Stage 6: structure.
  if (opt.structure_search) {
    if (D.structure.empty()) D.structure = D.outside_library;  // a tie leaves its finding there already
    for (auto& f : find_kinematic_structure(P, D.residual_final, opt)) D.structure.push_back(std::move(f));
  }
  return D;
}

// ---------------------------------------------------------------------------
// Stage 6: structure in what remains

namespace {

// The tests of the structure scan: one column set against the base refit of
// the residual, the p-value corrected for the search trials and the family
// of tests.
struct StructureScan {
  const KinematicProblem& P;
  const Engine& E;
  KinematicSpan span;
  double family;  // tests in the scan
  double alpha;
  // Fitted coefficients beta and corrected p of columns X; false when the fit fails.
  bool test(const Eigen::MatrixXd& X, double trials, double& p, Eigen::VectorXd& beta) const {
    const JointFit f = E.fit(X);
    const int q = static_cast<int>(X.cols());
    const NestedTest t = E.nested(E.rss_base(), f.rss, q, E.base_rank() + q, f.n_eff);
    p = std::min(1.0, t.p_value * trials);
    beta = f.beta;
    return t.f_stat > 0.0 && f.full_rank;
  }
  // A single column not (nearly) in the base span and significant: its coefficient.
  bool significant(const Eigen::MatrixXd& X, double& p, double& b) const {
    Eigen::VectorXd beta;
    if (!(E.base_share(X)(0) < 0.995 && test(X, family, p, beta) && p < alpha)) return false;
    b = beta(0);
    return true;
  }
};

// Periodic in axis i's position: the cyclic_error search.
void periodic_structure(const StructureScan& S, int i, const DiagnoseOptions& o, std::vector<StructureFinding>& out) {
  const CandidateResult c = evaluate_kinematic_candidate(S.P, S.E, "cyclic_error", i, o);
  if (!c.identifiable || c.columns.cols() != 2) return;
  double p = 1.0;
  Eigen::VectorXd b;
  if (!(S.test(c.columns, c.trials * S.family, p, b) && p < S.alpha)) return;
  const double lam = c.params[1].value, a = c.params[0].value;
  out.push_back({"periodic", i, "d" + std::to_string(i + 1), lam, a, 0.0,
                 "a periodic error along axis " + std::to_string(i + 1) + ": wavelength " + fmt(lam * 1e3) +
                     " mm, amplitude " + fmt(a * 1e6) + " µm in its effective displacement (p = " + fmt(p, 2) + ")"});
}

// A step in axis i's effective displacement: candidate positions at the 10..90 % quantiles.
void step_structure(const StructureScan& S, int i, std::vector<StructureFinding>& out) {
  const KinematicProblem& P = S.P;
  std::vector<double> v;
  for (const auto& d : P.d) v.push_back(d[i]);
  std::sort(v.begin(), v.end());
  const int nq = 17;
  double best_p = 1.0, best_at = 0.0, best_b = 0.0;
  for (int q = 0; q < nq; ++q) {
    const double at = v[static_cast<std::size_t>((0.1 + 0.05 * q) * (v.size() - 1))];
    const Eigen::MatrixXd X =
        hcat({displacement_column(P, i, [&](int j) { return P.d[static_cast<std::size_t>(j)][i] > at ? 1.0 : 0.0; })});
    if (X.col(0).squaredNorm() == 0.0 || S.E.base_share(X)(0) > 0.995) continue;
    double p = 1.0;
    Eigen::VectorXd b;
    if (S.test(X, nq * S.family, p, b) && p < best_p) { best_p = p; best_at = at; best_b = b(0); }
  }
  if (best_p < S.alpha)
    out.push_back({"step", i, "d" + std::to_string(i + 1), best_at, best_b, 0.0,
                   "a step of " + fmt(best_b * 1e6) + " µm in axis " + std::to_string(i + 1) +
                       "'s effective displacement at d" + std::to_string(i + 1) + " = " + fmt(best_at * 1e3, 4) +
                       " mm (p = " + fmt(best_p, 2) + ")"});
}

// Axis i reads differently by the direction of approach.
void direction_structure(const StructureScan& S, int i, std::vector<StructureFinding>& out) {
  const KinematicProblem& P = S.P;
  if (!P.has_dir || S.span.n_plus[i] == 0 || S.span.n_minus[i] == 0) return;
  const Eigen::MatrixXd X =
      hcat({displacement_column(P, i, [&](int j) { return -0.5 * P.inputs[static_cast<std::size_t>(j)].dir[i]; })});
  double p = 1.0, b = 0.0;
  if (S.significant(X, p, b))
    out.push_back({"direction", i, "d" + std::to_string(i + 1), 0.0, b, 0.0,
                   "axis " + std::to_string(i + 1) + " reads " + fmt(b * 1e6) +
                       " µm differently by direction of approach (p = " + fmt(p, 2) + ")"});
}

// A drift in time of the measurement itself (e.g. the bar or the instrument warming).
void trend_structure(const StructureScan& S, std::vector<StructureFinding>& out) {
  const KinematicProblem& P = S.P;
  const KinematicSpan& sp = S.span;
  if (!P.has_time || !(sp.t1 > sp.t0)) return;
  Eigen::VectorXd col(P.rows());
  for (int r = 0; r < P.rows(); ++r) col(r) = P.inputs[static_cast<std::size_t>(P.sample_of_row(r))].t - sp.t0;
  double p = 1.0, b = 0.0;
  if (S.significant(hcat({col}), p, b))
    out.push_back({"trend", -1, "t", sp.t1 - sp.t0, b * (sp.t1 - sp.t0), 0.0,
                   "a drift in time of " + fmt(b * (sp.t1 - sp.t0) * 1e6) + " µm over the " + fmt(sp.t1 - sp.t0) +
                       " s of the data (p = " + fmt(p, 2) + ")"});
}

}  // namespace

std::vector<StructureFinding> find_kinematic_structure(const KinematicProblem& P0, const Eigen::VectorXd& residual,
                                                       const DiagnoseOptions& opt) {
  std::vector<StructureFinding> out;
  if (residual.size() != P0.rows()) return out;
  KinematicProblem P = P0;
  P.residual = -residual;  // residual_final is measurement - model (the engine's y)
  const Engine E(kinematic_linear_problem(P));
  const double family = 3.0 * (2.0 + (P.has_dir ? 1.0 : 0.0)) + (P.has_time ? 1.0 : 0.0);
  const StructureScan S{P, E, span_of(P), family, opt.alpha};
  DiagnoseOptions o = opt;
  o.structure_search = false;
  for (int i = 0; i < 3; ++i) {
    periodic_structure(S, i, o, out);
    step_structure(S, i, out);
    direction_structure(S, i, out);
  }
  trend_structure(S, out);
  for (auto& f : out) f.z = 0.0;
  return out;
}

}  // namespace cpm::ident
