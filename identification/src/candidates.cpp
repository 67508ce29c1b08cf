// SPDX-License-Identifier: Apache-2.0
// Stage "columns": the fitter table and the one entry point every stage uses
// to evaluate a candidate (evaluate_dynamic_candidate), and what the fitters
// share: recording a fit, its confounding with the base, the excitation.
#include "candidates.hpp"
#include "effect_search.hpp"

#include <algorithm>
#include <cmath>
#include <sstream>

#include "internal.hpp"

namespace cpm::ident {
namespace detail {
namespace {

using T = ctl::DynamicEffectType;
using K = CandidateKind;

// How identification fits each effect of the library, in the order of
// ctl::DynamicEffectType. A new effect type without its row here fails
// candidate_fitting (and tests/identification/test_candidates.cpp).
constexpr CandidateFitting kFitting[ctl::kDynamicEffectTypes] = {
    // type                kind               fitter             in_alignment_columns  steady_on_one_way_axis  drive_gain
    {T::viscous_friction,  K::column,         fit_linear_column, true,  false, false},
    {T::coulomb_friction,  K::column,         fit_linear_column, true,  true, false},
    {T::stribeck_friction, K::column,         fit_stribeck,      false, false, false},
    {T::cogging,           K::column,         fit_cogging,       false, false, false},
    {T::spring,            K::column,         fit_spring,        false, true, false},
    {T::force_gain,        K::column,         fit_linear_column, false, true, true},
    {T::payload_mass,      K::base_direction, fit_payload,       false, false, false},
    {T::inertia_error,     K::base_refit,     fit_base_refit,    false, false, false},
    {T::actuation_delay,   K::alignment,      nullptr,           false, false, false},
    {T::actuator_inertia,  K::column,         fit_linear_column, false, false, false},
};

// Columns (nearly) in the span of the base: the candidate is the base itself in these data.
void flag_inside_base(const CandidateContext& ctx, CandidateResult& c, const Eigen::MatrixXd& X,
                      const Eigen::MatrixXd& cosines) {
  c.identifiable = false;
  std::string with;
  if (cosines.cols())
    for (Eigen::Index j = 0; j < X.cols(); ++j) with = most_alike_base(cosines, j, ctx.E.problem().base_names);
  c.note = "in these data it cannot be told apart from the base model" +
           (with.empty() ? std::string() : " (parameter " + with + ")");
}

// The base parameters each column is confounded with (R^2 with the base >= 0.81).
void add_base_confounders(const CandidateContext& ctx, CandidateResult& c, const Eigen::VectorXd& share,
                          const Eigen::MatrixXd& cosines) {
  const std::string advice = ctx.effect.depends_on.direction && ctx.axis >= 0 && ctx.ex.one_way[ctx.axis]
                                 ? "move axis " + std::to_string(ctx.axis + 1) + " in both directions"
                                 : "vary the accelerations, speeds and poses more widely";
  for (Confounder& cf : base_confounders(share, cosines, ctx.E.problem().base_names,
                                         [&](const std::string&) { return advice; }))
    c.confounded.push_back(std::move(cf));
}

bool already_in_model(const ctl::MachineModel& model, const ctl::DynamicEffectInfo& in, int axis) {
  for (const auto& e : model.effects)
    if (in.per_axis && e.type == in.type && e.axis == axis) return true;
  return false;
}

}  // namespace

const CandidateFitting& candidate_fitting(ctl::DynamicEffectType type) {
  const CandidateFitting& row = kFitting[static_cast<int>(type)];
  if (row.type != type || (row.kind != K::alignment && !row.fit))
    throw Error(std::string("identification has no candidate fitter for ") + ctl::info(type).name +
                " (the fitter table, identification/src/candidates.cpp)");
  return row;
}

const ctl::DynamicEffectInfo& library_row(const std::string& effect) {
  const auto type = ctl::dynamic_effect_from_name(effect);
  if (!type) throw Error("unknown dynamic effect '" + effect + "'");
  return ctl::info(*type);
}

const CandidateFitting& candidate_fitting(const std::string& effect) { return candidate_fitting(library_row(effect).type); }

namespace {
const CandidateFitting* fitting_or_null(const std::string& effect) {
  const auto t = ctl::dynamic_effect_from_name(effect);
  return t ? &candidate_fitting(*t) : nullptr;
}
}  // namespace

bool is_alignment(const std::string& effect) {
  const auto* f = fitting_or_null(effect);
  return f && f->kind == K::alignment;
}
bool is_base_refit(const std::string& effect) {
  const auto* f = fitting_or_null(effect);
  return f && f->kind == K::base_refit;
}
bool is_base_direction(const std::string& effect) {
  const auto* f = fitting_or_null(effect);
  return f && (f->kind == K::base_direction || f->kind == K::base_refit);
}
bool is_drive_gain(const std::string& effect) {
  const auto* f = fitting_or_null(effect);
  return f && f->drive_gain;
}

ctl::DynamicEffect CandidateContext::with(std::array<double, 4> p) const {
  ctl::DynamicEffect e;
  e.type = effect.type;
  e.axis = static_cast<std::int8_t>(axis);
  e.param = p;
  return e;
}

AxisExcitation excitation(const MotionProblem& P) {
  AxisExcitation x;
  Vec3 dmin = Vec3::Constant(1e300), dmax = Vec3::Constant(-1e300);
  x.vmin.setConstant(1e300);
  x.vmax.setConstant(-1e300);
  for (int r = 0; r < P.rows(); ++r)
    for (int i = 0; i < 3; ++i) {
      dmin[i] = std::min(dmin[i], P.d[r][i]);
      dmax[i] = std::max(dmax[i], P.d[r][i]);
      x.vmin[i] = std::min(x.vmin[i], P.v[r][i]);
      x.vmax[i] = std::max(x.vmax[i], P.v[r][i]);
      x.fmax[i] = std::max(x.fmax[i], std::fabs(P.f[r][i]));
    }
  x.span = dmax - dmin;
  for (int i = 0; i < 3; ++i) {
    int plus = 0, minus = 0;
    for (int r = 0; r < P.rows(); ++r) {
      plus += P.v[r][i] > 1e-3;
      minus += P.v[r][i] < -1e-3;
    }
    x.one_way[i] = plus + minus > 0 && std::min(plus, minus) < 0.02 * (plus + minus);
  }
  return x;
}

void set_not_identifiable(const CandidateContext& ctx, CandidateResult& c, const std::string& why) {
  c.identifiable = false;
  c.note = why;
  c.rss = ctx.E.rss_base();
  c.residual_after = ctx.E.base_fit().residual;
  c.fitted = Eigen::VectorXd::Zero(ctx.E.rows());
  for (int j = 0; j < ctx.effect.n_params; ++j)
    c.params.push_back({ctx.effect.params[j].name, ctx.effect.params[j].unit, 0.0, -1.0, false});
}

void record_base_after(const CandidateContext& ctx, CandidateResult& c, const JointFit& f, bool with_base) {
  // The engine's base may be a part of the problem's (nuisance_only,
  // without_nuisance): its columns are found by name.
  const auto& base = ctx.P.base_params;
  const std::vector<std::string>& fitted = ctx.E.problem().base_names;
  for (const BaseParameter& b : base) {
    const auto at = std::find(fitted.begin(), fitted.end(), b.name) - fitted.begin();
    const bool moved = with_base && at < f.base_delta.size();
    c.base_after.push_back({b.name, b.unit, b.value + (moved ? f.base_delta(at) : 0.0), -1.0, false});
  }
}

void record_fit(const CandidateContext& ctx, CandidateResult& c, const Eigen::MatrixXd& X, const JointFit& f,
                const Eigen::MatrixXd& jac, const std::vector<double>& values, bool with_base) {
  const Engine& E = ctx.E;
  c.columns = X;
  c.rss = f.rss;
  c.n_eff = f.n_eff;
  c.residual_after = f.residual;
  c.fitted = X.cols() ? Eigen::VectorXd(X * f.beta) : Eigen::VectorXd::Zero(E.rows());
  const Eigen::MatrixXd cov =
      E.covariance(jac, f, (with_base ? E.base_rank() : 0) + static_cast<int>(jac.cols()), with_base);
  for (int j = 0; j < ctx.effect.n_params; ++j) {
    const double se = j < cov.rows() ? std::sqrt(std::max(0.0, cov(j, j))) : -1.0;
    c.params.push_back({ctx.effect.params[j].name, ctx.effect.params[j].unit, values[static_cast<std::size_t>(j)],
                        se, false});
  }
  record_base_after(ctx, c, f, with_base);
  if (!X.cols()) return;
  const Eigen::VectorXd share = E.base_share(X);
  const Eigen::MatrixXd cosines = E.base_cosines(X);
  if (!f.full_rank || share.minCoeff() > 1.0 - 1e-6) flag_inside_base(ctx, c, X, cosines);
  add_base_confounders(ctx, c, share, cosines);
}

std::vector<std::pair<std::string, int>> candidate_list(const DiagnoseOptions& opt) {
  std::vector<std::pair<std::string, int>> todo;
  for (int t = 0; t < ctl::kDynamicEffectTypes; ++t) {
    const auto& in = ctl::info(static_cast<ctl::DynamicEffectType>(t));
    if (candidate_fitting(in.type).kind == K::alignment) continue;
    if (!opt.effects.empty() && std::find(opt.effects.begin(), opt.effects.end(), in.name) == opt.effects.end())
      continue;
    if (in.per_axis)
      for (int i = 0; i < 3; ++i) todo.emplace_back(in.name, i);
    else
      todo.emplace_back(in.name, -1);
  }
  return todo;
}

void score_by_kind(CandidateResult& c, const Engine& E, double baseline_ms) {
  const int rank = E.base_rank();
  switch (candidate_fitting(c.effect).kind) {
    case K::base_direction:
      score_candidate(c, E, E.rss_given(), c.n_params, E.nuisance_rank() + c.n_params, baseline_ms);
      break;
    case K::base_refit:
      score_candidate(c, E, E.rss_given(), E.base_rank_beyond_nuisance(), rank, baseline_ms);
      break;
    case K::column:
    case K::alignment:
      score_candidate(c, E, E.rss_base(), c.n_params, rank + c.n_params, baseline_ms);
      break;
  }
}

}  // namespace detail

CandidateResult evaluate_dynamic_candidate(const MotionProblem& P, const Engine& E,
                                           const ctl::MachineModel& model, const std::string& effect,
                                           int axis, const DiagnoseOptions& opt) {
  CandidateResult c;
  c.effect = effect;
  c.axis = axis;
  const ctl::DynamicEffectInfo& in = detail::library_row(effect);
  if (in.per_axis && (axis < 0 || axis > 2)) throw Error(effect + ": needs an axis 1..3");
  if (!in.per_axis && axis >= 0) throw Error(effect + " acts on all axes together; give no axis");
  detail::CandidateContext ctx{P, E, in, axis, opt, detail::excitation(P)};
  if (axis >= 0) ctx.vabs = std::max(std::fabs(ctx.ex.vmin[axis]), std::fabs(ctx.ex.vmax[axis]));
  if (detail::already_in_model(model, in, axis)) {
    detail::set_not_identifiable(ctx, c, "already in the model: refitted with the base parameters");
    return c;
  }
  const detail::CandidateFitting& row = detail::candidate_fitting(in.type);
  if (row.kind == detail::CandidateKind::alignment)
    throw Error(effect + " is estimated with the force-to-motion alignment, not as a candidate");
  c.n_params = in.n_params;
  row.fit(ctx, c);
  return c;
}

}  // namespace cpm::ident
