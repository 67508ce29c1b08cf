// SPDX-License-Identifier: Apache-2.0
// The stages "selection", "verdict" and "structure" of the motion diagnosis,
// and cpm fit, as units: forward selection on small synthetic LinearProblems
// whose answer is known (planted columns, pure noise), the look-elsewhere
// count, the selection from the calibrated base (kinematic data), the structure scan
// on a synthetic MotionProblem with a planted bump, step or period, and
// fit_motion refitting only what it is asked to.
#include <gtest/gtest.h>

#include <cmath>
#include <numbers>
#include <random>
#include <string>
#include <vector>

#include "../../identification/src/selection.hpp"
#include "cpm/identification/fit.hpp"
#include "cpm/identification/structure.hpp"
#include "identification/sim_data.hpp"

namespace cpm::ident {
namespace {

using detail::forward_selection;
using detail::look_elsewhere;
using detail::select_motion_effects;
using detail::selection_terms;

constexpr int kRows = 400;

Eigen::MatrixXd gaussian(int rows, int cols, std::mt19937_64& rng) {
  std::normal_distribution<double> n(0.0, 1.0);
  Eigen::MatrixXd X(rows, cols);
  for (int c = 0; c < cols; ++c)
    for (int r = 0; r < rows; ++r) X(r, c) = n(rng);
  return X;
}

// A problem with white noise of sigma 1 in unit weights, one series, no
// resolution floor; base columns B, the first `nuisance` of them nuisance.
LinearProblem problem(const Eigen::VectorXd& y, const Eigen::MatrixXd& B, int nuisance) {
  LinearProblem L;
  L.y = y;
  L.B = B;
  for (int j = 0; j < B.cols(); ++j) {
    L.base_names.push_back(std::to_string(j));  // (a name built with + trips GCC 12's -Wrestrict)
    L.base_units.push_back("N");
    L.base_values.push_back(0.0);
    L.nuisance.push_back(j < nuisance ? 1 : 0);
  }
  L.w = Eigen::VectorXd::Ones(y.size());
  L.series.assign(static_cast<std::size_t>(y.size()), 0);
  return L;
}

// The constant offset: a nuisance column fitted in every model.
Eigen::MatrixXd offset_column(int rows) { return Eigen::MatrixXd::Ones(rows, 1); }

// A candidate with its columns: one amplitude parameter per column.
CandidateResult candidate(const std::string& effect, int axis, const Eigen::MatrixXd& X, double trials = 1.0) {
  CandidateResult c;
  c.effect = effect;
  c.axis = axis;
  c.columns = X;
  c.n_params = static_cast<int>(X.cols());
  c.trials = trials;
  c.params.push_back({"a", "N", 1.0, 0.1, false});
  return c;
}

// Candidates "viscous_friction[axis 1..]" on the columns of X, one each.
Diagnosis with_candidates(const Eigen::MatrixXd& X) {
  Diagnosis D;
  for (int j = 0; j < X.cols(); ++j) D.candidates.push_back(candidate("spring", j, X.col(j)));
  return D;
}

std::vector<std::string> found_labels(const Diagnosis& D) {
  std::vector<std::string> out;
  for (int j : D.found()) out.push_back(D.candidates[static_cast<std::size_t>(j)].label());
  return out;
}

TEST(LookElsewhere, IsTheSearchTrialsTimesTheFamilyCappedAtOne) {
  EXPECT_DOUBLE_EQ(look_elsewhere(1e-4, 3.0, 10.0), 3e-3);
  EXPECT_DOUBLE_EQ(look_elsewhere(1e-4, 0.2, 10.0), 1e-3);  // fewer than one trial counts as one
  EXPECT_DOUBLE_EQ(look_elsewhere(0.2, 2.0, 10.0), 1.0);
}

TEST(SelectionTerms, TheAlignmentAndEffectsHeldAtZeroAreNotChoicesAndTheBaseRefitIsOneWhereItAddsSomething) {
  std::mt19937_64 rng(3);
  const Eigen::MatrixXd X = gaussian(kRows, 3, rng);
  Eigen::MatrixXd B(kRows, 2);
  B << offset_column(kRows), gaussian(kRows, 1, rng);
  const Engine E(problem(gaussian(kRows, 1, rng).col(0), B, 1));
  Diagnosis D = with_candidates(X);
  D.candidates.push_back(candidate("actuation_delay", -1, X.col(0)));
  D.candidates[1].params[0] = {"a", "N", 0.0, 0.1, true};  // held at its bound 0
  CandidateResult base = candidate("inertia_error", -1, Eigen::MatrixXd(kRows, 0));
  D.candidates.push_back(base);
  D.candidates[2].identifiable = false;
  const std::vector<detail::Term> terms = selection_terms(D, E);
  ASSERT_EQ(terms.size(), 2u);
  EXPECT_EQ(terms[0].candidate, 0);
  EXPECT_FALSE(terms[0].base);
  EXPECT_EQ(terms[1].candidate, 4);
  EXPECT_TRUE(terms[1].base);
  // With the whole base nuisance, a refit adds nothing: not a choice.
  const Engine En(problem(E.problem().y, B, 2));
  EXPECT_EQ(selection_terms(D, En).size(), 1u);
}

TEST(ForwardSelection, PicksExactlyThePlantedColumnsStrongestFirstAndStops) {
  std::mt19937_64 rng(11);
  const Eigen::MatrixXd X = gaussian(kRows, 8, rng);
  const Eigen::VectorXd noise = gaussian(kRows, 1, rng).col(0);
  const Eigen::VectorXd y = 3.0 * X.col(5) + 1.0 * X.col(2) + noise + Eigen::VectorXd::Constant(kRows, 4.0);
  const Engine E(problem(y, offset_column(kRows), 1));
  Diagnosis D = with_candidates(X);
  const detail::Selection sel = forward_selection(D, E, {});
  EXPECT_EQ(sel.state.chosen, (std::vector<int>{5, 2}));
  EXPECT_FALSE(sel.state.base_in);
  EXPECT_EQ(sel.state.XS.cols(), 2);
  // The state's RSS is that of the noise less what two columns and the offset take.
  EXPECT_NEAR(sel.state.rss / kRows, 1.0, 0.15);
  for (int j : {5, 2}) {
    EXPECT_TRUE(sel.at_choice[static_cast<std::size_t>(j)].ok);
    EXPECT_LT(sel.at_choice[static_cast<std::size_t>(j)].p_adj, 1e-6);
  }
  // The others were tried on top of both and failed.
  for (int j : {0, 1, 3, 4, 6, 7}) EXPECT_FALSE(sel.last[static_cast<std::size_t>(j)].ok) << j;
}

TEST(ForwardSelection, TheDiagnosisRanksByItAndAttributesTheFitToEachEffectChosen) {
  std::mt19937_64 rng(12);
  const Eigen::MatrixXd X = gaussian(kRows, 6, rng);
  const Eigen::VectorXd noise = gaussian(kRows, 1, rng).col(0);
  const Eigen::VectorXd y = 2.0 * X.col(1) - 1.0 * X.col(4) + noise;
  const Engine E(problem(y, offset_column(kRows), 1));
  Diagnosis D = with_candidates(X);
  select_motion_effects(D, E, {});
  EXPECT_EQ(found_labels(D), (std::vector<std::string>{"spring[axis 2]", "spring[axis 5]"}));
  EXPECT_EQ(D.verdict, 0);
  EXPECT_EQ(D.also, (std::vector<int>{1}));
  // The significance column is "chosen"; the ranking is the order chosen.
  for (std::size_t j = 0; j < D.candidates.size(); ++j) EXPECT_EQ(D.candidates[j].significant, j < 2) << j;
  // Each chosen effect's contribution is its column times its fitted amplitude
  // (within a few standard errors, 1/sqrt(400) = 0.05).
  const double a1 = D.candidates[0].fitted.dot(X.col(1)) / X.col(1).squaredNorm();
  const double a4 = D.candidates[1].fitted.dot(X.col(4)) / X.col(4).squaredNorm();
  EXPECT_NEAR(a1, 2.0, 0.2);
  EXPECT_NEAR(a4, -1.0, 0.2);
  EXPECT_NEAR(Engine::rms(D.residual_final), 1.0, 0.1);
  EXPECT_EQ(D.verdict_text.rfind("missing: spring[axis 2]", 0), 0u) << D.verdict_text;
  EXPECT_NE(D.verdict_text.find("Together they bring"), std::string::npos) << D.verdict_text;
}

TEST(ForwardSelection, ACandidateThatIsNoiseIsChosenNoMoreOftenThanAlphaOverManySeeds) {
  // Ten columns of noise against a residual of noise: the Bonferroni
  // correction over the family bounds the seeds where anything is chosen by
  // alpha (0.01): about 3 of 300 at most, 8 is 3 sigma above that.
  int seeds_with_a_choice = 0;
  for (std::uint64_t seed = 1; seed <= 300; ++seed) {
    std::mt19937_64 rng(seed);
    const Eigen::MatrixXd X = gaussian(kRows, 10, rng);
    const Engine E(problem(gaussian(kRows, 1, rng).col(0), offset_column(kRows), 1));
    Diagnosis D = with_candidates(X);
    seeds_with_a_choice += forward_selection(D, E, {}).state.chosen.empty() ? 0 : 1;
  }
  EXPECT_LE(seeds_with_a_choice, 8);
}

TEST(ForwardSelection, TheBonferroniCountIsTheCandidatesStillInPlayTimesTheirOwnTrials) {
  std::mt19937_64 rng(21);
  const Eigen::MatrixXd X = gaussian(kRows, 5, rng);
  const Eigen::VectorXd y = 2.0 * X.col(0) + gaussian(kRows, 1, rng).col(0);
  const Engine E(problem(y, offset_column(kRows), 1));
  Diagnosis D = with_candidates(X);
  const std::vector<double> trials = {1.0, 3.0, 7.5, 1.0, 40.0};
  for (std::size_t j = 0; j < trials.size(); ++j) D.candidates[j].trials = trials[j];
  // Candidates the data cannot show are in the family too.
  D.candidates.push_back(candidate("cogging", 0, X.col(1)));
  D.candidates.back().identifiable = false;
  const detail::Selection sel = forward_selection(D, E, {});
  ASSERT_EQ(sel.state.chosen, (std::vector<int>{0}));
  const double family_first = 6.0, family_after = 5.0;  // all six; then all but the one chosen
  const detail::StepFit& s0 = sel.at_choice[0];
  EXPECT_DOUBLE_EQ(s0.p_adj, std::min(1.0, s0.p * trials[0] * family_first));
  for (std::size_t j = 1; j < trials.size(); ++j) {
    const detail::StepFit& s = sel.last[j];
    ASSERT_GT(s.rss, 0.0) << j;
    EXPECT_DOUBLE_EQ(s.p_adj, std::min(1.0, s.p * trials[j] * family_after)) << j;
  }
}

TEST(ForwardSelection, TheBaseRefitIsAChoiceOfItsOwnAndIsAttributedTheBaseChange) {
  std::mt19937_64 rng(31);
  const Eigen::MatrixXd X = gaussian(kRows, 3, rng);
  const Eigen::MatrixXd rigid = gaussian(kRows, 1, rng);  // a base direction the model has wrong
  Eigen::MatrixXd B(kRows, 2);
  B << offset_column(kRows), rigid;
  const Eigen::VectorXd y = 1.5 * rigid.col(0) + gaussian(kRows, 1, rng).col(0);
  const Engine E(problem(y, B, 1));
  Diagnosis D = with_candidates(X);
  D.candidates.push_back(candidate("inertia_error", -1, Eigen::MatrixXd(kRows, 0)));
  D.candidates.back().n_params = 4;
  select_motion_effects(D, E, {});
  ASSERT_EQ(found_labels(D), (std::vector<std::string>{"inertia_error"}));
  const Eigen::VectorXd& f = D.candidates[0].fitted;
  EXPECT_NEAR(f.dot(rigid.col(0)) / rigid.col(0).squaredNorm(), 1.5, 0.15);
}

TEST(ForwardSelection, TwoEffectsWithTheSameSignatureAreNamedAsAlternatives) {
  std::mt19937_64 rng(41);
  Eigen::MatrixXd X = gaussian(kRows, 3, rng);
  X.col(1) = X.col(0) + 0.02 * gaussian(kRows, 1, rng).col(0);  // alike to |cos| 0.9998
  const Eigen::VectorXd y = 2.0 * X.col(0) + gaussian(kRows, 1, rng).col(0);
  const Engine E(problem(y, offset_column(kRows), 1));
  Diagnosis D = with_candidates(X);
  select_motion_effects(D, E, {});
  ASSERT_EQ(D.found().size(), 1u) << D.verdict_text;
  const CandidateResult& v = D.candidates[0];
  ASSERT_EQ(v.alternatives.size(), 1u);
  EXPECT_EQ(v.alternatives[0], v.label() == "spring[axis 1]" ? "spring[axis 2]" : "spring[axis 1]");
  EXPECT_TRUE(D.ambiguous);
  EXPECT_NE(D.verdict_text.find("cannot tell"), std::string::npos) << D.verdict_text;
}

TEST(Verdict, NothingChosenSaysNoneWithTheResidualAndTheNoiseFloor) {
  Diagnosis D;
  D.baseline_rms = 0.5;
  D.noise_floor = 0.25;
  D.ambiguous = true;
  detail::verdict_text_motion(D);
  EXPECT_FALSE(D.ambiguous);
  EXPECT_EQ(D.verdict_text.rfind("none: ", 0), 0u);
  EXPECT_NE(D.verdict_text.find("RMS 0.5 N"), std::string::npos) << D.verdict_text;
  EXPECT_NE(D.verdict_text.find("about 0.25 N"), std::string::npos) << D.verdict_text;
}

TEST(Verdict, ImplausibleValuesAreNamedPerEffectAndOrdinaryOnesAreNot) {
  CandidateResult c = candidate("payload_mass", -1, Eigen::MatrixXd());
  c.params[0].value = -0.1;
  EXPECT_NE(detail::implausible(c).find("negative payload"), std::string::npos);
  c.params[0].value = 0.1;
  EXPECT_TRUE(detail::implausible(c).empty());
  c.effect = "force_gain";
  c.params[0].value = -0.35;
  EXPECT_FALSE(detail::implausible(c).empty());
  c.effect = "spring";
  c.params[0].value = 1e6;
  EXPECT_TRUE(detail::implausible(c).empty());  // no bound said for it
}

// Kinematic data start the selection from the calibrated base: a smooth
// effect (a drift in file order) left in the residual makes the lag-1
// correlation of every other candidate's residual high, so a second effect
// judged alone is not significant (its effective sample size collapses);
// chosen beside the drift it is. The state starts with the base refitted.
TEST(ForwardSelection, FromTheCalibratedBaseAnEffectHiddenAloneBehindASmoothOneIsChosenBesideIt) {
  std::mt19937_64 rng(51);
  Eigen::MatrixXd X(kRows, 3);
  for (int r = 0; r < kRows; ++r) X(r, 0) = 1.0 - std::exp(-3.0 * r / kRows);  // the drift
  X.rightCols(2) = gaussian(kRows, 2, rng);
  const Eigen::VectorXd y = 20.0 * X.col(0) + 0.5 * X.col(1) + gaussian(kRows, 1, rng).col(0);
  const Engine E(problem(y, offset_column(kRows), 0));
  Diagnosis D = with_candidates(X);
  // Alone (with the base), the second column's residual holds the drift.
  const JointFit alone = E.fit(X.col(1));
  const NestedTest t = E.nested(E.rss_base(), alone.rss, 1, E.base_rank() + 1, alone.n_eff);
  EXPECT_LT(alone.n_eff, 0.1 * kRows);
  EXPECT_GT(look_elsewhere(t.p_value, 1.0, 3.0), 0.01);
  detail::SelectionKind calibrated;
  calibrated.base_refitted = true;
  calibrated.gains_beyond_state = true;
  const detail::SelectionState start(E, calibrated);
  EXPECT_TRUE(start.base_in);
  EXPECT_EQ(start.rss, E.rss_base());
  EXPECT_EQ(start.k, E.base_rank());
  const detail::Selection sel = forward_selection(D, E, {}, calibrated);
  EXPECT_EQ(sel.state.chosen, (std::vector<int>{0, 1}));
  EXPECT_NEAR(sel.state.rss / kRows, 1.0, 0.15);
  EXPECT_FALSE(sel.last[2].ok);
}

// A searched parameter is searched again beside what is chosen: each term not
// chosen before it is tried, each chosen one beside every later choice, with
// the columns of all the others.
TEST(ForwardSelection, AResearchSeesTheColumnsOfTheEffectsChosenBesideIt) {
  std::mt19937_64 rng(52);
  const Eigen::MatrixXd X = gaussian(kRows, 3, rng);
  const Eigen::VectorXd y = 3.0 * X.col(0) + 2.0 * X.col(1) + gaussian(kRows, 1, rng).col(0);
  const Engine E(problem(y, offset_column(kRows), 1));
  Diagnosis D = with_candidates(X);
  std::vector<std::pair<int, Eigen::Index>> calls;  // candidate, columns beside it
  detail::SelectionKind kind;
  kind.research = [&](detail::Term& term, CandidateResult&, const Eigen::MatrixXd& others) {
    calls.emplace_back(term.candidate, others.cols());
  };
  const detail::Selection sel = forward_selection(D, E, {}, kind);
  ASSERT_EQ(sel.state.chosen, (std::vector<int>{0, 1}));
  // Step 2: the two not chosen beside the first; the first again beside the
  // second once it is chosen; step 3: the last beside both.
  const std::vector<std::pair<int, Eigen::Index>> expected = {{1, 1}, {2, 1}, {0, 1}, {2, 2}};
  EXPECT_EQ(calls, expected);
}

// A synthetic motion problem: every axis sweeps its stroke back and forth
// (a triangle wave, period 8 s), rows every 10 ms; the residual is white
// noise of 1 N plus what the test plants.
struct Sweep {
  MotionProblem P;
  Eigen::VectorXd residual;
};

Sweep sweep(std::uint64_t seed, int rows = 3000) {
  Sweep s;
  std::mt19937_64 rng(seed);
  std::normal_distribution<double> n(0.0, 1.0);
  const double stroke = 0.3, period = 8.0;
  s.residual.resize(3 * rows);
  for (int r = 0; r < rows; ++r) {
    const double t = 0.01 * r;
    s.P.sample.push_back(r);
    s.P.t.push_back(t);
    Vec3 d, v;
    for (int i = 0; i < 3; ++i) {
      const double ph = std::fmod(t / period + 0.17 * i, 1.0);
      d[i] = ph < 0.5 ? 2.0 * ph * stroke : 2.0 * (1.0 - ph) * stroke;
      v[i] = (ph < 0.5 ? 2.0 : -2.0) * stroke / period;
    }
    s.P.d.push_back(d);
    s.P.v.push_back(v);
    for (int i = 0; i < 3; ++i) s.residual(3 * r + i) = n(rng);
  }
  return s;
}

const Vec3 kUnitNoise = Vec3::Ones();

const StructureFinding* first_of(const std::vector<StructureFinding>& out, const std::string& kind, int axis) {
  for (const auto& f : out)
    if (f.kind == kind && f.axis == axis) return &f;
  return nullptr;
}

std::string texts(const std::vector<StructureFinding>& out) {
  std::string s;
  for (const auto& f : out) s += f.text + "\n";
  return s;
}

TEST(StructureScan, NoiseAloneReportsNothing) {
  for (std::uint64_t seed = 1; seed <= 10; ++seed) {
    const Sweep s = sweep(seed);
    const auto out = find_motion_structure(s.P, s.residual, kUnitNoise);
    EXPECT_TRUE(out.empty()) << seed << ": " << texts(out);
  }
}

TEST(StructureScan, FindsAPlantedBumpAtItsLocation) {
  Sweep s = sweep(61);
  // 1.5 N over d3 in [140, 160] mm: a bin of the scan (a twentieth of the
  // rows, 15 mm here) two thirds inside it stands out by 1 N, 12 standard errors.
  for (int r = 0; r < s.P.rows(); ++r)
    if (s.P.d[r][2] > 0.14 && s.P.d[r][2] < 0.16) s.residual(3 * r + 2) += 1.5;
  const auto out = find_motion_structure(s.P, s.residual, kUnitNoise);
  const StructureFinding* f = first_of(out, "bump", 2);
  ASSERT_NE(f, nullptr) << texts(out);
  EXPECT_EQ(f->coordinate, "d3");
  EXPECT_GT(f->location, 0.14);
  EXPECT_LT(f->location, 0.16);
  EXPECT_NEAR(f->size, 1.0, 0.3);
  EXPECT_GT(f->z, 6.0);
  EXPECT_LE(f->lo, f->location);
  EXPECT_GE(f->hi, f->location);
  EXPECT_EQ(first_of(out, "step", 2), nullptr) << texts(out);
  for (int i : {0, 1}) EXPECT_EQ(first_of(out, "bump", i), nullptr) << texts(out);
}

TEST(StructureScan, FindsAPlantedStepAtItsLocationWithoutABumpBesideIt) {
  Sweep s = sweep(62);
  for (int r = 0; r < s.P.rows(); ++r)
    if (s.P.d[r][0] > 0.2) s.residual(3 * r) += 0.5;
  const auto out = find_motion_structure(s.P, s.residual, kUnitNoise);
  const StructureFinding* f = first_of(out, "step", 0);
  ASSERT_NE(f, nullptr) << texts(out);
  EXPECT_NEAR(f->location, 0.2, 0.01);
  EXPECT_NEAR(f->size, 0.5, 0.15);
  EXPECT_EQ(first_of(out, "bump", 0), nullptr) << texts(out);
}

TEST(StructureScan, FindsAForcePeriodicInPositionAtItsWavelength) {
  Sweep s = sweep(63);
  const double lambda = 0.012;  // m
  for (int r = 0; r < s.P.rows(); ++r)
    s.residual(3 * r + 1) += 0.5 * std::sin(2.0 * std::numbers::pi * s.P.d[r][1] / lambda);
  const auto out = find_motion_structure(s.P, s.residual, kUnitNoise);
  const StructureFinding* f = nullptr;
  for (const auto& g : out)
    if (g.kind == "periodic" && g.coordinate == "d2") f = &g;
  ASSERT_NE(f, nullptr) << texts(out);
  EXPECT_EQ(f->axis, 1);
  EXPECT_NEAR(f->location, lambda, 0.0005);
  EXPECT_NEAR(f->size, 0.5, 0.1);
}

TEST(StructureScan, FindsADirectionDependentForce) {
  Sweep s = sweep(64);
  for (int r = 0; r < s.P.rows(); ++r) s.residual(3 * r + 2) += s.P.v[r][2] > 0.0 ? 0.3 : -0.3;
  const auto out = find_motion_structure(s.P, s.residual, kUnitNoise);
  const StructureFinding* f = first_of(out, "direction", 2);
  ASSERT_NE(f, nullptr) << texts(out);
  EXPECT_NEAR(f->size, 0.6, 0.15);
  for (int i : {0, 1}) EXPECT_EQ(first_of(out, "direction", i), nullptr) << texts(out);
}

// cpm fit refits what it is asked for and nothing else: an effect of the
// model not asked for keeps its value, the base stays as the model says,
// one already in the model that is asked for is refitted from scratch.
TEST(FitMotion, RefitsOnlyWhatIsAsked) {
  test::SimSpec s;
  s.duration = 12.0;
  s.seed = 71;
  s.base_errors = false;
  s.effects = {{"coulomb_friction", 1, {2.0}}, {"viscous_friction", 0, {20.0}}};
  const io::MotionData log = test::simulate(s);
  ctl::MachineModel given = ctl::MachineModel::elkady();
  ctl::add_effect(given, "viscous_friction", 0, {20.0});
  ctl::add_effect(given, "spring", 2, {5.0, 0.2});
  const FitResult F = fit_motion(log, given, {parse_fit_request("coulomb_friction:2")}, {}, nullptr, false);
  ASSERT_EQ(F.effects.size(), 1u);
  EXPECT_EQ(F.effects[0].label(), "coulomb_friction[axis 2]");
  EXPECT_NEAR(F.effects[0].params[0].value, 2.0, 0.2);
  EXPECT_FALSE(F.base_refitted);
  EXPECT_FALSE(F.delay.has_value());
  EXPECT_TRUE(F.notes.empty() || F.notes[0].find("was in the model") == std::string::npos);
  for (const auto& p : F.fitted) EXPECT_EQ(p.name.rfind("effects.coulomb_friction.axis2.", 0), 0u) << p.name;
  // The model: what was given, and the effect fitted.
  ASSERT_EQ(F.model.effects.size(), 3u);
  int seen = 0;
  for (const auto& e : F.model.effects) {
    if (e.label() == "viscous_friction[axis 1]") { EXPECT_EQ(e.param[0], 20.0); ++seen; }
    if (e.label() == "spring[axis 3]") { EXPECT_EQ(e.param[0], 5.0); EXPECT_EQ(e.param[1], 0.2); ++seen; }
    if (e.label() == "coulomb_friction[axis 2]") { EXPECT_EQ(e.param[0], F.effects[0].params[0].value); ++seen; }
  }
  EXPECT_EQ(seen, 3);
  EXPECT_LT(F.on_fit.after, F.on_fit.before);
  // Asked for again, the viscous friction in the model is refitted, not added twice.
  const FitResult G = fit_motion(log, given, {parse_fit_request("viscous_friction:1")}, {}, nullptr, false);
  int viscous = 0;
  for (const auto& e : G.model.effects) viscous += e.label() == "viscous_friction[axis 1]";
  EXPECT_EQ(viscous, 1);
  ASSERT_FALSE(G.notes.empty());
  EXPECT_NE(G.notes[0].find("viscous_friction[axis 1] was in the model"), std::string::npos) << G.notes[0];
}

}  // namespace
}  // namespace cpm::ident
