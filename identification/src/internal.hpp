// SPDX-License-Identifier: Apache-2.0
// Pieces the motion and the kinematic diagnosis share (not a public header).
#pragma once

#include <algorithm>
#include <cmath>
#include <functional>
#include <initializer_list>
#include <sstream>
#include <string>

#include "cpm/identification/diagnose.hpp"
#include "cpm/identification/stats.hpp"

namespace cpm::ident::detail {

// Columns side by side.
inline Eigen::MatrixXd hcat(std::initializer_list<Eigen::VectorXd> cols) {
  Eigen::MatrixXd X(cols.begin()->size(), static_cast<Eigen::Index>(cols.size()));
  Eigen::Index j = 0;
  for (const auto& c : cols) X.col(j++) = c;
  return X;
}

// A number for a note or a verdict ("0.123").
inline std::string fmt(double v, int prec = 3) {
  std::ostringstream os;
  os.precision(prec);
  os << v;
  return os.str();
}

// Golden-section minimum of f on [a, b] (f unimodal there, or close to it).
template <class F>
inline
double golden(F&& f, double a, double b, int iters, double& fbest) {
  const double g = (std::sqrt(5.0) - 1.0) / 2.0;
  double x1 = b - g * (b - a), x2 = a + g * (b - a);
  double f1 = f(x1), f2 = f(x2);
  for (int i = 0; i < iters; ++i) {
    if (f1 < f2) {
      b = x2; x2 = x1; f2 = f1; x1 = b - g * (b - a); f1 = f(x1);
    } else {
      a = x1; x1 = x2; f1 = f2; x2 = a + g * (b - a); f2 = f(x2);
    }
  }
  fbest = std::min(f1, f2);
  return f1 < f2 ? x1 : x2;
}


// The roles effects of the library play in the stages, said once: an effect
// that takes one of these roles is added here, not at every stage that asks.
// They read the fitter table (candidates.cpp); false for a name outside the library.
// The alignment itself (align.hpp): estimated with it, never a column of the selection.
bool is_alignment(const std::string& effect);
// The base refit itself (A, B, C, E changed): no columns of its own; choosing
// it in the selection refits the base.
bool is_base_refit(const std::string& effect);
// A base direction: its signature lies in the span of the rigid-body base, so
// it is judged against the model as given (off the nuisance only), where the
// base does not absorb the others.
bool is_base_direction(const std::string& effect);
// A scale of the drive's force on its axis (force_gain): on every axis
// together with the base refitted, a scale of the whole equation.
bool is_drive_gain(const std::string& effect);

// [a, b]: the columns of a and then of b (either may have none).
inline Eigen::MatrixXd hstack(const Eigen::MatrixXd& a, const Eigen::MatrixXd& b) {
  Eigen::MatrixXd X(a.rows() ? a.rows() : b.rows(), a.cols() + b.cols());
  if (a.cols()) X.leftCols(a.cols()) = a;
  if (b.cols()) X.rightCols(b.cols()) = b;
  return X;
}

// BIC change of a model with weighted RSS `rss` and q parameters more than
// its parent's (`rss_parent`), both with the resolution floor `floor_rss`, at
// n effective rows (< 0 favours the model).
inline double bic_change(double n, double rss, double rss_parent, double floor_rss, int q) {
  return n * std::log((rss + floor_rss) / (rss_parent + floor_rss)) + q * std::log(std::max(2.0, n));
}

// Fill the statistics of a fitted candidate: RMS after, shares explained,
// nested F-test against `rss_parent` with q parameters (k_total fitted in
// all), BIC.
void score_candidate(CandidateResult& c, const Engine& E, double rss_parent, int q, int k_total,
                     double baseline_ms);

// "0.123 N" or "1.23 µm" for a value in the diagnosis' units.
std::string amount(double v, const std::string& units);
// "(noise floor about F)" after a residual `rms` reached; when the floor's
// estimate is above it, said so instead of printed as if it were below
// ("(below the noise floor's estimate F: that estimate is too high)").
std::string floor_after(double rms, double floor, const std::string& units);

// Plot axes (report.cpp): a "nice" tick step (1, 2 or 5 times a power of
// ten) for about `n` ticks over `range`, and a tick's label with as many
// decimals as the step needs (73.190, 73.192, ... never 73.19, 73.19, 73.2).
double nice_step(double range, int n);
std::string tick_text(double v, double step);
// A parameter in the unit a person reads it in, with its standard error:
// "4.01 ± 0.03 µm", "1.00 ± 0.01 ms", "2.5 ± 0.3 %", "150 ± 20 mN".
std::string human_value(const ParamEstimate& p);

// "none: no effect of the library explains ..." with the residual and the noise floor.
std::string no_effect_text(const Diagnosis& D);

// Motion logs: forward selection by one statistic from the model as given
// (select.cpp; its units in selection.hpp): reorders the candidates, sets
// verdict, also, significance and the verdict text.
void select_motion_effects(Diagnosis& D, const Engine& E, const DiagnoseOptions& opt);
// The verdict text of a motion diagnosis from its found() effects, their
// parameters and alternatives (after the parameters are refined; verdict.cpp).
void verdict_text_motion(Diagnosis& D);
// Why a fitted value is physically implausible for this machine, or empty (verdict.cpp).
std::string implausible(const CandidateResult& c);
// The same for an effect's first parameter at `first_param` (its unit's, SI);
// with impossible_only, only values no machine at all has (a negative mass).
std::string implausible_value(const std::string& effect, double first_param, bool impossible_only = false);
// Why a fitted value is no missing effect's (implausible, or a parameter held
// at a physical bound other than 0), or empty (verdict.cpp).
std::string unphysical(const CandidateResult& c);
// Beside structure outside the library: why an effect's refit there is part
// of that structure rather than a missing effect (unphysical, or a parameter
// the data do not determine), or empty (verdict.cpp).
std::string not_missing_beside_outside(const CandidateResult& c);
// Motion logs, outside the library (outside.cpp): the strong findings of the
// structure scan in what the chosen effects leave (bump_beside_step as for
// find_motion_structure); the problem with their columns as nuisance (to
// select again beside them); the verdict text led by them.
std::vector<StructureFinding> strong_structure(const Diagnosis& D, const MotionProblem& P, const DiagnoseOptions& opt,
                                               bool bump_beside_step = false);
LinearProblem with_structure(const LinearProblem& L, const std::vector<StructureFinding>& S, const MotionProblem& P);
void lead_with_outside_library(Diagnosis& D);
// Structure in what the model as given leaves (a bump, a step, a smooth force:
// local or smooth shapes no library effect has) that explains the data better,
// by BIC, than the library effects the selection chose on its axis: the
// selection takes library effects first, and cogging plus a spring and a drive
// gain imitate a bump well enough that nothing is left for the scan after them.
std::vector<StructureFinding> structure_that_beats_library(const Diagnosis& D, const Engine& E,
                                                           const DiagnoseOptions& opt);
// Of D.outside_library, the findings that the scan still finds strong when the
// others are fitted beside the effects chosen: a large finding leaks into the
// nuisance fit (a bump on z tilts the planes) and shows as structure
// elsewhere, which is gone once the finding itself is fitted.
std::vector<StructureFinding> confirmed_outside_library(const Diagnosis& D, const Engine& E, const DiagnoseOptions& opt);

// The measurement that would separate two candidates.
using SeparateAdvice = std::function<std::string(const CandidateResult&, const CandidateResult&)>;

// Shared middle of a diagnosis: look-elsewhere correction and significance of
// each candidate alone, the ranking by it, confounding between candidates. The
// candidates must be scored already; the verdict is the selection's that
// follows (select_motion_effects; kinematic: select_kinematic_effects).
void rank_and_confound(Diagnosis& D, const Engine& E, const DiagnoseOptions& opt, const SeparateAdvice& advice);

}  // namespace cpm::ident::detail
