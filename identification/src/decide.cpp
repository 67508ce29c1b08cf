// Shared tail of a diagnosis (internal.hpp, rank_and_decide): look-elsewhere
// correction and the score against the model as given, the ranking, the
// confounding between candidates, and for the kinematic kinds the verdict with
// forward selection on top of it (motion logs choose in select.cpp); and the
// way values are said to people.
#include <algorithm>
#include <cmath>
#include <sstream>

#include "internal.hpp"

namespace cpm::ident::detail {
std::string amount(double v, const std::string& units) {
  if (units == "m") return fmt(v * 1e6, 3) + " µm";
  return fmt(v, 3) + " " + units;
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

// Per candidate (index in the ranking): the others that explain the data
// about as well against the model as given (BIC within 10). A verdict for it
// is then ambiguous.
using Rivals = std::vector<std::vector<std::string>>;

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
// (u: ca's signature there): confounded when cb reproduces most of it, a
// rival when cb alone explains the data about as well.
void judge_against_base_direction(CandidateResult& ca, const CandidateResult& cb, const Eigen::VectorXd& u,
                                  const Engine& E, const SeparateAdvice& advice, double ne_ref,
                                  std::vector<std::string>& rivals) {
  const double share = reproduced_share(E.project_off_nuisance(cb.columns), u);
  if (share < kConfoundShare) return;
  if (!names_confounder(ca, cb.label()))
    ca.confounded.push_back({cb.label(), cb.effect, cb.axis, std::sqrt(share), advice(ca, cb)});
  const double score_b = bic_change(ne_ref, E.rss(cb.columns, false), E.rss_given(), E.floor_rss(), cb.n_params);
  if (score_b - ca.score < 10.0) rivals.push_back(cb.label());
}

// Candidates that are base directions (payload, inertia error) are judged
// against the model as given, where the base does not absorb the others:
// compare there, off the nuisance only. A force-gain error on the axis that
// carries the weight is mostly "the weight is off", what a payload is too.
Rivals confound_base_directions(Diagnosis& D, const Engine& E, const SeparateAdvice& advice, double ne_ref) {
  Rivals rival(D.candidates.size());
  for (int a = 0; a < confound_top(D); ++a) {
    CandidateResult& ca = D.candidates[a];
    if (!is_base_direction(ca.effect) || !ca.identifiable || ca.fitted.size() != E.rows()) continue;
    const Eigen::VectorXd u = E.project_off_nuisance(ca.fitted);
    if (u.squaredNorm() <= 0.0) continue;
    for (std::size_t b = 0; b < D.candidates.size(); ++b) {
      const CandidateResult& cb = D.candidates[b];
      if (static_cast<int>(b) == a || cb.columns.cols() == 0 || !cb.refits_base) continue;
      judge_against_base_direction(ca, cb, u, E, advice, ne_ref, rival[static_cast<std::size_t>(a)]);
    }
  }
  return rival;
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

// Kinematic kinds: the candidates the verdict (candidates[0]) cannot be told
// apart from, "label (how to separate)"; sets D.ambiguous when there are any.
std::vector<std::string> kinematic_alternatives(Diagnosis& D, const std::vector<std::string>& rivals) {
  const CandidateResult& v = D.candidates[0];
  std::vector<std::string> alts;
  for (const auto& cf : v.confounded) {
    if (cf.effect.empty() || cf.correlation < 0.85) continue;
    const bool close_given = std::find(rivals.begin(), rivals.end(), cf.with) != rivals.end();
    for (const auto& o : D.candidates)
      if (o.label() == cf.with && ((o.significant && o.score - v.score < 10.0) || !o.identifiable || close_given)) {
        D.ambiguous = true;
        alts.push_back(cf.with + " (" + cf.separate_by + ")");
      }
  }
  return alts;
}

std::string kinematic_verdict_text(const Diagnosis& D, const std::vector<std::string>& alts) {
  const CandidateResult& v = D.candidates[0];
  std::ostringstream os;
  os << "missing: " << v.label() << " — ";
  for (std::size_t j = 0; j < v.params.size(); ++j)
    os << (j ? ", " : "") << v.params[j].name << " = " << fmt(v.params[j].value, 4) << " " << v.params[j].unit;
  os << "; it brings the residual from " << amount(D.baseline_rms, D.units) << " to "
     << amount(v.rms_after, D.units) << " RMS (noise floor about " << amount(D.noise_floor, D.units) << ")";
  if (D.ambiguous) {
    os << ". These data cannot tell it apart from ";
    for (std::size_t j = 0; j < alts.size(); ++j) os << (j ? "; " : "") << alts[j];
  }
  return os.str();
}

// The next effect of the kinematic forward selection on top of the columns
// `acc` (fit `cur`): the significant one with the lowest BIC change, or none.
struct NextEffect {
  int index = -1;
  JointFit fit;
};

NextEffect next_kinematic_effect(const Diagnosis& D, const Engine& E, const DiagnoseOptions& opt,
                                 const Eigen::MatrixXd& acc, const JointFit& cur, const std::vector<bool>& used,
                                 double family) {
  NextEffect best;
  double best_bic = 0.0;
  for (std::size_t j = 0; j < D.candidates.size(); ++j) {
    const CandidateResult& c = D.candidates[j];
    if (used[j] || !c.significant || !c.refits_base || c.columns.cols() == 0) continue;
    const Eigen::MatrixXd X = hstack(acc, c.columns);
    const JointFit f = E.fit(X);
    if (!f.full_rank) continue;
    const int k_total = E.base_rank() + static_cast<int>(X.cols());
    const NestedTest t = E.nested(cur.rss, f.rss, c.n_params, k_total, std::max(f.n_eff, 10.0));
    const double p = std::min(1.0, t.p_value * c.trials * family);
    if (p < opt.alpha && t.delta_bic < best_bic) {
      best = {static_cast<int>(j), f};
      best_bic = t.delta_bic;
    }
  }
  return best;
}

// Forward selection of further effects on top of the verdict (candidates[0]):
// fills D.also, returns the fit of everything chosen.
JointFit forward_select_kinematic(Diagnosis& D, const Engine& E, const DiagnoseOptions& opt, double family) {
  const CandidateResult& v = D.candidates[0];
  Eigen::MatrixXd acc = v.refits_base ? v.columns : Eigen::MatrixXd(E.rows(), 0);
  JointFit cur = E.fit(acc);
  std::vector<bool> used(D.candidates.size(), false);
  used[0] = true;
  for (int step = 0; step < opt.max_forward_steps; ++step) {
    NextEffect next = next_kinematic_effect(D, E, opt, acc, cur, used, family);
    if (next.index < 0) break;
    used[static_cast<std::size_t>(next.index)] = true;
    D.also.push_back(next.index);
    acc = hstack(acc, D.candidates[static_cast<std::size_t>(next.index)].columns);
    cur = std::move(next.fit);
  }
  return cur;
}

// Verdict of the kinematic kinds: the first of the ranking when significant,
// further effects by forward selection on top of it.
void decide_kinematic(Diagnosis& D, const Engine& E, const DiagnoseOptions& opt, const Rivals& rival, double family) {
  if (D.candidates.empty() || !D.candidates[0].significant) {
    D.verdict_text = no_effect_text(D);
    D.residual_final = E.base_fit().residual;
    return;
  }
  D.verdict = 0;
  D.verdict_text = kinematic_verdict_text(D, kinematic_alternatives(D, rival[0]));
  const JointFit cur = forward_select_kinematic(D, E, opt, family);
  const CandidateResult& v = D.candidates[0];
  D.residual_final = v.refits_base || !D.also.empty() ? cur.residual : v.residual_after;
  if (!D.also.empty()) {
    D.verdict_text += ". Also significant on top of it: ";
    for (std::size_t j = 0; j < D.also.size(); ++j)
      D.verdict_text += (j ? ", " : "") + D.candidates[D.also[j]].label();
  }
}

}  // namespace

std::string no_effect_text(const Diagnosis& D) {
  return "none: no effect of the library explains a significant part of the residual "
         "(RMS " + amount(D.baseline_rms, D.units) + ", noise floor about " + amount(D.noise_floor, D.units) + ")";
}

void rank_and_decide(Diagnosis& D, const Engine& E, const DiagnoseOptions& opt, const SeparateAdvice& advice) {
  // Look-elsewhere: the family of candidates and the search trials within each.
  const Family F = family_of(D);
  judge_against_given(D, E, opt, F);
  rank_by_significance_and_score(D);
  confound_off_base(D, E, advice);
  const Rivals rival = confound_base_directions(D, E, advice, F.ne_ref);
  confound_absorbed(D, E, advice);
  // Verdict and forward selection: motion logs choose by one statistic from
  // the model as given (select_motion_effects, select.cpp); the kinematic kinds as below.
  if (D.kind == "motion") return;
  decide_kinematic(D, E, opt, rival, F.size);
}

}  // namespace cpm::ident::detail
