// SPDX-License-Identifier: Apache-2.0
// The fitters of the candidate table (candidates.hpp) but cogging's
// (candidate_cogging.cpp): linear one-column effects with their physical
// bounds, the spring with its rest position, Stribeck friction with its speed
// search, the payload as a base direction, inertia_error as the base refit.
#include <algorithm>
#include <cmath>

#include "candidates.hpp"
#include "effect_search.hpp"
#include "internal.hpp"

namespace cpm::ident::detail {
namespace {

// Two-stage least squares with one column: the instrument z (free of the
// residual's noise) scaled by the first-stage fit of the noisy regressor x on
// it, off the base. Least squares on the result gives <z, y> / <z, x>: the
// instrumental-variable estimate, without the attenuation that least squares
// on z alone has where z is noisier than x.
Eigen::VectorXd instrumented(const Engine& E, const Eigen::VectorXd& z, const Eigen::VectorXd& x) {
  const Eigen::VectorXd zp = E.project_off_base(z), xp = E.project_off_base(x);
  const double zz = zp.squaredNorm();
  return zz > 0.0 ? Eigen::VectorXd(z * (zp.dot(xp) / zz)) : z;
}

std::string axis_number(const CandidateContext& ctx) { return std::to_string(ctx.axis + 1); }

// The Stribeck column at speed v_s (m/s): the force per N of breakaway force.
Eigen::MatrixXd stribeck_column(const CandidateContext& ctx, double vs) {
  return hcat({ctx.P.effect_column(ctx.with({1.0, vs, 0, 0}), 0)});
}

}  // namespace

BoundedFit fit_bounded_column(const Engine& E, const Eigen::MatrixXd& X, double lower, double upper) {
  BoundedFit b;
  b.fit = E.fit(X);
  b.value = b.free_value = b.fit.beta(0);
  if (!(b.value < lower || b.value > upper)) return b;
  b.value = std::clamp(b.value, lower, upper);
  b.held = true;
  b.fit = E.fit(Eigen::MatrixXd(X.rows(), 0));
  if (b.value != 0.0) {  // a bound other than 0: the column at its bound is fixed, refit the base
    LinearProblem L = E.problem();
    L.y -= X.col(0) * b.value;
    b.fit = Engine(L).base_fit();
  }
  b.fit.beta = Eigen::VectorXd::Constant(1, b.value);
  return b;
}

void fit_linear_column(const CandidateContext& ctx, CandidateResult& c) {
  Eigen::MatrixXd X;
  if (ctx.effect.type == ctl::DynamicEffectType::force_gain) {
    if (ctx.ex.fmax[ctx.axis] < 1e-6)
      return set_not_identifiable(ctx, c, "no force was commanded on axis " + axis_number(ctx));
    X = hcat({instrumented(ctx.E, ctx.P.force_gain_column(ctx.axis), ctx.P.force_gain_column_logged(ctx.axis))});
  } else {
    if (ctx.vabs < 5e-3) return set_not_identifiable(ctx, c, "axis " + axis_number(ctx) + " does not move in these data");
    X = hcat({ctx.P.effect_column(ctx.with({1.0, 0, 0, 0}), 0)});
  }
  const ctl::EffectParameter& bound = ctx.effect.params[0];
  const BoundedFit b = fit_bounded_column(ctx.E, X, bound.lower, bound.upper);
  record_fit(ctx, c, X, b.fit, X, {b.value}, true);
  if (b.held) {
    c.params[0].at_bound = true;
    c.note = "the best fit (" + fmt(b.free_value) + ") is outside the physical range; held at " + fmt(b.value);
    c.identifiable = c.identifiable && b.value != 0.0;
  }
}

void fit_spring(const CandidateContext& ctx, CandidateResult& c) {
  if (ctx.ex.span[ctx.axis] < 1e-3)
    return set_not_identifiable(ctx, c, "axis " + axis_number(ctx) + " does not move in these data");
  const ctl::EffectParameter &stiffness = ctx.effect.params[0], &rest = ctx.effect.params[1];
  // k (d - d_ref) is linear in (k, k d_ref): the columns of a unit spring at d_ref = 0.
  const ctl::DynamicEffect unit = ctx.with({1.0, 0.0, 0, 0});
  const Eigen::MatrixXd X = hcat({ctx.P.effect_column(unit, 0), ctx.P.effect_column(unit, 1)});
  JointFit f = ctx.E.fit(X);
  double k = f.beta(0), dref = std::fabs(k) > 0.0 ? f.beta(1) / k : 1e300;
  bool held = false;
  Eigen::MatrixXd Xf = X;
  if (!(dref >= rest.lower && dref <= rest.upper)) {
    held = true;
    dref = std::clamp(dref, rest.lower, rest.upper);
    Xf = hcat({ctx.P.effect_force_column(ctx.with({1.0, dref, 0, 0}))});
    f = ctx.E.fit(Xf);
    k = f.beta(0);
  }
  k = std::clamp(k, stiffness.lower, stiffness.upper);
  const ctl::DynamicEffect fe = ctx.with({k, dref, 0, 0});
  const Eigen::MatrixXd jac = hcat({ctx.P.effect_column(fe, 0), ctx.P.effect_column(fe, 1)});
  record_fit(ctx, c, Xf, f, held ? Eigen::MatrixXd(jac.col(0)) : jac, {k, dref}, true);
  if (held) {
    c.params[1].at_bound = true;
    c.params[1].std_error = -1.0;
    c.note = "the spring's rest position is outside [-1, 1] m; held at the bound";
    // The selection fits without the base refit, where a constant force on
    // the axis is its own (on z it is the weight's E only once the base is
    // refitted): it gets the spring's whole linear pair.
    c.columns = X;
  }
}

// The speed is searched with a Coulomb force on the same axis free beside
// the bell (both at least 0): alone, a broad bell (v_s well above the true
// one) takes the Coulomb step as well and wins, and a Coulomb column beside it
// then adds nothing, so the pair was never reached (issue 26).
double search_stribeck_speed(const CandidateContext& ctx, double lo, double hi) {
  ctl::DynamicEffect coulomb;
  coulomb.type = ctl::DynamicEffectType::coulomb_friction;
  coulomb.axis = static_cast<std::int8_t>(ctx.axis);
  coulomb.param = {1.0, 0, 0, 0};
  const Eigen::VectorXd xc = ctx.P.effect_column(coulomb, 0);
  auto cost = [&](double logvs) {
    const Eigen::MatrixXd xs = stribeck_column(ctx, std::exp(logvs));
    const JointFit pair = ctx.E.fit(hcat({xc, xs.col(0)}));
    if (pair.beta(0) >= 0.0 && pair.beta(1) >= 0.0) return pair.rss;
    const JointFit f = ctx.E.fit(xs);
    return f.beta(0) >= 0.0 ? f.rss : ctx.E.rss_base();
  };
  return std::exp(grid_then_golden(cost, std::log(lo), std::log(hi), 16, 12, std::log(lo)));
}

// Speeds a factor of 3 apart give nearly independent columns.
double stribeck_trials(double lo, double hi) { return std::max(1.0, std::log(hi / lo) / std::log(3.0)); }

void fit_stribeck(const CandidateContext& ctx, CandidateResult& c) {
  const double lo = 2.0 * ctl::kSignEpsilon, hi = std::min(ctx.effect.params[1].upper, ctx.vabs);
  if (ctx.vabs < 5e-3 || hi <= lo * 1.5)
    return set_not_identifiable(ctx, c, "axis " + axis_number(ctx) + " does not move fast enough in these data");
  const double vs = search_stribeck_speed(ctx, lo, hi);
  const Eigen::MatrixXd X = stribeck_column(ctx, vs);
  JointFit f = ctx.E.fit(X);
  double fs = f.beta(0);
  const bool held = fs < 0.0;
  if (held) {
    fs = 0.0;
    f = ctx.E.base_fit();
    f.beta = Eigen::VectorXd::Zero(1);
  }
  const ctl::DynamicEffect fe = ctx.with({fs, vs, 0, 0});
  const Eigen::MatrixXd jac = hcat({ctx.P.effect_column(fe, 0), ctx.P.effect_column(fe, 1)});
  record_fit(ctx, c, X, f, held ? Eigen::MatrixXd(jac.col(0)) : jac, {fs, vs}, true);
  c.trials = stribeck_trials(lo, hi);
  if (held) {
    c.params[0].at_bound = true;
    c.identifiable = false;
    c.note = "the best fit is a negative breakaway force (unphysical); held at 0";
  }
}

// dm (q_dd - g) is Delta A = dm / 2, Delta E = dm g: one direction of the base,
// fitted with the base as the model gives it.
void fit_payload(const CandidateContext& ctx, CandidateResult& c) {
  const Engine& E = ctx.E;
  const ctl::EffectParameter& dm_bound = ctx.effect.params[0];
  c.refits_base = false;
  const Eigen::MatrixXd X = hcat({0.5 * ctx.P.base.col(0) + ctl::kGravity * ctx.P.base.col(3)});
  JointFit f = E.fit(X, false);
  double dm = f.beta(0);
  if (dm < dm_bound.lower || dm > dm_bound.upper) {
    dm = std::clamp(dm, dm_bound.lower, dm_bound.upper);
    LinearProblem L = E.problem();
    L.y -= X.col(0) * dm;
    const Engine e2(L);
    f = e2.fit(Eigen::MatrixXd(X.rows(), 0), false);
    f.beta = Eigen::VectorXd::Constant(1, dm);
    c.note = "the best fit is outside the physical range; held at " + fmt(dm) + " kg";
  }
  c.columns = X;
  c.rss = f.rss;
  c.n_eff = f.n_eff;
  c.residual_after = f.residual;
  c.fitted = X * f.beta;
  const Eigen::MatrixXd cov = E.covariance(X, f, 1, false);
  c.params.push_back({dm_bound.name, dm_bound.unit, dm, std::sqrt(std::max(0.0, cov(0, 0))), false});
  record_base_after(ctx, c, f, false);
}

// The base refit itself: the changes of A, B, C, E (the first base columns,
// in the order of the effect's parameters).
void fit_base_refit(const CandidateContext& ctx, CandidateResult& c) {
  const Engine& E = ctx.E;
  const int n = ctx.effect.n_params;
  c.refits_base = true;
  const JointFit& f = E.base_fit();
  c.columns = Eigen::MatrixXd(E.rows(), 0);
  c.rss = f.rss;
  c.n_eff = f.n_eff;
  c.residual_after = f.residual;
  c.fitted = E.problem().y - f.residual;
  const Eigen::MatrixXd cov = E.covariance(ctx.P.base.leftCols(n), f, E.base_rank(), false);
  const auto& un = E.unidentifiable_base();
  for (int j = 0; j < n; ++j) {
    const bool undet = std::find(un.begin(), un.end(), j) != un.end();
    c.params.push_back({ctx.effect.params[j].name, ctx.effect.params[j].unit, f.base_delta(j),
                        undet ? -1.0 : std::sqrt(std::max(0.0, cov(j, j))), false});
  }
  record_base_after(ctx, c, f, true);
  c.n_params = E.base_rank_beyond_nuisance();
  if (!un.empty()) {
    std::string names;
    for (int j : un) names += (names.empty() ? "" : ", ") + ctx.P.base_params[static_cast<std::size_t>(j)].name;
    c.note = "these data cannot determine " + names + " (kept at the model's value)";
  }
}

}  // namespace cpm::ident::detail
