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
#include <array>
#include <cmath>

#include "selection.hpp"

namespace cpm::ident::detail {
namespace {

// Alternatives: as good by BIC (within 6, "strong" evidence) with a signature
// alike (what either adds to the fit so far, off the nuisance: |cos| > 0.9).
constexpr double kAlternativeBic = 6.0;
constexpr double kAlternativeCos = 0.9;

// Parameters a term adds: the columns, or the effect's parameters where some
// were searched (a cogging wavelength, a Stribeck speed) and so were fitted
// too; the base refit adds the base beyond the nuisance.
int params_added(const Term& t, const CandidateResult& c, const Engine& E) {
  return t.base ? E.base_rank_beyond_nuisance() : std::max(static_cast<int>(t.X.cols()), c.n_params);
}

const Term& term_of(const std::vector<Term>& terms, int candidate) {
  return *std::find_if(terms.begin(), terms.end(), [&](const Term& t) { return t.candidate == candidate; });
}

// One term fitted on top of the state, tested against it with the
// look-elsewhere correction over `family` candidates.
StepFit step_fit(const Engine& E, const DiagnoseOptions& opt, const Term& t, const CandidateResult& c,
                 const SelectionState& S, double family) {
  StepFit s;
  s.fit = E.fit(t.base ? S.XS : hstack(S.XS, t.X), S.base_in || t.base);
  const int q = params_added(t, c, E);
  if (!s.fit.full_rank || s.fit.rss >= S.rss) return s;
  const NestedTest nt = E.nested(S.rss, s.fit.rss, q, S.k + q, std::max(s.fit.n_eff, 10.0));
  const double ne_ref = std::max(10.0, E.base_fit().n_eff);
  const double fr = E.floor_rss();
  s.rss = s.fit.rss;
  s.n_eff = s.fit.n_eff;
  s.f_stat = nt.f_stat;
  s.p = nt.p_value;
  s.p_adj = look_elsewhere(nt.p_value, c.trials, family);
  s.dbic = S.rss + fr > 0.0 ? bic_change(ne_ref, s.rss, S.rss, fr, q) : 0.0;
  s.ok = s.p_adj < opt.alpha && s.dbic < 0.0;
  return s;
}

// A drive gain on every axis with the base refitted is a scale of the whole
// equation (g F = J^T (M p_dd + G p_dot + K) is homogeneous in the three gains
// and A..E together): a fit along it shrinks the noise with the residual, and
// nothing in motion data fixes it but a mass known beforehand. Such a term is
// not tried.
bool scales_whole_equation(const Diagnosis& D, const SelectionState& S, const Term& t) {
  if (!(S.base_in || t.base)) return false;
  std::array<bool, 3> gain{};
  auto count = [&](int candidate) {
    const CandidateResult& c = D.candidates[static_cast<std::size_t>(candidate)];
    if (is_drive_gain(c.effect) && c.axis >= 0) gain[static_cast<std::size_t>(c.axis)] = true;
  };
  for (int j : S.chosen) count(j);
  count(t.candidate);
  return gain[0] && gain[1] && gain[2];
}

// Every term not chosen tried on top of the state (their statistics kept in
// sel.last); the candidate with the lowest BIC change among those that pass, or -1.
int best_next_term(const Diagnosis& D, const Engine& E, const DiagnoseOptions& opt, const std::vector<Term>& terms,
                   Selection& sel) {
  // The family: every candidate of the library on every axis that has not been
  // chosen, whether or not the data can show it (those held at a bound were
  // looked at too).
  const double remaining = static_cast<double>(D.candidates.size() - sel.state.chosen.size());
  int best = -1;
  for (const Term& t : terms) {
    if (sel.state.has(t.candidate)) continue;
    const auto j = static_cast<std::size_t>(t.candidate);
    if (scales_whole_equation(D, sel.state, t)) {
      sel.last[j] = StepFit{};
      continue;
    }
    sel.last[j] = step_fit(E, opt, t, D.candidates[j], sel.state, remaining);
    if (sel.last[j].ok && (best < 0 || sel.last[j].dbic < sel.last[static_cast<std::size_t>(best)].dbic))
      best = t.candidate;
  }
  return best;
}

// The effects that explain the data as well as the one chosen (`best`) at this step.
void name_alternatives(Diagnosis& D, const Engine& E, const std::vector<Term>& terms, const Selection& sel,
                       int best) {
  const StepFit& s = sel.last[static_cast<std::size_t>(best)];
  const Eigen::VectorXd y_off = E.project_off_nuisance(E.problem().y);
  const Eigen::VectorXd gain_best = y_off - E.project_off_nuisance(s.fit.residual);
  for (const Term& t : terms) {
    if (t.candidate == best || sel.state.has(t.candidate)) continue;
    const StepFit& o = sel.last[static_cast<std::size_t>(t.candidate)];
    if (!o.ok || o.dbic - s.dbic > kAlternativeBic) continue;
    const Eigen::VectorXd gain_o = y_off - E.project_off_nuisance(o.fit.residual);
    const double den = gain_best.norm() * gain_o.norm();
    if (den > 0.0 && std::fabs(gain_best.dot(gain_o)) / den > kAlternativeCos)
      D.candidates[static_cast<std::size_t>(best)].alternatives.push_back(
          D.candidates[static_cast<std::size_t>(t.candidate)].label());
  }
}

// The statistics every column shows: at the step an effect was chosen, or,
// for the others, on top of everything chosen.
void set_column_statistics(Diagnosis& D, const Selection& sel) {
  for (std::size_t j = 0; j < D.candidates.size(); ++j) {
    CandidateResult& c = D.candidates[j];
    if (is_alignment(c.effect)) continue;
    const bool is_chosen = sel.state.has(static_cast<int>(j));
    const StepFit& s = is_chosen ? sel.at_choice[j] : sel.last[j];
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
}

// Ranking: the chosen in the order chosen, then the rest by the same statistic;
// the verdict is the first chosen, `also` the others.
void rank_by_selection(Diagnosis& D, const std::vector<int>& chosen) {
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
}

// The residual after everything chosen, and what each chosen effect (the
// first n_chosen of the ranking, in the order of the columns) contributes to it.
void attribute_final_fit(Diagnosis& D, const Engine& E, const SelectionState& S) {
  const JointFit final_fit = E.fit(S.XS, S.base_in);
  const int n_chosen = static_cast<int>(S.chosen.size());
  D.residual_final = n_chosen > 0 ? final_fit.residual : E.base_fit().residual;
  Eigen::Index at = 0;
  for (int j = 0; j < n_chosen; ++j) {
    CandidateResult& c = D.candidates[static_cast<std::size_t>(j)];
    if (is_base_refit(c.effect)) {
      // The base change beyond the nuisance.
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

}  // namespace

double look_elsewhere(double p, double trials, double family) {
  return std::min(1.0, p * std::max(1.0, trials) * family);
}

SelectionState::SelectionState(const Engine& E) : XS(E.rows(), 0), rss(E.rss_given()), k(E.nuisance_rank()) {}

bool SelectionState::has(int candidate) const {
  return std::find(chosen.begin(), chosen.end(), candidate) != chosen.end();
}

void SelectionState::take(const Term& t, const CandidateResult& c, const StepFit& s, const Engine& E) {
  chosen.push_back(t.candidate);
  if (t.base) base_in = true;
  else XS = hstack(XS, t.X);
  k += params_added(t, c, E);
  rss = s.rss;
}

std::vector<Term> selection_terms(const Diagnosis& D, const Engine& E) {
  std::vector<Term> terms;
  for (std::size_t j = 0; j < D.candidates.size(); ++j) {
    const CandidateResult& c = D.candidates[j];
    if (!c.identifiable || is_alignment(c.effect)) continue;
    if (!c.params.empty() && c.params[0].at_bound && c.params[0].value == 0.0) continue;
    Term t;
    t.candidate = static_cast<int>(j);
    t.base = is_base_refit(c.effect);
    if (!t.base) {
      if (c.columns.cols() == 0) continue;
      t.X = c.columns;
    } else if (E.base_rank_beyond_nuisance() == 0) {
      continue;
    }
    terms.push_back(std::move(t));
  }
  return terms;
}

Selection forward_selection(Diagnosis& D, const Engine& E, const DiagnoseOptions& opt) {
  const std::vector<Term> terms = selection_terms(D, E);
  Selection sel(E, D.candidates.size());
  const int max_steps = std::max(1, opt.max_forward_steps);
  for (int step = 0; step <= max_steps; ++step) {
    const int best = best_next_term(D, E, opt, terms, sel);
    if (best < 0 || step == max_steps) break;
    name_alternatives(D, E, terms, sel, best);
    const auto j = static_cast<std::size_t>(best);
    sel.at_choice[j] = sel.last[j];
    sel.state.take(term_of(terms, best), D.candidates[j], sel.last[j], E);
  }
  return sel;
}

void apply_selection(Diagnosis& D, const Engine& E, const Selection& sel) {
  set_column_statistics(D, sel);
  rank_by_selection(D, sel.state.chosen);
  attribute_final_fit(D, E, sel.state);
}

void select_motion_effects(Diagnosis& D, const Engine& E, const DiagnoseOptions& opt) {
  apply_selection(D, E, forward_selection(D, E, opt));
  verdict_text_motion(D);
}

}  // namespace cpm::ident::detail
