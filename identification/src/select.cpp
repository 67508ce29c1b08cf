// Stage "selection" of the motion diagnosis (internal.hpp, select_motion_effects).
//
// One statistic for the ranking, the verdict and the significance column:
// forward selection from the model as given. At each step every effect not
// yet chosen (every library effect on every axis, the payload, and the base
// refit itself as inertia_error) is fitted jointly with those chosen so far;
// the one with the lowest BIC change is taken when its nested F-test, with
// the look-elsewhere correction over the candidates still in play and its
// own search trials (Bonferroni over the whole library and all axes, which
// also bounds the false discoveries),
// stands below alpha. The base is refitted only once inertia_error has been
// chosen: what a refit would absorb (a payload, a drive gain on z, a mass
// error) is then a finding of its own instead of vanishing into it.
#include <algorithm>
#include <cmath>
#include <sstream>

#include "internal.hpp"

namespace cpm::ident::detail {
namespace {

struct Term {
  int candidate = -1;
  bool base = false;    // inertia_error: the base refit
  Eigen::MatrixXd X;    // columns (unweighted); none for the base
};

struct StepFit {
  double rss = 0.0, n_eff = 0.0, p_adj = 1.0, dbic = 0.0, f_stat = 0.0, p = 1.0;
  bool ok = false;
  JointFit fit;
};

Eigen::MatrixXd hstack(const Eigen::MatrixXd& a, const Eigen::MatrixXd& b) {
  Eigen::MatrixXd X(a.rows() ? a.rows() : b.rows(), a.cols() + b.cols());
  if (a.cols()) X.leftCols(a.cols()) = a;
  if (b.cols()) X.rightCols(b.cols()) = b;
  return X;
}

}  // namespace

void select_motion_effects(Diagnosis& D, const Engine& E, const DiagnoseOptions& opt) {
  std::vector<Term> terms;
  for (std::size_t j = 0; j < D.candidates.size(); ++j) {
    const CandidateResult& c = D.candidates[j];
    if (!c.identifiable || c.effect == "actuation_delay") continue;
    if (!c.params.empty() && c.params[0].at_bound && c.params[0].value == 0.0) continue;
    Term t;
    t.candidate = static_cast<int>(j);
    t.base = c.effect == "inertia_error";
    if (!t.base) {
      if (c.columns.cols() == 0) continue;
      t.X = c.columns;
    } else if (E.base_rank_beyond_nuisance() == 0) {
      continue;
    }
    terms.push_back(std::move(t));
  }
  const double ne_ref = std::max(10.0, E.base_fit().n_eff);
  Eigen::MatrixXd XS(E.rows(), 0);
  bool base_in = false;
  double rss_cur = E.rss_given();
  int k_cur = E.nuisance_rank();
  std::vector<int> chosen;  // candidate indices, in order
  std::vector<StepFit> at_choice(D.candidates.size());
  std::vector<StepFit> last(D.candidates.size());
  const double fr = E.floor_rss();
  const int max_steps = std::max(1, opt.max_forward_steps);
  for (int step = 0; step <= max_steps; ++step) {
    // The family: every candidate of the library on every axis that has not been
    // chosen, whether or not the data can show it (those held at a bound were
    // looked at too).
    const double remaining = static_cast<double>(D.candidates.size() - chosen.size());
    int best = -1;
    for (const Term& t : terms) {
      if (std::find(chosen.begin(), chosen.end(), t.candidate) != chosen.end()) continue;
      const CandidateResult& c = D.candidates[static_cast<std::size_t>(t.candidate)];
      StepFit s;
      const bool with_base = base_in || t.base;
      const Eigen::MatrixXd X = t.base ? XS : hstack(XS, t.X);
      s.fit = E.fit(X, with_base);
      // Parameters added: the columns, or the effect's parameters where some
      // were searched (a cogging wavelength, a Stribeck speed) and so were fitted too.
      const int q = t.base ? E.base_rank_beyond_nuisance() : std::max(static_cast<int>(t.X.cols()), c.n_params);
      const int k_new = k_cur + q;
      if (!s.fit.full_rank || s.fit.rss >= rss_cur) {
        last[static_cast<std::size_t>(t.candidate)] = s;
        continue;
      }
      const NestedTest nt = E.nested(rss_cur, s.fit.rss, q, k_new, std::max(s.fit.n_eff, 10.0));
      s.rss = s.fit.rss;
      s.n_eff = s.fit.n_eff;
      s.f_stat = nt.f_stat;
      s.p = nt.p_value;
      s.p_adj = std::min(1.0, nt.p_value * std::max(1.0, c.trials) * remaining);
      s.dbic = rss_cur + fr > 0.0 ? ne_ref * std::log((s.rss + fr) / (rss_cur + fr)) + q * std::log(ne_ref) : 0.0;
      s.ok = s.p_adj < opt.alpha && s.dbic < 0.0;
      last[static_cast<std::size_t>(t.candidate)] = s;
      if (s.ok && (best < 0 || s.dbic < last[static_cast<std::size_t>(best)].dbic)) best = t.candidate;
    }
    if (best < 0 || step == max_steps) break;
    const StepFit& s = last[static_cast<std::size_t>(best)];
    // Alternatives: as good by BIC (within 6, "strong" evidence) with a signature
    // alike (what either adds to the fit so far, off the nuisance: |cos| > 0.9).
    {
      const Eigen::VectorXd ub = E.project_off_nuisance(s.fit.residual) ;
      const Eigen::VectorXd gain_best = E.project_off_nuisance(E.problem().y) - ub;
      for (const Term& t : terms) {
        if (t.candidate == best || std::find(chosen.begin(), chosen.end(), t.candidate) != chosen.end()) continue;
        const StepFit& o = last[static_cast<std::size_t>(t.candidate)];
        if (!o.ok || o.dbic - s.dbic > 6.0) continue;
        const Eigen::VectorXd gain_o = E.project_off_nuisance(E.problem().y) - E.project_off_nuisance(o.fit.residual);
        const double den = gain_best.norm() * gain_o.norm();
        if (den > 0.0 && std::fabs(gain_best.dot(gain_o)) / den > 0.9)
          D.candidates[static_cast<std::size_t>(best)].alternatives.push_back(
              D.candidates[static_cast<std::size_t>(t.candidate)].label());
      }
    }
    at_choice[static_cast<std::size_t>(best)] = s;
    chosen.push_back(best);
    for (const Term& t : terms)
      if (t.candidate == best) {
        if (t.base) {
          base_in = true;
          k_cur += E.base_rank_beyond_nuisance();
        } else {
          XS = hstack(XS, t.X);
          k_cur += std::max(static_cast<int>(t.X.cols()), D.candidates[static_cast<std::size_t>(best)].n_params);
        }
      }
    rss_cur = s.rss;
  }

  // The statistics every column shows: at the step an effect was chosen, or,
  // for the others, on top of everything chosen.
  for (std::size_t j = 0; j < D.candidates.size(); ++j) {
    CandidateResult& c = D.candidates[j];
    if (c.effect == "actuation_delay") continue;
    const bool is_chosen = std::find(chosen.begin(), chosen.end(), static_cast<int>(j)) != chosen.end();
    const StepFit& s = is_chosen ? at_choice[j] : last[j];
    c.significant = is_chosen;
    if (s.rss > 0.0) {
      c.f_stat = s.f_stat;
      c.p_value = s.p;
      c.p_adjusted = s.p_adj;
      c.delta_bic = s.dbic;
    } else {
      c.f_stat = 0.0;
      c.p_value = c.p_adjusted = 1.0;
      c.delta_bic = 0.0;
    }
    c.score = c.delta_bic;
  }
  // Ranking: the chosen in the order chosen, then the rest by the same statistic.
  std::vector<int> order(D.candidates.size());
  for (std::size_t j = 0; j < order.size(); ++j) order[j] = static_cast<int>(j);
  auto pos = [&](int j) {
    const auto it = std::find(chosen.begin(), chosen.end(), j);
    return it == chosen.end() ? static_cast<int>(chosen.size()) : static_cast<int>(it - chosen.begin());
  };
  std::stable_sort(order.begin(), order.end(), [&](int a, int b) {
    const int pa = pos(a), pb = pos(b);
    if (pa != pb) return pa < pb;
    const CandidateResult &ca = D.candidates[static_cast<std::size_t>(a)], &cb = D.candidates[static_cast<std::size_t>(b)];
    if (ca.identifiable != cb.identifiable) return ca.identifiable;
    return ca.score < cb.score;
  });
  std::vector<CandidateResult> sorted;
  for (int j : order) sorted.push_back(std::move(D.candidates[static_cast<std::size_t>(j)]));
  D.candidates = std::move(sorted);
  const int n_chosen = static_cast<int>(chosen.size());
  D.verdict = n_chosen > 0 ? 0 : -1;
  D.also.clear();
  for (int j = 1; j < n_chosen; ++j) D.also.push_back(j);

  // The residual after everything chosen, and what each chosen effect contributes to it.
  const JointFit final_fit = E.fit(XS, base_in);
  D.residual_final = n_chosen > 0 ? final_fit.residual : E.base_fit().residual;
  {
    Eigen::Index at = 0;
    for (int j = 0; j < n_chosen; ++j) {
      CandidateResult& c = D.candidates[static_cast<std::size_t>(j)];
      if (c.effect == "inertia_error") {
        Eigen::VectorXd db = final_fit.base_delta;
        for (std::size_t b = 0; b < E.problem().nuisance.size(); ++b)
          if (E.problem().nuisance[b]) db(static_cast<Eigen::Index>(b)) = 0.0;
        c.fitted = E.problem().B * db;
        continue;
      }
      const Eigen::Index q = c.columns.cols();
      c.fitted = c.columns * final_fit.beta.segment(at, q);
      at += q;
    }
  }

  verdict_text_motion(D);
}

std::string implausible(const CandidateResult& c) {
  // Values no healthy machine of this size has: worth a second look before
  // they go into a model (a sign error in the log, a wrong unit, a model far off).
  if (c.params.empty()) return {};
  const double v = c.params[0].value;
  if (c.effect == "payload_mass" && v < 0.0) return "a negative payload: mass taken off the platform, or the model's masses too large";
  if (c.effect == "force_gain" && std::fabs(v) > 0.3) return "a drive gain off by more than 30 %: check the torque constant and the units of the force column";
  if (c.effect == "coulomb_friction" && v > 30.0) return "more than 30 N of dry friction (a quarter of the force limit)";
  if (c.effect == "viscous_friction" && v > 200.0) return "more than 200 N s/m of viscous friction";
  if (c.effect == "cogging" && v > 20.0) return "more than 20 N of cogging";
  if (c.effect == "actuation_delay" && v > 0.02) return "a dead time of more than 20 ms";
  return {};
}

void verdict_text_motion(Diagnosis& D) {
  const std::vector<int> found = D.found();
  if (found.empty()) {
    D.ambiguous = false;
    D.verdict_text = "none: no effect of the library explains a significant part of the residual "
                     "(RMS " + amount(D.baseline_rms, D.units) + ", noise floor about " +
                     amount(D.noise_floor, D.units) + ")";
    return;
  }
  // Ambiguity: an effect chosen that another explains as well (alternatives),
  // with the measurement that separates them where the confounding says it.
  std::vector<std::string> alts;
  D.ambiguous = false;
  for (int j : found) {
    const CandidateResult& v = D.candidates[static_cast<std::size_t>(j)];
    for (const auto& a : v.alternatives) {
      D.ambiguous = true;
      std::string how;
      for (const auto& cf : v.confounded)
        if (cf.with == a) how = " (to separate: " + cf.separate_by + ")";
      alts.push_back(v.label() + " from " + a + how);
    }
  }
  std::ostringstream os;
  os << "missing: ";
  for (std::size_t j = 0; j < found.size(); ++j) {
    const CandidateResult& v = D.candidates[static_cast<std::size_t>(found[j])];
    os << (j ? "; " : "") << v.label();
    for (const auto& a : v.alternatives) os << " or " << a;
    os << " (";
    for (std::size_t q = 0; q < v.params.size(); ++q)
      os << (q ? ", " : "") << v.params[q].name << " = " << human_value(v.params[q]);
    os << ")";
    const std::string why = implausible(v);
    if (!why.empty()) os << " [implausible: " << why << "]";
  }
  const int n_chosen = static_cast<int>(found.size());
  os << ". " << (n_chosen > 1 ? "Together they bring" : "It brings") << " the residual from "
     << amount(D.baseline_rms, D.units) << " to " << amount(Engine::rms(D.residual_final), D.units)
     << " RMS (noise floor about " << amount(D.noise_floor, D.units) << ")";
  if (D.ambiguous) {
    os << ". These data cannot tell ";
    for (std::size_t j = 0; j < alts.size(); ++j) os << (j ? "; nor " : "") << alts[j];
    os << " apart";
  }
  D.verdict_text = os.str();
}

}  // namespace cpm::ident::detail
