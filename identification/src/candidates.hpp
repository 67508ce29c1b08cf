// SPDX-License-Identifier: Apache-2.0
// Stage "columns" of the motion diagnosis (not a public header): every
// dynamic effect of the library fitted as a candidate on the residual of the
// base model. The library (ctl::info, control/src/effects.cpp) says what an
// effect is and what its force depends on; the table here (candidate_fitting)
// says how identification fits it. Adding an effect: its row in the library,
// its force and gradient there, and one row in the fitter table
// (candidates.cpp) naming its fitter.
#pragma once

#include <array>
#include <string>
#include <utility>
#include <vector>

#include "cpm/identification/diagnose.hpp"
#include "internal.hpp"

namespace cpm::ident::detail {

// How each axis moved in a motion log (per axis i: displacement d_i in m,
// velocity v_i in m/s, commanded force f_i in N).
struct AxisExcitation {
  Vec3 vmax = Vec3::Zero(), vmin = Vec3::Zero(), span = Vec3::Zero(), fmax = Vec3::Zero();
  // The axis moved one way only: fewer than 2 % of its moving rows (|v| > 1 mm/s)
  // go the other way (start-up and settling wobble do not count as a reversal).
  std::array<bool, 3> one_way{};
};
AxisExcitation excitation(const MotionProblem& P);

// What every fitter reads: the data, the engine of the base model, the
// effect's library row and axis, the options, and how the axes moved.
struct CandidateContext {
  const MotionProblem& P;
  const Engine& E;
  const ctl::DynamicEffectInfo& effect;
  int axis;                 // 0..2, -1 for machine-wide effects
  const DiagnoseOptions& opt;
  AxisExcitation ex;
  double vabs = 0.0;        // fastest |v| of the axis (m/s); 0 for machine-wide effects

  // This effect on this axis with parameters p (in the order of the library row).
  [[nodiscard]] ctl::DynamicEffect with(std::array<double, 4> p) const;
};

// A fitter fills the candidate's parameters, columns, fit and notes (the
// statistics come after, detail::score_candidate).
using CandidateFitter = void (*)(const CandidateContext&, CandidateResult&);

// How a candidate enters the regression, hence what it is scored against.
enum class CandidateKind {
  column,          // columns of its own, fitted with the base refitted; scored against the base refit
  base_direction,  // a direction inside the base (payload): fitted with the base as given
                   // (nuisance only), scored against the model as given
  base_refit,      // the base refit itself (inertia_error), scored against the model as given
  alignment,       // estimated with the force-to-motion alignment (align.hpp), not a candidate
};

// One row per dynamic effect type, in the order of ctl::DynamicEffectType.
struct CandidateFitting {
  ctl::DynamicEffectType type;
  CandidateKind kind;
  CandidateFitter fit;            // nullptr for kind alignment
  // Already among the alignment's own columns (alignment_linear_problem fits
  // viscous and Coulomb friction on every axis): not added again when the
  // alignment is redone with the effects found.
  bool in_alignment_columns;
  // On an axis that moved one way only its force is a steady force, what a
  // tilted plane's share of the weight is too: such data cannot name it.
  bool steady_on_one_way_axis;
  // A scale of the drive's force on its axis: on every axis, with the base
  // refitted, a scale of the whole equation (select.cpp never fits that).
  bool drive_gain;
};

// The library row of a dynamic effect's name (Error for a name outside the library).
const ctl::DynamicEffectInfo& library_row(const std::string& effect);
// The fitter row of an effect type; of a name (Error for a name outside the
// library, or for a type without its row here).
const CandidateFitting& candidate_fitting(ctl::DynamicEffectType type);
const CandidateFitting& candidate_fitting(const std::string& effect);

// The candidates of a diagnosis: every dynamic effect that is a candidate
// (or those asked for, options.effects) on every axis, in the library's order.
std::vector<std::pair<std::string, int>> candidate_list(const DiagnoseOptions& opt);
// The statistics of a fitted candidate (score_candidate) against the parent
// its kind has: the base refit for a column, the model as given for a base
// direction or the base refit itself.
void score_by_kind(CandidateResult& c, const Engine& E, double baseline_ms);

// The fitters of the table.
void fit_linear_column(const CandidateContext& ctx, CandidateResult& c);  // viscous, Coulomb, force gain
void fit_spring(const CandidateContext& ctx, CandidateResult& c);
void fit_stribeck(const CandidateContext& ctx, CandidateResult& c);
void fit_cogging(const CandidateContext& ctx, CandidateResult& c);
void fit_payload(const CandidateContext& ctx, CandidateResult& c);
void fit_base_refit(const CandidateContext& ctx, CandidateResult& c);     // inertia_error

// What the fitters share.
// Nothing fitted: the base refit's residual, every parameter undetermined.
void set_not_identifiable(const CandidateContext& ctx, CandidateResult& c, const std::string& why);
// The base parameters after the fit (changed only when it refitted the base).
void record_base_after(const CandidateContext& ctx, CandidateResult& c, const JointFit& f, bool with_base);
// A fit of columns X (values of the effect's parameters `values`, Jacobian
// `jac` at them for the standard errors) recorded in c, with its confounding
// with the base.
void record_fit(const CandidateContext& ctx, CandidateResult& c, const Eigen::MatrixXd& X, const JointFit& f,
                const Eigen::MatrixXd& jac, const std::vector<double>& values, bool with_base);

// One column fitted with the base refitted, its coefficient held within
// [lower, upper]: at a bound the column is fixed there and only the base is
// refitted (at 0 nothing is fitted).
struct BoundedFit {
  JointFit fit;             // beta: the value held
  double value = 0.0;       // the coefficient, within the bounds
  double free_value = 0.0;  // the unconstrained least-squares coefficient
  bool held = false;        // free_value was outside the bounds
};
BoundedFit fit_bounded_column(const Engine& E, const Eigen::MatrixXd& X, double lower, double upper);

// The Stribeck speed v_s (m/s) that fits best on [lo, hi], with a Coulomb
// force on the same axis free beside it (a log grid of 16 then golden-section
// refinement; a negative breakaway or Coulomb force counts as none), and the
// effective number of independent trials of that search.
double search_stribeck_speed(const CandidateContext& ctx, double lo, double hi);
double stribeck_trials(double lo, double hi);

// Power of a force periodic in the axis position, against wavenumber k
// (1/m) on the grid k_min + q dk, in the base refit's residual; each
// wavenumber's column is damped by the force filter's response at the row's
// temporal frequency |v| k.
struct Periodogram {
  double k_min = 0.0, dk = 0.0;
  std::vector<double> power;  // weighted least-squares power of a sin/cos pair
};
Periodogram cogging_periodogram(const CandidateContext& ctx, double k_min, double k_max, double dk);
// Indices of the local maxima of `power`, strongest first, at most n.
std::vector<int> periodogram_peaks(const std::vector<double>& power, std::size_t n);
// The wavelength (m) that fits best near the peaks (golden section within
// one grid step of each, within [k_min, k_max]).
double refine_cogging_wavelength(const CandidateContext& ctx, const Periodogram& pg, const std::vector<int>& peaks,
                                 double k_max);
double cogging_trials(double span, double k_min, double k_max);

}  // namespace cpm::ident::detail
