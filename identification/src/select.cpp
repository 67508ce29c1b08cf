// SPDX-License-Identifier: Apache-2.0
// Stage "selection" of a diagnosis (selection.hpp; motion logs:
// internal.hpp, select_motion_effects; kinematic data: kinematic_select.cpp).
//
// One statistic for the ranking, the verdict and the significance column:
// forward selection. At each step every effect not yet chosen (every library
// effect on every axis; on motion logs also the payload and the base refit
// itself as inertia_error) is fitted jointly with those chosen so far; the
// one with the lowest BIC change is taken when its nested F-test, with the
// look-elsewhere correction over the candidates still in play and its own
// search trials (Bonferroni over the whole library and all axes, which also
// bounds the false discoveries), stands below alpha. Motion logs start from
// the model as given and refit the base only once inertia_error has been
// chosen: what a refit would absorb (a payload, a drive gain on z, a mass
// error) is then a finding of its own instead of vanishing into it. Kinematic
// data start from the calibrated base (docs/identification.md, "Kinematic side": the base is calibration's).
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

// The term of a candidate, or nullptr (one chosen by a test of its own).
template <class Terms>
auto term_of(Terms& terms, int candidate) -> decltype(&terms[0]) {
  const auto it = std::find_if(terms.begin(), terms.end(), [&](const Term& t) { return t.candidate == candidate; });
  return it == terms.end() ? nullptr : &*it;
}

// One term fitted on top of the state, tested against it with the
// look-elsewhere correction over `family` candidates.
StepFit step_fit(const Engine& E, const DiagnoseOptions& opt, const Term& t, const CandidateResult& c,
                 const SelectionState& S, double family) {
  JointFit fit = E.fit(t.base ? S.XS : hstack(S.XS, t.X), S.base_in || t.base);
  if (!fit.full_rank || fit.rss >= S.rss) return StepFit{};
  const int q = params_added(t, c, E);
  StepFit s = step_statistics(E, opt, S.rss, fit.rss, q, S.k + q, fit.n_eff, c.trials, family);
  s.fit = std::move(fit);
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

// What a term adds to the fit so far (its gain), off the nuisance.
Eigen::VectorXd gain_off_nuisance(const Engine& E, const SelectionState& S, const StepFit& s) {
  return E.project_off_nuisance(S.reference) - E.project_off_nuisance(s.fit.residual);
}

// |cos| of two terms' gains above kAlternativeCos: the data see them alike.
bool alike(const Eigen::VectorXd& gain_a, const Eigen::VectorXd& gain_b) {
  const double den = gain_a.norm() * gain_b.norm();
  return den > 0.0 && std::fabs(gain_a.dot(gain_b)) / den > kAlternativeCos;
}

// Why the value a one-parameter term takes at this step is one no healthy
// machine has (with impossible_only, no machine at all: a negative mass;
// verdict.cpp's table), or empty. Its column is the effect at a unit
// parameter, so the coefficient is the parameter.
std::string implausible_at_step(const CandidateResult& c, const StepFit& s, bool impossible_only) {
  if (c.n_params > 1 || c.columns.cols() != 1 || s.fit.beta.size() == 0) return {};
  return implausible_value(c.effect, s.fit.beta(s.fit.beta.size() - 1), impossible_only);
}

// A best term whose value no machine has gives way to the best term on the
// same axis that passes, whose value is plausible and that the data see alike:
// a drive gain of +18 % on an axis under a plant disturbance at 250 Hz fitted
// a little worse than a reflected inertia of -0.76 kg there (the acceleration
// columns share some of the disturbance, the gain's instrument does not), and
// the negative rotor was named. Where nothing plausible is alike, the term is
// chosen and the verdict flags its value (drop_what_no_longer_adds lets it go
// first). Values that are only unusual (a gain of -90 % on a one-frequency
// circle, where structure outside the library leads) are left to the verdict.
// One that gave way is not tried again.
int possible_instead(const Diagnosis& D, const Engine& E, const std::vector<Term>& terms, Selection& sel,
                     int best) {
  const auto b = static_cast<std::size_t>(best);
  if (implausible_at_step(D.candidates[b], sel.last[b], true).empty()) return best;
  const int axis = D.candidates[b].axis;
  const Eigen::VectorXd gain_best = gain_off_nuisance(E, sel.state, sel.last[b]);
  int instead = -1;
  for (const Term& t : terms) {
    const auto j = static_cast<std::size_t>(t.candidate);
    if (t.candidate == best || sel.state.has(t.candidate) || sel.gave_way[j] || !sel.last[j].ok) continue;
    if (D.candidates[j].axis != axis || !implausible_at_step(D.candidates[j], sel.last[j], false).empty()) continue;
    if (instead >= 0 && sel.last[j].dbic >= sel.last[static_cast<std::size_t>(instead)].dbic) continue;
    if (alike(gain_best, gain_off_nuisance(E, sel.state, sel.last[j]))) instead = t.candidate;
  }
  if (instead < 0) return best;
  sel.gave_way[b] = true;
  return instead;
}

// Every term not chosen tried on top of the state (their statistics kept in
// sel.last); the candidate with the lowest BIC change among those that pass,
// or the one it gives way to (possible_instead), or -1.
int best_next_term(const Diagnosis& D, const Engine& E, const DiagnoseOptions& opt, const std::vector<Term>& terms,
                   Selection& sel) {
  // The family: every candidate of the library on every axis that has not been
  // chosen, whether or not the data can show it (those held at a bound were
  // looked at too).
  const double remaining = remaining_family(D, sel.state);
  int best = -1;
  for (const Term& t : terms) {
    const auto j = static_cast<std::size_t>(t.candidate);
    if (sel.state.has(t.candidate) || sel.gave_way[j]) continue;
    if (scales_whole_equation(D, sel.state, t)) {
      sel.last[j] = StepFit{};
      continue;
    }
    sel.last[j] = step_fit(E, opt, t, D.candidates[j], sel.state, remaining);
    if (sel.last[j].ok && (best < 0 || sel.last[j].dbic < sel.last[static_cast<std::size_t>(best)].dbic))
      best = t.candidate;
  }
  return best < 0 ? best : possible_instead(D, E, terms, sel, best);
}

// kind.research: every term not chosen searched again on what the chosen leave.
void search_on_what_is_left(Diagnosis& D, std::vector<Term>& terms, const SelectionState& S, const SelectionKind& kind) {
  if (!kind.research || S.XS.cols() == 0) return;
  for (Term& t : terms)
    if (!t.base && !S.has(t.candidate)) kind.research(t, D.candidates[static_cast<std::size_t>(t.candidate)], S.XS);
}

// The columns of the chosen terms but `except`, in the order chosen.
Eigen::MatrixXd chosen_columns(const std::vector<Term>& terms, const SelectionState& S, int except) {
  Eigen::MatrixXd X(S.XS.rows(), 0);
  for (int j : S.chosen)
    if (const Term* t = term_of(terms, j); j != except && t && !t->base) X = hstack(X, t->X);
  return X;
}

// kind.research: each term chosen before the last searched again beside all
// the others (a wavelength found on a residual that held the effect chosen
// later may be an alias), and the state refitted with what they became.
void search_chosen_again(Diagnosis& D, const Engine& E, std::vector<Term>& terms, SelectionState& S,
                         const SelectionKind& kind) {
  if (!kind.research || S.chosen.size() < 2) return;
  for (std::size_t m = 0; m + 1 < S.chosen.size(); ++m) {
    const int j = S.chosen[m];
    if (Term* t = term_of(terms, j); t && !t->base)
      kind.research(*t, D.candidates[static_cast<std::size_t>(j)], chosen_columns(terms, S, j));
  }
  S.XS = chosen_columns(terms, S, -1);
  const JointFit f = E.fit(S.XS, S.base_in);
  S.rss = f.rss;
  if (S.reference_follows) S.reference = f.residual;
}

// Term j out of the state (the others kept in the order chosen).
void drop_from_state(const Engine& E, const std::vector<Term>& terms, int j, int q, SelectionState& S) {
  S.chosen.erase(std::find(S.chosen.begin(), S.chosen.end(), j));
  if (const Term* t = term_of(terms, j); t && t->base) S.base_in = false;
  S.XS = chosen_columns(terms, S, -1);
  S.k -= q;
  const JointFit f = E.fit(S.XS, S.base_in);
  S.rss = f.rss;
  if (S.reference_follows) S.reference = f.residual;
}

// A term chosen whose value in the state's joint fit no machine has, on
// `axis`, other than `except`; or -1.
int impossible_on_axis(const Diagnosis& D, const Engine& E, const std::vector<Term>& terms, const SelectionState& S,
                       int axis, int except) {
  const JointFit f = E.fit(S.XS, S.base_in);
  Eigen::Index at = 0;
  for (int j : S.chosen) {
    const Term* t = term_of(terms, j);
    if (!t || t->base) continue;
    const Eigen::Index q = t->X.cols();
    const CandidateResult& c = D.candidates[static_cast<std::size_t>(j)];
    if (j != except && c.axis == axis && q == 1 && c.n_params <= 1 && at < f.beta.size() &&
        !implausible_value(c.effect, f.beta(at), true).empty())
      return j;
    at += q;
  }
  return -1;
}

// kind.prune: each term chosen before the last tested again on top of all the
// others, over the family it would be chosen from again; the first that no
// longer passes is dropped (its statistics those of that test), and the rest
// tested again without it. Where a term on its axis has a value no machine
// has, that one is dropped instead and set aside (possible_instead): a +16 %
// drive gain chosen first, a reflected inertia of -0.69 kg on its axis came
// next, then a spring, and the gain had been the one dropped.
void drop_what_no_longer_adds(Diagnosis& D, const Engine& E, const DiagnoseOptions& opt,
                              const std::vector<Term>& terms, Selection& sel, const SelectionKind& kind) {
  SelectionState& S = sel.state;
  // The last chosen passed its test beside the others; once one of those was
  // set aside it is tested again too.
  bool last_too = false;
  for (bool dropped = kind.prune; dropped;) {
    dropped = false;
    const double n_eff = E.fit(S.XS, S.base_in).n_eff;
    for (std::size_t m = 0; m + (last_too ? 0 : 1) < S.chosen.size() && !dropped; ++m) {
      const int j = S.chosen[m];
      const Term* t = term_of(terms, j);
      // The base refit (motion: a term of its own) is tested again too: chosen
      // first for what two effects did together (a drive gain on y and a
      // spring on z, both largely in the base's span), it may not stand beside them.
      if (!t || (t->base && kind.base_refitted)) continue;
      CandidateResult& c = D.candidates[static_cast<std::size_t>(j)];
      const int q = params_added(*t, c, E);
      const double rss_without = E.fit(chosen_columns(terms, S, j), S.base_in && !t->base).rss;
      const StepFit s = step_statistics(E, opt, rss_without, S.rss, q, S.k, n_eff, c.trials, remaining_family(D, S) + 1.0);
      if (s.ok) continue;
      if (const int i = impossible_on_axis(D, E, terms, S, c.axis, j); i >= 0) {
        CandidateResult& ci = D.candidates[static_cast<std::size_t>(i)];
        sel.at_choice[static_cast<std::size_t>(i)] = StepFit{};
        sel.gave_way[static_cast<std::size_t>(i)] = true;
        ci.alternatives.clear();
        drop_from_state(E, terms, i, params_added(*term_of(terms, i), ci, E), S);
        dropped = last_too = true;
        continue;
      }
      sel.last[static_cast<std::size_t>(j)] = s;
      sel.at_choice[static_cast<std::size_t>(j)] = StepFit{};
      c.alternatives.clear();
      drop_from_state(E, terms, j, q, S);
      dropped = true;
    }
  }
}

// The effects that explain the data as well as the one chosen (`best`) at this step.
void name_alternatives(Diagnosis& D, const Engine& E, const std::vector<Term>& terms, const Selection& sel,
                       int best) {
  const StepFit& s = sel.last[static_cast<std::size_t>(best)];
  const Eigen::VectorXd gain_best = gain_off_nuisance(E, sel.state, s);
  for (const Term& t : terms) {
    if (t.candidate == best || sel.state.has(t.candidate)) continue;
    const StepFit& o = sel.last[static_cast<std::size_t>(t.candidate)];
    if (!o.ok || o.dbic - s.dbic > kAlternativeBic) continue;
    if (alike(gain_best, gain_off_nuisance(E, sel.state, o)))
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
    if (q == 0) continue;  // chosen by a test of its own (held by the base): its fit stays
    c.fitted = c.columns * final_fit.beta.segment(at, q);
    at += q;
  }
}

}  // namespace

double look_elsewhere(double p, double trials, double family) {
  return std::min(1.0, p * std::max(1.0, trials) * family);
}

StepFit step_statistics(const Engine& E, const DiagnoseOptions& opt, double rss_parent, double rss, int q, int k,
                        double n_eff, double trials, double family) {
  StepFit s;
  const NestedTest nt = E.nested(rss_parent, rss, q, k, std::max(n_eff, 10.0));
  const double ne_ref = std::max(10.0, E.base_fit().n_eff);
  const double fr = E.floor_rss();
  s.rss = rss;
  s.n_eff = n_eff;
  s.f_stat = nt.f_stat;
  s.p = nt.p_value;
  s.p_adj = look_elsewhere(nt.p_value, trials, family);
  s.dbic = rss_parent + fr > 0.0 ? bic_change(ne_ref, rss, rss_parent, fr, q) : 0.0;
  s.ok = s.p_adj < opt.alpha && s.dbic < 0.0;
  return s;
}

double remaining_family(const Diagnosis& D, const SelectionState& S) {
  return static_cast<double>(D.candidates.size() - S.chosen.size());
}

SelectionState::SelectionState(const Engine& E, const SelectionKind& kind)
    : XS(E.rows(), 0),
      base_in(kind.base_refitted),
      rss(kind.base_refitted ? E.rss_base() : E.rss_given()),
      k(kind.base_refitted ? E.base_rank() : E.nuisance_rank()),
      reference(kind.gains_beyond_state ? E.fit(XS, base_in).residual : E.problem().y),
      reference_follows(kind.gains_beyond_state) {}

bool SelectionState::has(int candidate) const {
  return std::find(chosen.begin(), chosen.end(), candidate) != chosen.end();
}

void SelectionState::take(const Term& t, const CandidateResult& c, const StepFit& s, const Engine& E) {
  chosen.push_back(t.candidate);
  if (t.base) base_in = true;
  else XS = hstack(XS, t.X);
  k += params_added(t, c, E);
  rss = s.rss;
  if (reference_follows) reference = s.fit.residual;
}

std::vector<Term> selection_terms(const Diagnosis& D, const Engine& E) {
  std::vector<Term> terms;
  for (std::size_t j = 0; j < D.candidates.size(); ++j) {
    const CandidateResult& c = D.candidates[j];
    if (!c.identifiable || c.held_out || is_alignment(c.effect)) continue;
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

Selection forward_selection(Diagnosis& D, const Engine& E, const DiagnoseOptions& opt, const SelectionKind& kind) {
  std::vector<Term> terms = selection_terms(D, E);
  Selection sel(E, kind, D.candidates.size());
  const int max_steps = std::max(1, opt.max_forward_steps);
  for (int step = 0; step <= max_steps; ++step) {
    search_on_what_is_left(D, terms, sel.state, kind);
    const int best = best_next_term(D, E, opt, terms, sel);
    if (best < 0 || step == max_steps) break;
    name_alternatives(D, E, terms, sel, best);
    const auto j = static_cast<std::size_t>(best);
    sel.at_choice[j] = sel.last[j];
    sel.state.take(*term_of(terms, best), D.candidates[j], sel.last[j], E);
    search_chosen_again(D, E, terms, sel.state, kind);
    drop_what_no_longer_adds(D, E, opt, terms, sel, kind);
  }
  return sel;
}

void apply_selection(Diagnosis& D, const Engine& E, const Selection& sel) {
  set_column_statistics(D, sel);
  rank_by_selection(D, sel.state.chosen);
  attribute_final_fit(D, E, sel.state);
}

void select_motion_effects(Diagnosis& D, const Engine& E, const DiagnoseOptions& opt) {
  SelectionKind kind;
  kind.prune = true;
  apply_selection(D, E, forward_selection(D, E, opt, kind));
  verdict_text_motion(D);
}

}  // namespace cpm::ident::detail
