// SPDX-License-Identifier: Apache-2.0
// Stage "columns" of the motion diagnosis (identification/src/candidates.hpp):
// the fitter table covers the effect library, and each fitter recovers a
// value planted in the residual of a simulated log within its standard error,
// with the physical bounds enforced. The log is simulated once, effect-free;
// each test plants its effect as the model's own filtered force column (what
// the force of that effect is after the acceleration filter), so the fitter
// sees the real rows, weights, noise and base.
#include <gtest/gtest.h>

#include <cmath>
#include <memory>
#include <numbers>
#include <random>

#include "cpm/identification/diagnose.hpp"
#include "identification/sim_data.hpp"
// The stage's own header is internal to the library (not installed).
#include "../identification/src/candidates.hpp"

namespace cpm::ident {
namespace {

using ctl::DynamicEffectType;

ctl::DynamicEffect effect(DynamicEffectType t, int axis, std::array<double, 4> p) {
  ctl::DynamicEffect e;
  e.type = t;
  e.axis = static_cast<std::int8_t>(axis);
  e.param = p;
  return e;
}

// One effect-free simulated log, prepared against the nominal model (shared by the tests).
struct Log {
  ctl::Machine nominal{ctl::MachineModel::elkady()};
  io::MotionData data;
  MotionProblem P;
  DiagnoseOptions opt;
};

const Log& clean_log() {
  static const std::unique_ptr<Log> log = [] {
    auto l = std::make_unique<Log>();
    test::SimSpec s;
    s.duration = 12.0;
    s.seed = 7;
    l->data = test::simulate(s);
    l->P = prepare_motion(l->data, l->nominal);
    return l;
  }();
  return *log;
}

// The residual of the clean log plus `planted` (N, 3 rows per kept row).
Engine engine_with(const MotionProblem& P, const Eigen::VectorXd& planted) {
  LinearProblem L = motion_linear_problem(P);
  L.y += planted;
  return Engine(std::move(L));
}

CandidateResult evaluate(const Log& g, const Engine& E, const std::string& name, int axis) {
  return evaluate_dynamic_candidate(g.P, E, g.nominal.model(), name, axis, g.opt);
}

// Every parameter within 3 standard errors of the planted value (the
// standard error determined and positive).
void expect_recovered(const CandidateResult& c, const std::vector<double>& planted) {
  SCOPED_TRACE(c.label() + ": " + c.note);
  ASSERT_EQ(c.params.size(), planted.size());
  EXPECT_TRUE(c.identifiable);
  for (std::size_t j = 0; j < planted.size(); ++j) {
    const ParamEstimate& p = c.params[j];
    EXPECT_GT(p.std_error, 0.0) << p.name;
    EXPECT_FALSE(p.at_bound) << p.name;
    EXPECT_LE(std::fabs(p.value - planted[j]), 3.0 * p.std_error)
        << p.name << " = " << p.value << " +- " << p.std_error << ", planted " << planted[j];
  }
}

TEST(CandidateTable, EveryDynamicEffectButTheDelayHasItsFitter) {
  for (int t = 0; t < ctl::kDynamicEffectTypes; ++t) {
    const auto type = static_cast<DynamicEffectType>(t);
    const ctl::DynamicEffectInfo& in = ctl::info(type);
    SCOPED_TRACE(in.name);
    const detail::CandidateFitting* row = nullptr;
    ASSERT_NO_THROW(row = &detail::candidate_fitting(type));
    EXPECT_EQ(row->type, type);
    EXPECT_EQ(&detail::candidate_fitting(std::string(in.name)), row);
    if (type == DynamicEffectType::actuation_delay) {
      EXPECT_EQ(row->kind, detail::CandidateKind::alignment);
      EXPECT_EQ(row->fit, nullptr);
    } else {
      EXPECT_NE(row->kind, detail::CandidateKind::alignment);
      EXPECT_NE(row->fit, nullptr);
    }
    // The advice that separates effects needs to know what each one depends on.
    const ctl::EffectDependence d = in.depends_on;
    EXPECT_TRUE(d.direction || d.speed || d.position || d.force);
  }
  EXPECT_THROW(detail::candidate_fitting(std::string("backlash")), Error);  // kinematic, not a force
}

TEST(CandidateTable, TheCandidateListIsEveryEffectOnEveryAxisButTheDelay) {
  int expected = 0;
  for (int t = 0; t < ctl::kDynamicEffectTypes; ++t) {
    const ctl::DynamicEffectInfo& in = ctl::info(static_cast<DynamicEffectType>(t));
    if (in.type != DynamicEffectType::actuation_delay) expected += in.per_axis ? 3 : 1;
  }
  const auto all = detail::candidate_list(DiagnoseOptions{});
  EXPECT_EQ(static_cast<int>(all.size()), expected);
  for (const auto& [name, axis] : all) EXPECT_NE(name, "actuation_delay");
  DiagnoseOptions only;
  only.effects = {"spring", "payload_mass"};
  const auto some = detail::candidate_list(only);
  ASSERT_EQ(some.size(), 4u);
  EXPECT_EQ(some[0], std::make_pair(std::string("spring"), 0));
  EXPECT_EQ(some[3], std::make_pair(std::string("payload_mass"), -1));
}

TEST(CandidateTable, TheDelayAndAxesOutsideAnEffectsReachAreRefused) {
  const Log& g = clean_log();
  const Engine E(motion_linear_problem(g.P));
  EXPECT_THROW(evaluate(g, E, "actuation_delay", -1), Error);
  EXPECT_THROW(evaluate(g, E, "payload_mass", 0), Error);
  EXPECT_THROW(evaluate(g, E, "spring", -1), Error);
  EXPECT_THROW(evaluate(g, E, "spring", 3), Error);
  EXPECT_THROW(evaluate(g, E, "backlash", 0), Error);
}

// y = beta x + base + white noise on a synthetic problem: the fit is the
// closed form <x_perp, y_perp> / |x_perp|^2 off the base; outside the bounds
// the coefficient is held at the bound and only the base is refitted.
struct Synthetic {
  LinearProblem L;
  Eigen::MatrixXd X;
};

Synthetic synthetic(double beta) {
  const int N = 400;
  std::mt19937_64 rng(3);
  std::normal_distribution<double> noise(0.0, 0.1);
  Synthetic s;
  s.L.B.resize(N, 2);
  s.X.resize(N, 1);
  s.L.y.resize(N);
  for (int r = 0; r < N; ++r) {
    const double t = r / static_cast<double>(N);
    s.L.B(r, 0) = 1.0;
    s.L.B(r, 1) = t;
    s.X(r, 0) = std::sin(7.0 * t) + 0.3 * t;
    s.L.y(r) = beta * s.X(r, 0) + 0.5 - 2.0 * t + noise(rng);
  }
  s.L.base_names = {"c0", "c1"};
  s.L.base_units = {"N", "N"};
  s.L.base_values = {0.0, 0.0};
  s.L.nuisance = {0, 0};
  s.L.w = Eigen::VectorXd::Ones(N);
  s.L.series.assign(N, 0);
  return s;
}

TEST(BoundedColumn, WithinItsBoundsItIsTheLeastSquaresCoefficientOffTheBase) {
  const Synthetic s = synthetic(2.5);
  const Engine E(s.L);
  const detail::BoundedFit b = detail::fit_bounded_column(E, s.X, 0.0, 10.0);
  const Eigen::VectorXd xp = E.project_off_base(s.X).col(0);
  const Eigen::VectorXd yp = E.project_off_base(s.L.y).col(0);
  EXPECT_FALSE(b.held);
  EXPECT_NEAR(b.value, xp.dot(yp) / xp.squaredNorm(), 1e-9);
  EXPECT_EQ(b.value, b.free_value);
  EXPECT_NEAR(b.value, 2.5, 3.0 * 0.1 / xp.norm());
}

TEST(BoundedColumn, ANegativeFrictionIsHeldAtZeroAndNothingIsFitted) {
  const Synthetic s = synthetic(-1.5);
  const Engine E(s.L);
  const detail::BoundedFit b = detail::fit_bounded_column(E, s.X, 0.0, 500.0);
  EXPECT_TRUE(b.held);
  EXPECT_EQ(b.value, 0.0);
  EXPECT_NEAR(b.free_value, -1.5, 0.05);
  EXPECT_EQ(b.fit.beta(0), 0.0);
  EXPECT_LT((b.fit.residual - E.base_fit().residual).norm(), 1e-12);
}

TEST(BoundedColumn, AtABoundOtherThanZeroTheColumnIsFixedThereAndTheBaseRefitted) {
  const Synthetic s = synthetic(-2.0);
  const Engine E(s.L);
  const detail::BoundedFit b = detail::fit_bounded_column(E, s.X, -0.9, 10.0);
  EXPECT_TRUE(b.held);
  EXPECT_EQ(b.value, -0.9);
  EXPECT_EQ(b.fit.beta(0), -0.9);
  LinearProblem fixed = s.L;
  fixed.y -= -0.9 * s.X.col(0);
  EXPECT_LT((b.fit.residual - Engine(fixed).base_fit().residual).norm(), 1e-12);
}

TEST(CandidateFitters, ViscousFrictionIsRecovered) {
  const Log& g = clean_log();
  const ctl::DynamicEffect e = effect(DynamicEffectType::viscous_friction, 0, {4.0, 0, 0, 0});
  expect_recovered(evaluate(g, engine_with(g.P, g.P.effect_force_column(e)), "viscous_friction", 0), {4.0});
}

TEST(CandidateFitters, ANegativeCoulombFrictionIsHeldAtZeroAndReportedAtItsBound) {
  const Log& g = clean_log();
  const ctl::DynamicEffect e = effect(DynamicEffectType::coulomb_friction, 1, {2.0, 0, 0, 0});
  const Engine E = engine_with(g.P, -g.P.effect_force_column(e));
  const CandidateResult c = evaluate(g, E, "coulomb_friction", 1);
  ASSERT_EQ(c.params.size(), 1u);
  EXPECT_EQ(c.params[0].value, 0.0);
  EXPECT_TRUE(c.params[0].at_bound);
  EXPECT_FALSE(c.identifiable);
  EXPECT_NE(c.note.find("held at 0"), std::string::npos) << c.note;
  EXPECT_LT((c.residual_after - E.base_fit().residual).norm(), 1e-9 * E.base_fit().residual.norm());
}

TEST(CandidateFitters, TheForceGainIsRecoveredThroughItsInstrument) {
  const Log& g = clean_log();
  expect_recovered(evaluate(g, engine_with(g.P, 0.03 * g.P.force_gain_column_logged(2)), "force_gain", 2), {0.03});
}

TEST(CandidateFitters, ASpringsStiffnessAndRestPositionAreRecovered) {
  const Log& g = clean_log();
  const ctl::DynamicEffect e = effect(DynamicEffectType::spring, 1, {60.0, 0.35, 0, 0});
  expect_recovered(evaluate(g, engine_with(g.P, g.P.effect_force_column(e)), "spring", 1), {60.0, 0.35});
}

TEST(CandidateFitters, ASpringRestingBeyondAMetreIsHeldAtTheBound) {
  const Log& g = clean_log();
  // k (d - d_ref) with d_ref = 5 m: the rest position alone is out of range.
  const ctl::DynamicEffect unit = effect(DynamicEffectType::spring, 0, {1.0, 0.0, 0, 0});
  const Eigen::VectorXd planted = 20.0 * g.P.effect_column(unit, 0) + 20.0 * 5.0 * g.P.effect_column(unit, 1);
  const CandidateResult c = evaluate(g, engine_with(g.P, planted), "spring", 0);
  ASSERT_EQ(c.params.size(), 2u);
  EXPECT_EQ(c.params[1].value, 1.0);
  EXPECT_TRUE(c.params[1].at_bound);
  EXPECT_LT(c.params[1].std_error, 0.0);
  EXPECT_EQ(c.columns.cols(), 2);  // the selection gets the whole linear pair
  EXPECT_NE(c.note.find("rest position"), std::string::npos) << c.note;
}

TEST(CandidateFitters, AStribeckSpeedIsFoundByItsSearch) {
  const Log& g = clean_log();
  const ctl::DynamicEffect e = effect(DynamicEffectType::stribeck_friction, 2, {3.0, 0.02, 0, 0});
  const CandidateResult c = evaluate(g, engine_with(g.P, g.P.effect_force_column(e)), "stribeck_friction", 2);
  expect_recovered(c, {3.0, 0.02});
  EXPECT_GT(c.trials, 1.0);
}

TEST(CandidateFitters, ANegativeBreakawayForceIsHeldAtZero) {
  const Log& g = clean_log();
  const ctl::DynamicEffect e = effect(DynamicEffectType::stribeck_friction, 0, {3.0, 0.02, 0, 0});
  const CandidateResult c = evaluate(g, engine_with(g.P, -g.P.effect_force_column(e)), "stribeck_friction", 0);
  ASSERT_EQ(c.params.size(), 2u);
  EXPECT_EQ(c.params[0].value, 0.0);
  EXPECT_TRUE(c.params[0].at_bound);
  EXPECT_FALSE(c.identifiable);
}

TEST(CandidateFitters, ACoggingWavelengthIsTheStrongestPeakAndIsRefinedToItsValue) {
  const Log& g = clean_log();
  const double lambda = 0.012;
  const ctl::DynamicEffect e = effect(DynamicEffectType::cogging, 0, {0.8, lambda, 0.5, 0});
  const Engine E = engine_with(g.P, g.P.effect_force_column(e));
  const detail::AxisExcitation ex = detail::excitation(g.P);
  const detail::CandidateContext ctx{g.P, E, ctl::info(DynamicEffectType::cogging), 0, g.opt, ex, 0.5};
  const double kmin = 1.0 / 0.1, kmax = 1.0 / 0.002, dk = 1.0 / (4.0 * ex.span[0]);
  const detail::Periodogram pg = detail::cogging_periodogram(ctx, kmin, kmax, dk);
  const std::vector<int> peaks = detail::periodogram_peaks(pg.power, 3);
  ASSERT_FALSE(peaks.empty());
  EXPECT_LE(std::fabs(pg.k_min + peaks[0] * pg.dk - 1.0 / lambda), pg.dk);
  EXPECT_NEAR(detail::refine_cogging_wavelength(ctx, pg, peaks, kmax), lambda, 0.01 * lambda);

  CandidateResult c = evaluate(g, E, "cogging", 0);
  ASSERT_EQ(c.params.size(), 3u);
  c.params[2].value = std::remainder(c.params[2].value, 2.0 * std::numbers::pi);  // phase modulo a turn
  expect_recovered(c, {0.8, lambda, 0.5});
  EXPECT_GT(c.trials, 1.0);
}

TEST(CandidateFitters, PeaksAreLocalMaximaStrongestFirst) {
  const std::vector<double> power = {1, 3, 2, 5, 4, 4, 0};
  EXPECT_EQ(detail::periodogram_peaks(power, 3), (std::vector<int>{3, 5, 1}));
  EXPECT_EQ(detail::periodogram_peaks(power, 2), (std::vector<int>{3, 5}));
  EXPECT_TRUE(detail::periodogram_peaks({}, 3).empty());
}

TEST(CandidateFitters, SearchTrialsCountIndependentColumns) {
  EXPECT_NEAR(detail::stribeck_trials(0.002, 0.162), 4.0, 1e-12);  // 3^4 = 81
  EXPECT_EQ(detail::stribeck_trials(0.002, 0.003), 1.0);
  EXPECT_NEAR(detail::cogging_trials(0.2, 10.0, 510.0), 100.0, 1e-12);
}

// A payload the model carries but the machine does not: the residual is a
// negative payload, within the bound or held at it.
TEST(CandidateFitters, APayloadIsABaseDirectionWithItsLowerBound) {
  const Log& g = clean_log();
  for (double model_payload : {0.2, 1.0}) {
    SCOPED_TRACE(model_payload);
    ctl::MachineModel mm = ctl::MachineModel::elkady();
    ctl::add_effect(mm, "payload_mass", -1, {model_payload});
    const ctl::Machine with_payload(mm);
    const MotionProblem P = prepare_motion(g.data, with_payload);
    const Engine E(motion_linear_problem(P));
    const CandidateResult c = evaluate_dynamic_candidate(P, E, mm, "payload_mass", -1, g.opt);
    EXPECT_FALSE(c.refits_base);
    ASSERT_EQ(c.params.size(), 1u);
    if (model_payload < 0.3) {
      expect_recovered(c, {-model_payload});
    } else {
      EXPECT_EQ(c.params[0].value, ctl::info(DynamicEffectType::payload_mass).params[0].lower);
      EXPECT_NE(c.note.find("outside the physical range"), std::string::npos) << c.note;
    }
  }
}

}  // namespace
}  // namespace cpm::ident
