// SPDX-License-Identifier: Apache-2.0
// The stages of the kinematic diagnosis as units (kinematic_stages.hpp): the
// effect table covers every kinematic effect, an effect's columns against
// their closed form, the nonlinear searches recover planted values on
// synthetic data, the values of a joint fit, the refusals, the structure scan
// and the selection stage on simulated ball-bar data.
#include <gtest/gtest.h>

#include <cmath>
#include <numbers>
#include <random>

#include "cpm/identification/kinematic_stages.hpp"
#include "kin_data.hpp"

namespace cpm::ident {
namespace {

constexpr double kTwoPi = 2.0 * std::numbers::pi;

// A synthetic problem of n samples, one residual row each (as a ball-bar):
// readings spread over [0.05, 0.25] m on every axis, both directions, one
// sample a second; a sensitivity that varies from row to row; one base
// column (a constant offset of the residual). No forward kinematics is
// involved: the effects that act through the effective displacement only.
KinematicProblem synthetic(int n, std::uint64_t seed = 3) {
  KinematicProblem P;
  P.kind = "ballbar";
  P.data_file = "synthetic.csv";
  P.per_sample = 1;
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u(0.05, 0.25);
  P.d.resize(static_cast<std::size_t>(n));
  P.inputs.resize(static_cast<std::size_t>(n));
  P.sensitivity.resize(n, 3);
  for (int j = 0; j < n; ++j) {
    const auto s = static_cast<std::size_t>(j);
    P.d[s] = Vec3(u(rng), u(rng), u(rng));
    for (int i = 0; i < 3; ++i) P.inputs[s].dir[i] = (j % (2 + i + i / 2)) ? 1 : -1;  // periods 2, 3, 5
    P.inputs[s].t = 1.0 * j;
    for (int i = 0; i < 3; ++i) P.sensitivity(j, i) = 0.6 + 0.3 * std::sin(0.37 * j + i);
  }
  P.has_dir = P.has_time = true;
  P.base = Eigen::MatrixXd::Ones(n, 1);
  P.base_map = Eigen::MatrixXd::Identity(1, 1);
  P.base_value = Eigen::VectorXd::Zero(1);
  P.base_names = {"offset"};
  P.base_units = {"m"};
  P.residual = Eigen::VectorXd::Zero(n);
  P.residual_given = P.residual;
  return P;
}

// The residual (model - measurement) of data whose measurement exceeds the
// model by `planted` plus gaussian noise sigma (m), base offset included.
void plant(KinematicProblem& P, const Eigen::VectorXd& planted, double sigma, std::uint64_t seed = 5) {
  std::mt19937_64 rng(seed);
  std::normal_distribution<double> n(0.0, sigma);
  P.residual.resize(P.rows());
  for (int r = 0; r < P.rows(); ++r) P.residual(r) = -(planted(r) + 2e-6 + n(rng));
  P.residual_given = P.residual;
}

TEST(KinematicEffectTable, EveryKinematicEffectTypeHasAFitter) {
  for (int t = 0; t < kin::kKinematicEffectTypes; ++t) {
    const auto type = static_cast<kin::KinematicEffectType>(t);
    const KinematicEffectFitter* f = kinematic_fitter(type);
    ASSERT_NE(f, nullptr) << kin::info(type).name << " has no entry in the kinematic effect table";
    EXPECT_EQ(f->type, type);
    EXPECT_NE(f->evaluate, nullptr);
    EXPECT_NE(f->joint_values, nullptr);
  }
}

// What an effect's signature depends on agrees with what it needs from the data.
TEST(KinematicEffectTable, SignaturesAgreeWithWhatTheEffectsNeed) {
  for (int t = 0; t < kin::kKinematicEffectTypes; ++t) {
    const auto type = static_cast<kin::KinematicEffectType>(t);
    const KinematicEffectFitter* f = kinematic_fitter(type);
    ASSERT_NE(f, nullptr);
    EXPECT_EQ(f->signature.direction, kin::info(type).needs_direction) << kin::info(type).name;
    EXPECT_EQ(f->signature.time, kin::info(type).needs_time) << kin::info(type).name;
  }
  EXPECT_TRUE(kinematic_fitter(kin::KinematicEffectType::cyclic_error)->signature.periodic);
}

TEST(KinematicColumns, CyclicErrorColumnsAreSineAndCosineThroughTheSensitivity) {
  const KinematicProblem P = synthetic(50);
  const double k = 1.0 / 7.3e-3;
  const Eigen::MatrixXd X = cyclic_error_columns(P, 1, k);
  ASSERT_EQ(X.rows(), 50);
  ASSERT_EQ(X.cols(), 2);
  for (int r = 0; r < 50; ++r) {
    const double x = kTwoPi * P.d[static_cast<std::size_t>(r)][1] / 7.3e-3;
    EXPECT_NEAR(X(r, 0), P.sensitivity(r, 1) * std::sin(x), 1e-9);
    EXPECT_NEAR(X(r, 1), P.sensitivity(r, 1) * std::cos(x), 1e-9);
  }
}

TEST(KinematicColumns, ThermalDriftColumnGrowsTowardsTheReadingWithTime) {
  const KinematicProblem P = synthetic(40);
  const Eigen::VectorXd c = thermal_drift_column(P, 2, 10.0);
  for (int r = 0; r < 40; ++r) {
    const double t = r, d = P.d[static_cast<std::size_t>(r)][2];
    EXPECT_NEAR(c(r), P.sensitivity(r, 2) * d * (1.0 - std::exp(-t / 10.0)), 1e-15);
  }
  EXPECT_EQ(c(0), 0.0);  // t = 0: nothing has grown yet
}

TEST(KinematicColumns, DisplacementColumnIsTheSensitivityTimesTheChange) {
  KinematicProblem P = synthetic(10);
  P.per_sample = 3;  // position data: three rows a sample
  P.sensitivity = Eigen::MatrixXd::Constant(30, 3, 2.0);
  const Eigen::VectorXd c = displacement_column(P, 0, [](int j) { return 1.0 * j; });
  for (int r = 0; r < 30; ++r) EXPECT_EQ(c(r), 2.0 * (r / 3));
}

TEST(KinematicSearch, TheWavelengthSearchRecoversAPlantedWavelength) {
  KinematicProblem P = synthetic(400);
  const double lambda = 7.3e-3, a = 3e-6, phi = 0.8;
  Eigen::VectorXd planted(P.rows());
  for (int r = 0; r < P.rows(); ++r)
    planted(r) = P.sensitivity(r, 0) * a * std::sin(kTwoPi * P.d[static_cast<std::size_t>(r)][0] / lambda + phi);
  plant(P, planted, 0.2e-6);
  const Engine E(kinematic_linear_problem(P));
  const double stroke = span_of(P).hi[0] - span_of(P).lo[0];
  const double kmin = 1.0 / 0.05, kmax = 1.0 / 1e-3, dk = 1.0 / (4.0 * stroke);
  const double k = search_cyclic_wavenumber(P, E, 0, kmin, kmax, dk);
  EXPECT_NEAR(1.0 / k, lambda, 1e-3 * lambda);
}

// The search's grid is evaluated by rotating each row's phase instead of a
// least-squares fit per wavenumber: its answer leaves no more RSS than the
// best grid point fitted directly, on pure noise (many shallow minima) and
// with two sines of which the weaker must not win.
TEST(KinematicSearch, TheWavelengthSearchIsAtLeastAsGoodAsEveryGridPointFittedDirectly) {
  for (const double second : {0.0, 1.5e-6}) {
    KinematicProblem P = synthetic(300, 9);
    Eigen::VectorXd planted(P.rows());
    for (int r = 0; r < P.rows(); ++r) {
      const double d = P.d[static_cast<std::size_t>(r)][1];
      planted(r) = P.sensitivity(r, 1) * second * (std::sin(kTwoPi * d / 4.1e-3) + 0.6 * std::cos(kTwoPi * d / 11e-3));
    }
    plant(P, planted, 0.3e-6, 11);
    const Engine E(kinematic_linear_problem(P));
    const double stroke = span_of(P).hi[1] - span_of(P).lo[1];
    const double kmin = 1.0 / 0.05, kmax = 1.0 / 1e-3, dk = 1.0 / (4.0 * stroke);
    double best = 1e300, best_k = 0.0;
    for (double k = kmin; k <= kmax; k += dk) {
      const double rss = E.rss(cyclic_error_columns(P, 1, k));
      if (rss < best) { best = rss; best_k = k; }
    }
    const double k = search_cyclic_wavenumber(P, E, 1, kmin, kmax, dk);
    EXPECT_LE(E.rss(cyclic_error_columns(P, 1, k)), best * (1.0 + 1e-9)) << "grid best at " << 1.0 / best_k;
    if (second > 0.0) {
      EXPECT_NEAR(1.0 / k, 4.1e-3, 1e-3 * 4.1e-3);
    }
  }
}

TEST(KinematicSearch, TheTimeConstantSearchRecoversAPlantedTimeConstant) {
  KinematicProblem P = synthetic(300);
  const double tau = 40.0, e = 4e-5;
  Eigen::VectorXd planted(P.rows());
  for (int r = 0; r < P.rows(); ++r)
    planted(r) = P.sensitivity(r, 1) * e * P.d[static_cast<std::size_t>(r)][1] * (1.0 - std::exp(-r / tau));
  plant(P, planted, 0.1e-6);
  const Engine E(kinematic_linear_problem(P));
  EXPECT_NEAR(search_thermal_time_constant(P, E, 1, 10.0, 3000.0), tau, 0.05 * tau);
}

// The whole candidate on the synthetic data: the planted cyclic error named
// with its parameters within three standard errors.
TEST(KinematicCandidate, CyclicErrorIsFittedWithItsParameters) {
  KinematicProblem P = synthetic(400);
  const double lambda = 12e-3, a = 2e-6, phi = -1.1;
  Eigen::VectorXd planted(P.rows());
  for (int r = 0; r < P.rows(); ++r)
    planted(r) = P.sensitivity(r, 2) * a * std::sin(kTwoPi * P.d[static_cast<std::size_t>(r)][2] / lambda + phi);
  plant(P, planted, 0.2e-6);
  const Engine E(kinematic_linear_problem(P));
  const CandidateResult c = evaluate_kinematic_candidate(P, E, "cyclic_error", 2, {});
  ASSERT_TRUE(c.identifiable) << c.note;
  ASSERT_EQ(c.params.size(), 3u);
  const double truth[3] = {a, lambda, phi};
  for (int j = 0; j < 3; ++j) {
    ASSERT_GT(c.params[static_cast<std::size_t>(j)].std_error, 0.0);
    EXPECT_LT(std::fabs(c.params[static_cast<std::size_t>(j)].value - truth[j]),
              3.0 * c.params[static_cast<std::size_t>(j)].std_error)
        << c.params[static_cast<std::size_t>(j)].name;
  }
}

// Searched again beside another effect's column (in the base of `beside`),
// a cyclic error left at a wrong wavelength (as an alias found alone would
// be) takes the planted one, its amplitude fitted with the other effect; a
// second search, finding nothing better, leaves it as it is.
TEST(KinematicCandidate, ACyclicErrorSearchedAgainBesideAnotherEffectTakesThePlantedWavelength) {
  KinematicProblem P = synthetic(400);
  const double lambda = 12e-3, a = 2e-6, phi = -1.1;
  Eigen::VectorXd planted(P.rows()), other(P.rows());
  for (int r = 0; r < P.rows(); ++r) {
    const Vec3& d = P.d[static_cast<std::size_t>(r)];
    other(r) = P.sensitivity(r, 0) * d[0] * d[0];
    planted(r) = P.sensitivity(r, 2) * a * std::sin(kTwoPi * d[2] / lambda + phi) + 1e-4 * other(r);
  }
  plant(P, planted, 0.2e-6);
  const Engine E(kinematic_linear_problem(P));
  LinearProblem L = kinematic_linear_problem(P);
  L.B = Eigen::MatrixXd(P.rows(), 2);
  L.B << P.base, other;
  L.base_names.emplace_back("other");
  L.base_units.emplace_back("m");
  L.base_values.push_back(0.0);
  L.nuisance.push_back(0);
  const Engine beside(std::move(L));
  CandidateResult c = evaluate_kinematic_candidate(P, E, "cyclic_error", 2, {});
  c.params[1].value = 3.1e-3;
  c.columns = cyclic_error_columns(P, 2, 1.0 / 3.1e-3);
  const KinematicEffectFitter* f = kinematic_fitter(kin::KinematicEffectType::cyclic_error);
  ASSERT_NE(f->search_beside, nullptr);
  const KinematicCandidateContext x{P, E, 2, kin::info(kin::KinematicEffectType::cyclic_error), span_of(P)};
  f->search_beside(x, beside, c);
  const double truth[3] = {a, lambda, phi};
  for (int j = 0; j < 3; ++j) {
    const ParamEstimate& p = c.params[static_cast<std::size_t>(j)];
    ASSERT_GT(p.std_error, 0.0) << p.name;
    EXPECT_LT(std::fabs(p.value - truth[j]), 3.0 * p.std_error) << p.name << " " << p.value;
  }
  EXPECT_LT((c.columns - cyclic_error_columns(P, 2, 1.0 / c.params[1].value)).norm(), 1e-9 * c.columns.norm());
  const CandidateResult again = c;
  f->search_beside(x, beside, c);
  EXPECT_EQ(c.params[1].value, again.params[1].value);
  EXPECT_EQ(c.params[0].value, again.params[0].value);
  EXPECT_EQ(kinematic_fitter(kin::KinematicEffectType::limb_twist)->search_beside, nullptr);
}

TEST(KinematicCandidate, BacklashIsHeldAtZeroWhenTheDataSayNegative) {
  KinematicProblem P = synthetic(200);
  Eigen::VectorXd planted(P.rows());
  // A lost motion of -3 µm: the reading leads when moving forward.
  for (int r = 0; r < P.rows(); ++r) planted(r) = P.sensitivity(r, 0) * 1.5e-6 * P.inputs[static_cast<std::size_t>(r)].dir[0];
  plant(P, planted, 0.1e-6);
  const Engine E(kinematic_linear_problem(P));
  const CandidateResult c = evaluate_kinematic_candidate(P, E, "backlash", 0, {});
  ASSERT_EQ(c.params.size(), 1u);
  EXPECT_EQ(c.params[0].value, 0.0);
  EXPECT_TRUE(c.params[0].at_bound);
  EXPECT_EQ(c.rss, E.rss_base());
  EXPECT_NE(c.note.find("negative lost motion"), std::string::npos) << c.note;
}

TEST(KinematicCandidate, RefusalsSayWhy) {
  KinematicProblem P = synthetic(60);
  plant(P, Eigen::VectorXd::Zero(P.rows()), 0.1e-6);
  const Engine E(kinematic_linear_problem(P));
  EXPECT_THROW(evaluate_kinematic_candidate(P, E, "spring", 0, {}), Error);
  EXPECT_THROW(evaluate_kinematic_candidate(P, E, "backlash", 3, {}), Error);
  EXPECT_THROW(evaluate_kinematic_candidate(P, E, "backlash", -1, {}), Error);

  KinematicProblem no_dir = P;
  no_dir.has_dir = false;
  CandidateResult c = evaluate_kinematic_candidate(no_dir, E, "backlash", 1, {});
  EXPECT_FALSE(c.identifiable);
  EXPECT_NE(c.note.find("dir1"), std::string::npos) << c.note;
  EXPECT_EQ(c.params.size(), 1u);
  EXPECT_EQ(c.columns.cols(), 0);

  KinematicProblem no_time = P;
  no_time.has_time = false;
  c = evaluate_kinematic_candidate(no_time, E, "thermal_drift", 1, {});
  EXPECT_FALSE(c.identifiable);
  EXPECT_NE(c.note.find("column t"), std::string::npos) << c.note;

  KinematicProblem same_time = P;
  for (auto& in : same_time.inputs) in.t = 5.0;
  c = evaluate_kinematic_candidate(same_time, E, "thermal_drift", 0, {});
  EXPECT_FALSE(c.identifiable);
  EXPECT_NE(c.note.find("same time"), std::string::npos) << c.note;

  KinematicProblem has_it = P;
  has_it.given.effects[2].backlash = 2e-6;
  c = evaluate_kinematic_candidate(has_it, E, "backlash", 2, {});
  EXPECT_FALSE(c.identifiable);
  EXPECT_EQ(c.note, "already in the model");

  KinematicProblem short_stroke = P;
  for (auto& d : short_stroke.d) d[0] = 0.1 + 1e-4 * (d[0] - 0.05);  // 20 µm of travel
  c = evaluate_kinematic_candidate(short_stroke, E, "cyclic_error", 0, {});
  EXPECT_FALSE(c.identifiable);
  EXPECT_NE(c.note.find("too little to see a periodic error"), std::string::npos) << c.note;
}

TEST(KinematicJointValues, CyclicCoefficientsBecomeAmplitudeAndPhase) {
  const double a = 3e-6, phi = 2.0;
  JointFit f;
  f.beta = Eigen::Vector3d(7.0, a * std::cos(phi), a * std::sin(phi));
  CandidateResult c;
  c.effect = "cyclic_error";
  c.columns = Eigen::MatrixXd::Zero(4, 2);
  c.params = {{"a", "m", 0, -1, false}, {"lambda", "m", 9e-3, 1e-6, false}, {"phi", "rad", 0, -1, false}};
  std::array<double, 3> v{};
  kinematic_fitter(kin::KinematicEffectType::cyclic_error)->joint_values(f, 1, Eigen::MatrixXd::Identity(3, 3), c, v);
  EXPECT_NEAR(v[0], a, 1e-18);
  EXPECT_EQ(v[1], 9e-3);  // the searched wavelength is kept
  EXPECT_NEAR(v[2], phi, 1e-12);
  EXPECT_EQ(c.params[0].value, v[0]);
  EXPECT_EQ(c.params[2].value, v[2]);
}

TEST(KinematicJointValues, LinearEffectsTakeTheirCoefficientsAndANegativeBacklashIsRefused) {
  JointFit f;
  f.beta = Eigen::Vector3d(1.0, 2e-6, -3e-6);
  Eigen::MatrixXd cov = Eigen::MatrixXd::Zero(3, 3);
  cov.diagonal() << 1.0, 4e-14, 9e-14;
  CandidateResult c;
  c.effect = "backlash";
  c.axis = 0;
  c.columns = Eigen::MatrixXd::Zero(4, 1);
  c.params = {{"b", "m", 0, -1, false}};
  std::array<double, 3> v{};
  const auto* backlash = kinematic_fitter(kin::KinematicEffectType::backlash);
  backlash->joint_values(f, 1, cov, c, v);
  EXPECT_EQ(v[0], 2e-6);
  EXPECT_NEAR(c.params[0].std_error, 2e-7, 1e-20);
  EXPECT_THROW(backlash->joint_values(f, 2, cov, c, v), Error);
}

// The structure scan finds a step planted in an axis' effective displacement.
TEST(KinematicStructure, AStepInAnAxisIsFoundWhereItIs) {
  KinematicProblem P = synthetic(300);
  Eigen::VectorXd step(P.rows());
  for (int r = 0; r < P.rows(); ++r) step(r) = P.sensitivity(r, 1) * (P.d[static_cast<std::size_t>(r)][1] > 0.17 ? 3e-6 : 0.0);
  plant(P, step, 0.2e-6);
  // residual_final is measurement - model.
  const std::vector<StructureFinding> S = find_kinematic_structure(P, -P.residual, {});
  const StructureFinding* found = nullptr;
  for (const auto& s : S)
    if (s.kind == "step" && s.axis == 1) found = &s;
  ASSERT_NE(found, nullptr);
  EXPECT_NEAR(found->location, 0.17, 0.015);
  EXPECT_NEAR(found->size, 3e-6, 0.5e-6);
  EXPECT_TRUE(find_kinematic_structure(P, Eigen::VectorXd::Zero(3), {}).empty());  // wrong length: nothing
}

// Stage 4 on simulated ball-bar data: every effect of the table on every
// axis, in table order; a restriction to some effects keeps those.
TEST(KinematicSelection, EveryEffectOnEveryAxisInTableOrder) {
  const auto poses = test::hemisphere_poses({0.100, 0.150}, 4, 10, 11);
  const io::BallbarData b = test::kim_ballbar({{"backlash", 1, {5e-6, 0, 0}}}, poses);
  const KinematicProblem P = prepare_kinematic(b, ctl::MachineModel::elkady().kinematics);
  const Engine E(kinematic_linear_problem(P));
  const std::vector<CandidateResult> all = evaluate_kinematic_candidates(P, E, {});
  ASSERT_EQ(all.size(), static_cast<std::size_t>(3 * kin::kKinematicEffectTypes));
  for (std::size_t k = 0; k < all.size(); ++k) {
    EXPECT_EQ(all[k].effect, kin::info(static_cast<kin::KinematicEffectType>(k / 3)).name);
    EXPECT_EQ(all[k].axis, static_cast<int>(k % 3));
  }
  // The planted backlash is the best identifiable description of these data.
  const CandidateResult* best = nullptr;
  for (const auto& c : all)
    if (c.identifiable && (!best || c.rss < best->rss)) best = &c;
  ASSERT_NE(best, nullptr);
  EXPECT_EQ(best->label(), "backlash[axis 2]");
  // The noise floor: about the bar's noise (uniform +-0.5 µm), not the backlash.
  const double floor = kinematic_noise_floor(P, E, all);
  EXPECT_GT(floor, 0.1e-6);
  EXPECT_LT(floor, 0.6e-6);

  DiagnoseOptions only;
  only.effects = {"limb_twist"};
  const std::vector<CandidateResult> some = evaluate_kinematic_candidates(P, E, only);
  ASSERT_EQ(some.size(), 3u);
  for (const auto& c : some) EXPECT_EQ(c.effect, "limb_twist");
}

TEST(KinematicSelection, ADeclaredInstrumentSigmaIsTheNoiseFloor) {
  KinematicProblem P = synthetic(50);
  plant(P, Eigen::VectorXd::Zero(P.rows()), 1e-6);
  const Engine E(kinematic_linear_problem(P));
  EXPECT_GT(kinematic_noise_floor(P, E, {}), 0.5e-6);
  P.sigma_declared = 3e-6;
  EXPECT_EQ(kinematic_noise_floor(P, E, {}), 3e-6);
}

}  // namespace
}  // namespace cpm::ident
