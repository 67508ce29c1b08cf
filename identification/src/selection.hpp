// Stage "selection" of the motion diagnosis, in its units (select.cpp; not a
// public header): the terms the forward selection may choose, the model it
// has reached, and what it produces.
#pragma once

#include <vector>

#include "internal.hpp"

namespace cpm::ident::detail {

// One effect the selection may choose.
struct Term {
  int candidate = -1;   // index in Diagnosis::candidates
  bool base = false;    // inertia_error: the base refit
  Eigen::MatrixXd X;    // columns (unweighted); none for the base
};

// One term fitted on top of the effects chosen so far. rss == 0: the fit
// did not lower the RSS (or its columns are in the span of the others); not tested.
struct StepFit {
  double rss = 0.0, n_eff = 0.0, p_adj = 1.0, dbic = 0.0, f_stat = 0.0, p = 1.0;
  bool ok = false;   // passes: p_adj < alpha and dbic < 0
  JointFit fit;
};

// The model the selection has reached: the effects chosen (in order), their
// columns, whether the base is refitted, its weighted RSS and parameter count.
struct SelectionState {
  Eigen::MatrixXd XS;
  bool base_in = false;
  double rss = 0.0;
  int k = 0;
  std::vector<int> chosen;  // candidate indices, in order

  explicit SelectionState(const Engine& E);
  [[nodiscard]] bool has(int candidate) const;
  void take(const Term& t, const CandidateResult& c, const StepFit& s, const Engine& E);
};

// Everything the forward selection produces: the model reached, and per
// candidate its statistics at the step it was chosen and at the last step it was tried.
struct Selection {
  SelectionState state;
  std::vector<StepFit> at_choice, last;
  Selection(const Engine& E, std::size_t n) : state(E), at_choice(n), last(n) {}
};

// Look-elsewhere (Bonferroni) correction of a p-value: its own search trials
// (at least 1) times the candidates in the family, at most 1.
double look_elsewhere(double p, double trials, double family);

// The effects the selection may choose: those the data determine, the
// alignment and those held at zero left out; the base refit only where it adds
// something beyond the nuisance.
std::vector<Term> selection_terms(const Diagnosis& D, const Engine& E);

// Forward selection from the model as given over D.candidates (their order
// kept; indices in the result are into it). Names each chosen effect's
// alternatives in D; nothing else of D changes.
Selection forward_selection(Diagnosis& D, const Engine& E, const DiagnoseOptions& opt);

// What the selection says in D: the statistics of every column, the ranking
// (the chosen first, in order), verdict and also, residual_final and the
// contribution of each effect chosen.
void apply_selection(Diagnosis& D, const Engine& E, const Selection& sel);

}  // namespace cpm::ident::detail
