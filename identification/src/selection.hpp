// SPDX-License-Identifier: Apache-2.0
// Stage "selection" of a diagnosis, in its units (select.cpp; not a public
// header): the terms the forward selection may choose, where it starts for
// each kind of data, the model it has reached, and what it produces. Motion
// logs and kinematic data (ball-bar, positions) choose by this one statistic.
#pragma once

#include <functional>
#include <vector>

#include "internal.hpp"

namespace cpm::ident::detail {

// One effect the selection may choose.
struct Term {
  int candidate = -1;   // index in Diagnosis::candidates
  bool base = false;    // inertia_error: the base refit
  Eigen::MatrixXd X;    // columns (unweighted); none for the base
};

// Re-search a term's nonlinear parameter (a wavelength, a time constant) with
// the columns `others` fitted beside it: updates t.X and the candidate's
// parameters (its value, not its standard error).
using TermSearch = std::function<void(Term& t, CandidateResult& c, const Eigen::MatrixXd& others)>;

// Where the selection starts and what it may do on the way, by kind of data.
struct SelectionKind {
  // false (motion): from the model as given, nuisance fitted, the base refit
  // a term of its own. true (kinematic): from the calibrated base, refitted
  // with every model tried.
  bool base_refitted = false;
  // Alternatives are compared on what each adds to the model reached (true),
  // or on the whole fit from the model as given (false, motion).
  bool gains_beyond_state = false;
  // After each choice, every effect chosen before it is tested again on top
  // of all the others; one that no longer passes is dropped (a proxy chosen
  // first for what two effects did together).
  bool prune = false;
  // Empty: every term keeps the parameters its evaluation searched alone.
  // Otherwise each term not chosen is searched again on what the chosen leave
  // before it is tried, and each chosen one again beside every later choice.
  TermSearch research;
};

// One term fitted on top of the effects chosen so far. rss == 0: the fit
// did not lower the RSS (or its columns are in the span of the others); not tested.
struct StepFit {
  double rss = 0.0, n_eff = 0.0, p_adj = 1.0, dbic = 0.0, f_stat = 0.0, p = 1.0;
  bool ok = false;   // passes: p_adj < alpha and dbic < 0
  JointFit fit;
};

// The model the selection has reached: the effects chosen (in order), their
// columns, whether the base is refitted, its weighted RSS and parameter count,
// and the residual against which what a term adds is measured (alternatives).
struct SelectionState {
  Eigen::MatrixXd XS;
  bool base_in = false;
  double rss = 0.0;
  int k = 0;
  std::vector<int> chosen;  // candidate indices, in order
  Eigen::VectorXd reference;
  bool reference_follows = false;  // the reference is the model reached (SelectionKind::gains_beyond_state)

  SelectionState(const Engine& E, const SelectionKind& kind);
  [[nodiscard]] bool has(int candidate) const;
  void take(const Term& t, const CandidateResult& c, const StepFit& s, const Engine& E);
  // A candidate chosen by a test of its own (kinematic actuator_scale, judged
  // at the model as given): the calibrated base already holds it, so the
  // model reached here does not change.
  void take_held_by_base(int candidate) { chosen.push_back(candidate); }
};

// Everything the forward selection produces: the model reached, and per
// candidate its statistics at the step it was chosen and at the last step it was tried.
struct Selection {
  SelectionState state;
  std::vector<StepFit> at_choice, last;
  // Candidates that gave way to a plausible term the data see alike, their
  // value being one no healthy machine has: not tried again (select.cpp).
  std::vector<bool> gave_way;
  Selection(const Engine& E, const SelectionKind& kind, std::size_t n)
      : state(E, kind), at_choice(n), last(n), gave_way(n, false) {}
};

// Look-elsewhere (Bonferroni) correction of a p-value: its own search trials
// (at least 1) times the candidates in the family, at most 1.
double look_elsewhere(double p, double trials, double family);

// The statistics of a model with weighted RSS `rss` and q parameters more
// than its parent's (`rss_parent`), k fitted in all, n_eff effective rows
// (at least 10): nested F-test, corrected over `trials` x `family`; BIC
// change at the base fit's effective rows. `fit` is left empty.
StepFit step_statistics(const Engine& E, const DiagnoseOptions& opt, double rss_parent, double rss, int q, int k,
                        double n_eff, double trials, double family);

// The candidates still in play: those of the library not chosen yet.
double remaining_family(const Diagnosis& D, const SelectionState& S);

// The effects the selection may choose: those the data determine, the
// alignment and those held at zero left out; the base refit only where it adds
// something beyond the nuisance.
std::vector<Term> selection_terms(const Diagnosis& D, const Engine& E);

// Forward selection over D.candidates from where `kind` starts (their order
// kept; indices in the result are into it). Names each chosen effect's
// alternatives in D; with kind.research, the searched parameters of the
// candidates too; nothing else of D changes.
Selection forward_selection(Diagnosis& D, const Engine& E, const DiagnoseOptions& opt,
                            const SelectionKind& kind = {});

// What the selection says in D: the statistics of every column, the ranking
// (the chosen first, in order), verdict and also, residual_final and the
// contribution of each effect chosen.
void apply_selection(Diagnosis& D, const Engine& E, const Selection& sel);

}  // namespace cpm::ident::detail
