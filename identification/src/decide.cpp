// SPDX-License-Identifier: Apache-2.0
// Shared middle of a diagnosis (internal.hpp, rank_and_confound): look-elsewhere
// correction and the score of each candidate alone against the model as given,
// the ranking by it, the confounding between candidates (the verdict is the
// selection's: select.cpp); and the way values are said to people.
#include <algorithm>
#include <cmath>
#include <sstream>

#include "internal.hpp"

namespace cpm::ident::detail {
std::string amount(double v, const std::string& units) {
  if (units == "m") return fmt(v * 1e6, 3) + " µm";
  return fmt(v, 3) + " " + units;
}

std::string floor_after(double rms, double floor, const std::string& units) {
  if (floor > rms)
    return "(below the noise floor's estimate, " + amount(floor, units) + ": that estimate is too high)";
  return "(noise floor about " + amount(floor, units) + ")";
}

std::string human_value(const ParamEstimate& p) {
  // Scale to the unit a person reads this size in; the standard error in the same unit.
  double k = 1.0;
  std::string u = p.unit;
  const double a = std::fabs(p.value);
  if (p.unit == "m") { k = a < 1e-3 ? 1e6 : 1e3; u = a < 1e-3 ? "µm" : "mm"; }
  else if (p.unit == "s") { k = 1e3; u = "ms"; }
  else if (p.unit == "rad" && p.name != "phi") { k = a < 1e-3 ? 1e6 : 1e3; u = a < 1e-3 ? "µrad" : "mrad"; }
  else if (p.unit == "1") { k = a < 1e-3 ? 1e6 : 1e2; u = a < 1e-3 ? "ppm" : "%"; }
  else if (p.unit == "N") { k = a < 1.0 ? 1e3 : 1.0; u = a < 1.0 ? "mN" : "N"; }
  std::string s = fmt(p.value * k, 4);
  if (p.std_error >= 0.0) s += " ± " + fmt(p.std_error * k, 2);
  return s + " " + u;
}

namespace {

// Candidates at the top of the ranking whose confounding is looked for.
constexpr int kConfoundTop = 8;
// Share of one's signature another's columns reproduce above which they are
// confounded (|cos| 0.9).
constexpr double kConfoundShare = 0.81;

// The look-elsewhere family (every candidate) and the reference sample size of the scores.
struct Family {
  double size = 0.0;
  double ne_ref = 0.0;
};

Family family_of(const Diagnosis& D) {
  Family F;
  F.size = static_cast<double>(D.candidates.size());
  for (const auto& c : D.candidates) F.ne_ref = std::max(F.ne_ref, c.n_eff);
  return F;
}

int confound_top(const Diagnosis& D) { return std::min<int>(static_cast<int>(D.candidates.size()), kConfoundTop); }

bool names_confounder(const CandidateResult& c, const std::string& label) {
  bool dup = false;
  for (const auto& o : c.confounded) dup |= o.with == label;
  return dup;
}

// Share of u (0..1) that the columns X reproduce by least squares.
double reproduced_share(const Eigen::MatrixXd& X, const Eigen::VectorXd& u) {
  const Eigen::VectorXd coef = X.colPivHouseholderQr().solve(u);
  return std::clamp((X * coef).squaredNorm() / u.squaredNorm(), 0.0, 1.0);
}

// Look-elsewhere correction and significance of each candidate, and its BIC
// against the model as given (the score the ranking uses).
void judge_against_given(Diagnosis& D, const Engine& E, const DiagnoseOptions& opt, const Family& F) {
  const int rank = E.base_rank();
  const double fr = E.floor_rss();
  for (auto& c : D.candidates) {
    c.p_adjusted = std::min(1.0, c.p_value * c.trials * F.size);
    c.significant = c.identifiable && c.p_adjusted < opt.alpha && c.delta_bic < 0.0 &&
                    !(c.params.size() && c.params[0].at_bound && c.params[0].value == 0.0);
    // BIC against the model as given: the parameters beyond it (the nuisance is
    // fitted in every model alike and does not count).
    const int k_total = c.k_total > 0 ? c.k_total : rank + c.n_params;
    const int k_added = std::max(0, k_total - E.nuisance_rank());
    c.score = c.rss + fr > 0.0 && E.rss_given() + fr > 0.0 ? bic_change(F.ne_ref, c.rss, E.rss_given(), fr, k_added)
                                                           : 0.0;
  }
}

void rank_by_significance_and_score(Diagnosis& D) {
  std::stable_sort(D.candidates.begin(), D.candidates.end(), [](const auto& a, const auto& b) {
    if (a.significant != b.significant) return a.significant;
    if (a.identifiable != b.identifiable) return a.identifiable;
    return a.score < b.score;
  });
}

// Confounding between candidates: how much of one's fitted signature the
// other's columns reproduce (after the base is taken out).
void confound_off_base(Diagnosis& D, const Engine& E, const SeparateAdvice& advice) {
  std::vector<Eigen::MatrixXd> Xp(D.candidates.size());
  for (std::size_t j = 0; j < D.candidates.size(); ++j)
    if (D.candidates[j].identifiable && D.candidates[j].columns.cols() && D.candidates[j].refits_base)
      Xp[j] = E.project_off_base(D.candidates[j].columns);
  for (int a = 0; a < confound_top(D); ++a) {
    CandidateResult& ca = D.candidates[a];
    if (Xp[a].size() == 0 || !ca.identifiable) continue;
    const Eigen::VectorXd u = E.project_off_base(ca.fitted);
    if (u.squaredNorm() <= 0.0) continue;
    for (std::size_t b = 0; b < D.candidates.size(); ++b) {
      if (static_cast<int>(b) == a || Xp[b].size() == 0) continue;
      const double share = reproduced_share(Xp[b], u);
      if (share < kConfoundShare) continue;
      const CandidateResult& cb = D.candidates[b];
      ca.confounded.push_back({cb.label(), cb.effect, cb.axis, std::sqrt(share), advice(ca, cb)});
    }
  }
}

// One base-direction candidate ca against another cb, off the nuisance only
// (u: ca's signature there): confounded when cb reproduces most of it.
void judge_against_base_direction(CandidateResult& ca, const CandidateResult& cb, const Eigen::VectorXd& u,
                                  const Engine& E, const SeparateAdvice& advice) {
  const double share = reproduced_share(E.project_off_nuisance(cb.columns), u);
  if (share < kConfoundShare) return;
  if (!names_confounder(ca, cb.label()))
    ca.confounded.push_back({cb.label(), cb.effect, cb.axis, std::sqrt(share), advice(ca, cb)});
}

// Candidates that are base directions (payload, inertia error) are judged
// against the model as given, where the base does not absorb the others:
// compare there, off the nuisance only. A force-gain error on the axis that
// carries the weight is mostly "the weight is off", what a payload is too.
void confound_base_directions(Diagnosis& D, const Engine& E, const SeparateAdvice& advice) {
  for (int a = 0; a < confound_top(D); ++a) {
    CandidateResult& ca = D.candidates[a];
    if (!is_base_direction(ca.effect) || !ca.identifiable || ca.fitted.size() != E.rows()) continue;
    const Eigen::VectorXd u = E.project_off_nuisance(ca.fitted);
    if (u.squaredNorm() <= 0.0) continue;
    for (std::size_t b = 0; b < D.candidates.size(); ++b) {
      const CandidateResult& cb = D.candidates[b];
      if (static_cast<int>(b) == a || cb.columns.cols() == 0 || !cb.refits_base) continue;
      judge_against_base_direction(ca, cb, u, E, advice);
    }
  }
}

// A candidate the base absorbs completely (e.g. a constant force when the
// axis moves one way only) still looks like others on its axis: report the
// pair from the raw columns, so the verdict does not hide it.
void confound_absorbed(Diagnosis& D, const Engine& E, const SeparateAdvice& advice) {
  for (int a = 0; a < confound_top(D); ++a) {
    CandidateResult& ca = D.candidates[a];
    if (ca.columns.cols() == 0 || ca.axis < 0) continue;
    const Eigen::VectorXd ua = E.problem().w.cwiseProduct(ca.columns.col(0));
    for (std::size_t b = 0; b < D.candidates.size(); ++b) {
      const CandidateResult& cb = D.candidates[b];
      if (static_cast<int>(b) == a || cb.identifiable || cb.columns.cols() == 0 || cb.axis != ca.axis) continue;
      const Eigen::VectorXd ub = E.problem().w.cwiseProduct(cb.columns.col(0));
      const double den = ua.norm() * ub.norm();
      const double cosab = den > 0.0 ? std::fabs(ua.dot(ub)) / den : 0.0;
      if (cosab < 0.85 || names_confounder(ca, cb.label())) continue;
      ca.confounded.push_back({cb.label(), cb.effect, cb.axis, cosab,
                               advice(ca, cb) + " (" + cb.label() + " is absorbed by the base in these data)"});
    }
  }
}

}  // namespace

std::string no_effect_text(const Diagnosis& D) {
  return "none: no effect of the library explains a significant part of the residual "
         "(RMS " + amount(D.baseline_rms, D.units) + ", noise floor about " + amount(D.noise_floor, D.units) + ")";
}

void rank_and_confound(Diagnosis& D, const Engine& E, const DiagnoseOptions& opt, const SeparateAdvice& advice) {
  // Look-elsewhere: the family of candidates and the search trials within each.
  const Family F = family_of(D);
  judge_against_given(D, E, opt, F);
  rank_by_significance_and_score(D);
  confound_off_base(D, E, advice);
  confound_base_directions(D, E, advice);
  confound_absorbed(D, E, advice);
  // The verdict and the ranking after it are the selection's, by one
  // statistic: select_motion_effects (select.cpp) for motion logs,
  // select_kinematic_effects (kinematic_select.cpp) for the kinematic kinds.
}

}  // namespace cpm::ident::detail
