// SPDX-License-Identifier: Apache-2.0
// The kinematic side of diagnose / fit on simulated ball-bar and position
// data (a true machine with Kim's errors, the nominal model as given).
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <numbers>
#include <memory>

#include <nlohmann/json.hpp>

#include "cpm/identification/kinematic.hpp"
#include "cpm/identification/report.hpp"
#include "kin_data.hpp"

namespace cpm {
namespace {

using ident::Diagnosis;
using test::PlantedKinematic;

// CPM_IDENT_SEEDS=N runs the longer sweep (N seeds) of the planted-effect
// and no-effect checks; CI runs the default.
int seeds(int ci_default) {
  const char* e = std::getenv("CPM_IDENT_SEEDS");
  return e ? std::max(1, std::atoi(e)) : ci_default;
}

Diagnosis diagnose(const io::DataSet& ds, const ident::DiagnoseOptions& o = {}) {
  auto P = std::make_shared<const ident::KinematicProblem>(
      ident::prepare_kinematic(ds, ctl::MachineModel::elkady().kinematics));
  return ident::diagnose_kinematic(P, o);
}

const ident::CandidateResult* find(const Diagnosis& D, const std::string& effect, int axis) {
  for (const auto& c : D.candidates)
    if (c.effect == effect && c.axis == axis) return &c;
  return nullptr;
}

std::vector<Vec3> ballbar_poses(std::uint64_t seed = 7) { return test::hemisphere_poses({0.100, 0.150}, 6, 16, seed); }

// The residual of calibration's own function agrees with the problem's full
// forward kinematics, and the base columns are its Jacobian.
TEST(KinematicProblem, ResidualAndBaseAgreeWithCalibration) {
  const auto poses = ballbar_poses();
  const io::BallbarData b = test::kim_ballbar({}, poses);
  const auto P = ident::prepare_kinematic(b, ctl::MachineModel::elkady().kinematics);
  EXPECT_EQ(P.rows(), static_cast<int>(poses.size()));
  cal::VecX r;
  cal::ballbar_residuals(P.base_value, P.given.d0, P.d, P.length, P.pivot, r, nullptr);
  EXPECT_LT((r - P.residual).cwiseAbs().maxCoeff(), 1e-12);
  // Kim's errors are hundreds of µm; calibration leaves the bar's noise.
  EXPECT_GT(ident::Engine::rms(P.residual_given), 50e-6);
  EXPECT_LT(ident::Engine::rms(P.residual), 0.4e-6);
}

struct Plant {
  const char* effect;
  int axis;
  std::array<double, 3> shape;  // the planted parameters; the amplitude (index 0) is set by the sweep
  double probe;                 // an amplitude the search locks onto, to measure the standard error
};

constexpr double kBarSigma = 0.5e-6 / 1.7320508075688772;  // uniform +-0.5 µm

// 1x = 4 standard errors of the amplitude parameter (at the planted
// wavelength or time constant): about what the diagnosis, after its
// look-elsewhere correction, can still call noise. The standard error of a
// linear parameter does not depend on its value: measured on a probe.
double unit_of(const Diagnosis& probe, const Plant& p) {
  const auto* c = find(probe, p.effect, p.axis);
  EXPECT_NE(c, nullptr);
  return c ? 4.0 * c->params[0].std_error : 0.0;
}

struct Outcome {
  bool first = false, within = false, floor = false;
  double rms_after = 0.0;
  std::string text;
};

Outcome check(const Diagnosis& D, const Plant& p, const std::array<double, 3>& truth, double noise) {
  Outcome o;
  if (D.verdict < 0) {
    o.text = "verdict none";
    return o;
  }
  const auto& v = D.candidates[static_cast<std::size_t>(D.verdict)];
  o.first = v.effect == p.effect && v.axis == p.axis;
  o.rms_after = v.rms_after;
  o.floor = v.rms_after <= 1.2 * noise;
  o.within = o.first;
  char b[400];
  std::snprintf(b, sizeof b, "%s (rms after %.3f µm)", v.label().c_str(), v.rms_after * 1e6);
  o.text = b;
  if (!o.first) return o;
  for (std::size_t j = 0; j < v.params.size(); ++j) {
    double err = v.params[j].value - truth[j];
    if (v.params[j].name == "phi") err = std::remainder(err, 2.0 * std::numbers::pi);
    const bool ok = v.params[j].std_error > 0.0 && std::fabs(err) <= 3.0 * v.params[j].std_error;
    o.within = o.within && ok;
    std::snprintf(b, sizeof b, "; %s %.4g (true %.4g, %.1f sigma)", v.params[j].name.c_str(), v.params[j].value,
                  truth[j], std::fabs(err) / v.params[j].std_error);
    o.text += b;
  }
  return o;
}

void planted_sweep(bool ballbar, const std::vector<Plant>& plants, std::uint64_t seed) {
  const auto poses = ballbar ? ballbar_poses(seed) : test::hemisphere_poses({0.100, 0.150}, 5, 12, seed);
  test::KinSimOptions so;
  so.seed = seed;
  so.noise = ballbar ? 0.5e-6 : 2e-6;
  const double noise = ballbar ? kBarSigma : 2e-6;
  auto data = [&](const std::vector<PlantedKinematic>& pl) -> io::DataSet {
    if (ballbar) return test::kim_ballbar(pl, poses, so);
    return test::kim_positions(pl, poses, so);
  };
  for (const Plant& p : plants) {
    std::array<double, 3> probe = p.shape;
    probe[0] = p.probe;
    const double unit = unit_of(diagnose(data({{p.effect, p.axis, probe}})), p);
    for (double m : {1.0, 3.0, 10.0}) {
      std::array<double, 3> truth = p.shape;
      truth[0] = m * unit;
      const Diagnosis D = diagnose(data({{p.effect, p.axis, truth}}));
      const Outcome o = check(D, p, truth, noise);
      std::printf("[%s] %s axis %d at %2.0fx (%.3g): %s\n", ballbar ? "ballbar" : "position", p.effect, p.axis + 1, m,
                  truth[0], o.text.c_str());
      if (m >= 3.0) {
        EXPECT_TRUE(o.first) << p.effect << " at " << m << "x: " << o.text;
        EXPECT_TRUE(o.within) << p.effect << " at " << m << "x: " << o.text;
        EXPECT_TRUE(o.floor) << p.effect << " at " << m << "x: " << o.text;
      }
    }
  }
}

// Must show (issue 4): every kinematic effect a ball-bar can show, planted at
// 1x, 3x and 10x on Kim's true machine: at 3x and 10x ranked first on the
// right axis, parameters within 3 sigma, residual within 20 % of the noise.
TEST(KinematicPlanted, BallbarEffectsAreNamedOnTheRightAxisWithTheirParameters) {
  planted_sweep(true,
                {{"backlash", 1, {1, 0, 0}, 2e-6},
                 {"cyclic_error", 0, {1, 0.012, 0.7}, 2e-6},
                 {"guide_angular_error", 2, {1, 0, 0}, 1e-3},
                 {"limb_twist", 1, {1, 0, 0}, 5e-4},
                 {"thermal_drift", 0, {1, 1500.0, 0}, 5e-5}},
                3);
  for (int k = 1; k < seeds(1); ++k)
    planted_sweep(true,
                  {{"backlash", 1, {1, 0, 0}, 2e-6},
                   {"cyclic_error", 0, {1, 0.012, 0.7}, 2e-6},
                   {"guide_angular_error", 2, {1, 0, 0}, 1e-3},
                   {"limb_twist", 1, {1, 0, 0}, 5e-4},
                   {"thermal_drift", 0, {1, 1500.0, 0}, 5e-5}},
                  1000 + static_cast<std::uint64_t>(k));
}

TEST(KinematicPlanted, PositionEffectsAreNamedOnTheRightAxisWithTheirParameters) {
  planted_sweep(false,
                {{"backlash", 2, {1, 0, 0}, 1e-5},
                 {"cyclic_error", 1, {1, 0.020, -1.0}, 1e-5},
                 {"guide_angular_error", 0, {1, 0, 0}, 1e-3},
                 {"limb_twist", 2, {1, 0, 0}, 5e-4},
                 {"thermal_drift", 1, {1, 1000.0, 0}, 5e-4}},
                5);
}

// Must show: on data with no missing effect the verdict is none at least 95 %
// of the time (Kim's true machine, nothing planted, many seeds).
TEST(KinematicNoEffect, VerdictIsNoneAtLeast95PercentOfSeeds) {
  int none = 0, total = 0;
  for (std::uint64_t seed = 100; seed < 100 + 40 * static_cast<std::uint64_t>(seeds(1)); ++seed) {
    test::KinSimOptions so;
    so.seed = seed;
    const Diagnosis D = diagnose(test::kim_ballbar({}, ballbar_poses(seed), so));
    none += D.verdict < 0;
    ++total;
    if (D.verdict >= 0) std::printf("seed %d: %s\n", static_cast<int>(seed), D.verdict_text.c_str());
  }
  for (std::uint64_t seed = 200; seed < 220; ++seed) {
    test::KinSimOptions so;
    so.seed = seed;
    so.noise = 2e-6;
    const Diagnosis D = diagnose(test::kim_positions({}, test::hemisphere_poses({0.100, 0.150}, 5, 12, seed), so));
    none += D.verdict < 0;
    ++total;
    if (D.verdict >= 0) std::printf("seed %d: %s\n", static_cast<int>(seed), D.verdict_text.c_str());
  }
  std::printf("verdict none in %d of %d data sets\n", none, total);
  EXPECT_GE(none, static_cast<int>(std::ceil(0.95 * total)));
}

// docs/effects.md: actuator_scale exists so that a nominal-only model can name
// it. A calibrated base absorbs a scale (it is c_i); with the nominal model
// and a machine whose planes are otherwise nominal, the scale alone explains
// what a full calibration would, and the diagnosis names it. On Kim's machine
// the planes need calibrating anyway: no scale is named.
TEST(KinematicPlanted, ActuatorScaleIsNamedWhenTheModelIsNominalOnly) {
  const std::vector<test::PlantedKinematic> scale2 = {{"actuator_scale", 1, {2e-4, 0, 0}}};
  test::KinSimOptions so;
  so.kim_errors = false;
  for (int kind = 0; kind < 2; ++kind) {
    if (kind == 1) so.noise = 2e-6;
    const Diagnosis D = diagnose(kind == 0 ? io::DataSet(test::kim_ballbar(scale2, ballbar_poses(), so))
                                           : io::DataSet(test::kim_positions(scale2, ballbar_poses(), so)));
    ASSERT_GE(D.verdict, 0) << D.verdict_text;
    const auto& c = D.candidates[static_cast<std::size_t>(D.verdict)];
    EXPECT_EQ(c.label(), "actuator_scale[axis 2]") << D.verdict_text;
    ASSERT_GT(c.params[0].std_error, 0.0);
    EXPECT_LE(std::fabs(c.params[0].value - 2e-4), 3.0 * c.params[0].std_error) << c.params[0].value;
    std::printf("%s: actuator_scale[axis 2] s = %.4g +- %.2g (planted 2e-4)\n", kind == 0 ? "ball-bar" : "positions",
                c.params[0].value, c.params[0].std_error);
  }
  test::KinSimOptions kim;
  const Diagnosis K = diagnose(test::kim_ballbar(scale2, ballbar_poses(), kim));
  EXPECT_LT(K.verdict, 0) << K.verdict_text;
  const auto* s2 = find(K, "actuator_scale", 1);
  ASSERT_NE(s2, nullptr);
  EXPECT_NE(s2->note.find("full calibration"), std::string::npos) << s2->note;
}

std::vector<std::string> found_labels(const Diagnosis& D) {
  std::vector<std::string> out;
  for (int j : D.found()) out.push_back(D.candidates[static_cast<std::size_t>(j)].label());
  std::sort(out.begin(), out.end());
  return out;
}

// A scale beside another effect (nominal planes, the nominal model): judged at
// the model as given jointly with the effect the selection chose, it is named
// beside it; where none is planted, none is named (judged without the other
// effect, the scales took up part of a backlash on axis 3: a scale on axis 3
// came out significant; and the full calibration explained the backlash's
// share the scales could not, so a planted scale was never named).
TEST(KinematicPairs, AScaleBesideAnotherEffectIsNamedWithItAndOnlyWhereThereIsOne) {
  test::KinSimOptions so;
  so.kim_errors = false;
  so.seed = 21;
  const std::vector<PlantedKinematic> both = {{"backlash", 2, {4e-6, 0, 0}}, {"actuator_scale", 1, {3e-5, 0, 0}}};
  const Diagnosis D = diagnose(test::kim_ballbar(both, ballbar_poses(21), so));
  EXPECT_EQ(found_labels(D), (std::vector<std::string>{"actuator_scale[axis 2]", "backlash[axis 3]"})) << D.verdict_text;
  const auto* s = find(D, "actuator_scale", 1);
  ASSERT_NE(s, nullptr);
  ASSERT_GT(s->params[0].std_error, 0.0);
  EXPECT_LE(std::fabs(s->params[0].value - 3e-5), 3.0 * s->params[0].std_error) << s->params[0].value;
  const Diagnosis B = diagnose(test::kim_ballbar({both[0]}, ballbar_poses(21), so));
  EXPECT_EQ(found_labels(B), (std::vector<std::string>{"backlash[axis 3]"})) << B.verdict_text;
}

// With one bar radius axis 3 is seen at six heights: a sine of almost any
// wavelength fits there alike, each with its own share of a linear term, so
// scales judged beside a cyclic error there follow the wavelength chosen (all
// three were named beside a cyclic error on axis 3 and a scale on axis 1).
// The cyclic error is named, its wavelength said to be undetermined, and no
// scale is judged; with two radii the wavelength is determined and the scale
// on axis 1 is named, alone.
TEST(KinematicPairs, NoScaleIsJudgedBesideAWavelengthTheDataDoNotDetermine) {
  test::KinSimOptions so;
  so.kim_errors = false;
  so.seed = 7008;
  const std::vector<PlantedKinematic> planted = {{"cyclic_error", 2, {1e-5, 0.016, 0.3}},
                                                 {"actuator_scale", 0, {4e-5, 0, 0}}};
  const Diagnosis one = diagnose(test::kim_ballbar(planted, test::hemisphere_poses({0.150}, 6, 16, 7008), so));
  EXPECT_EQ(found_labels(one), (std::vector<std::string>{"cyclic_error[axis 3]"})) << one.verdict_text;
  const auto* c = find(one, "cyclic_error", 2);
  ASSERT_NE(c, nullptr);
  EXPECT_FALSE(c->searched_determined);
  EXPECT_NE(c->note.find("not determined"), std::string::npos) << c->note;
  for (int i = 0; i < 3; ++i) {
    const auto* s = find(one, "actuator_scale", i);
    ASSERT_NE(s, nullptr);
    EXPECT_NE(s->note.find("not judged"), std::string::npos) << s->note;
  }
  const Diagnosis two = diagnose(test::kim_ballbar(planted, ballbar_poses(7008), so));
  EXPECT_EQ(found_labels(two), (std::vector<std::string>{"actuator_scale[axis 1]", "cyclic_error[axis 3]"}))
      << two.verdict_text;
  EXPECT_TRUE(find(two, "cyclic_error", 2)->searched_determined);
}

// A cyclic error on axis 3 beside a limb twist there (two radii: axis 3 sits
// at twelve heights): its wavelength searched alone, on a residual holding the
// twist, lands on an alias; searched again beside the twist once that is
// chosen, it is the planted one, and nothing else is named (before, twists and
// guide errors on other axes took what the alias left).
TEST(KinematicPairs, AWavelengthIsSearchedAgainBesideTheEffectsChosenWithIt) {
  test::KinSimOptions so;
  so.seed = 1006;
  const io::BallbarData b = test::kim_ballbar(
      {{"cyclic_error", 2, {3.5e-6, 0.016, 0.3}}, {"limb_twist", 2, {4.1e-4, 0, 0}}}, ballbar_poses(1006), so);
  const auto P = ident::prepare_kinematic(b, ctl::MachineModel::elkady().kinematics);
  const ident::Engine E(ident::kinematic_linear_problem(P));
  const auto alone = ident::evaluate_kinematic_candidate(P, E, "cyclic_error", 2, {});
  std::printf("cyclic_error[axis 3] searched alone: lambda %.4g mm\n", alone.params[1].value * 1e3);
  const Diagnosis D = diagnose(b);
  EXPECT_EQ(found_labels(D), (std::vector<std::string>{"cyclic_error[axis 3]", "limb_twist[axis 3]"})) << D.verdict_text;
  const auto* c = find(D, "cyclic_error", 2);
  ASSERT_NE(c, nullptr);
  ASSERT_GT(c->params[1].std_error, 0.0);
  EXPECT_LE(std::fabs(c->params[1].value - 0.016), 3.0 * c->params[1].std_error) << c->params[1].value;
}

// The ISO 230-4 circular test (one XY circle of 150 mm, both directions) is
// the most common ball-bar measurement. It cannot determine the out-of-plane
// parameters: the base is calibrated where the circle sees (c1, c2, theta_z,
// the pivot in the plane), the rest kept as the model has it, and what the
// circle cannot see is said so, not fitted to a wild number (or NaN).
TEST(KinematicCircle, ACircularTestIsDiagnosedOnWhatItCanSee) {
  const auto nominal = ctl::MachineModel::elkady();
  const Vec3 c(0.430, 0.430, 0.400);
  std::vector<Vec3> poses;
  for (int dir : {+1, -1})
    for (int k = 0; k < 360; ++k) {
      const double a = dir * 2.0 * std::numbers::pi * k / 360.0;
      poses.push_back(c + 0.150 * Vec3(std::cos(a), std::sin(a), 0.0));
    }
  auto circle_data = [&](const std::vector<test::PlantedKinematic>& planted, bool kim) {
    cal::BallbarSimulation sim;
    sim.pivot_nominal = c;
    sim.pivot_true = c + Vec3(2e-5, -1e-5, 3e-6);
    sim.noise = {cal::NoiseShape::uniform, 0.5e-6, 1};
    sim.inputs = cal::sequence_inputs(nominal, poses, 0.1);
    io::BallbarData b = cal::simulate_ballbar(test::kim_truth_with(planted, kim), nominal, poses, sim);
    for (int k = 0; k < 720; ++k) b.extra.run.push_back(k < 360 ? 1 : 2);
    return b;
  };
  auto circle = [&](const std::vector<test::PlantedKinematic>& planted, bool kim) {
    return diagnose(circle_data(planted, kim));
  };
  EXPECT_LT(circle({}, true).verdict, 0);
  const Diagnosis B = circle({{"backlash", 0, {6e-6, 0, 0}}}, true);
  ASSERT_GE(B.verdict, 0) << B.verdict_text;
  const auto& v = B.candidates[static_cast<std::size_t>(B.verdict)];
  EXPECT_EQ(v.label(), "backlash[axis 1]");
  EXPECT_LE(std::fabs(v.params[0].value - 6e-6), 3.0 * v.params[0].std_error) << v.params[0].value;
  for (const auto& cand : B.candidates) {
    EXPECT_TRUE(std::isfinite(cand.rms_after)) << cand.label();
    if (cand.axis == 2) {
      EXPECT_FALSE(cand.identifiable) << cand.label() << ": axis 3 does not move";
    }
    for (const auto& p : cand.params) {
      if (p.std_error >= 0 && cand.identifiable) {
        EXPECT_LT(std::fabs(p.value), 1e3 * (p.std_error + 1e-12)) << cand.label();
      }
    }
  }
  EXPECT_EQ(ident::diagnosis_json(B).find("nan"), std::string::npos);
  EXPECT_TRUE(nlohmann::json::accept(ident::diagnosis_json(B)));
  // The fit recalibrates only what the circle determines (a tilt it cannot see stays put).
  const ident::KinematicFit F =
      ident::fit_kinematic(circle_data({{"backlash", 0, {6e-6, 0, 0}}}, true), nominal.kinematics, {{"backlash", 0}});
  EXPECT_LT(F.on_fit.after, 0.35e-6) << F.on_fit.before;
  ASSERT_TRUE(F.cross_validation.has_value());
  EXPECT_LT(F.cross_validation->after, 0.4e-6);
  EXPECT_NO_THROW(F.model.validate());
  const Diagnosis S = circle({{"actuator_scale", 1, {1e-4, 0, 0}}}, false);
  ASSERT_GE(S.verdict, 0) << S.verdict_text;
  EXPECT_EQ(S.candidates[static_cast<std::size_t>(S.verdict)].label(), "actuator_scale[axis 2]");
}

// Exact data (no noise at all): the residual after the base is rounding
// (1e-17 m); nothing is named on it, and a planted effect still is.
TEST(KinematicNoEffect, ExactDataNameNothingButTheEffectThatIsThere) {
  test::KinSimOptions so;
  so.noise = 0.0;
  const auto poses = ballbar_poses();
  EXPECT_LT(diagnose(test::kim_ballbar({}, poses, so)).verdict, 0);
  EXPECT_LT(diagnose(test::kim_positions({}, poses, so)).verdict, 0);
  const Diagnosis D = diagnose(test::kim_positions({{"cyclic_error", 1, {4e-6, 0.016, 0.3}}}, poses, so));
  ASSERT_GE(D.verdict, 0);
  EXPECT_EQ(D.candidates[static_cast<std::size_t>(D.verdict)].label(), "cyclic_error[axis 2]");
}

// Must show: confounded pairs are reported, not guessed. Backlash with every
// pose approached from the same side is a constant shift of the axis: the
// pivot error dq absorbs it; the report says so and how to separate them.
TEST(KinematicConfounding, BacklashWithOneDirectionIsReportedNotGuessed) {
  test::KinSimOptions so;
  so.one_direction = true;
  const Diagnosis D = diagnose(test::kim_ballbar({{"backlash", 1, {10e-6, 0, 0}}}, ballbar_poses(), so));
  EXPECT_LT(D.verdict, 0) << D.verdict_text;
  const auto* c = find(D, "backlash", 1);
  ASSERT_NE(c, nullptr);
  EXPECT_FALSE(c->identifiable);
  EXPECT_NE(c->note.find("both directions"), std::string::npos) << c->note;
  ASSERT_FALSE(c->confounded.empty());
  EXPECT_EQ(c->confounded[0].with.rfind("dq", 0), 0u) << c->confounded[0].with;
  const std::string js = ident::diagnosis_json(D);
  EXPECT_NE(js.find("both directions"), std::string::npos);
}

// Scale on all three axes with one bar radius and a bar of unknown length:
// the calibrated scales absorb each axis' scale, and their common part
// cannot be told from the bar's offset dl; the report says which measurement
// separates them, and names no effect.
TEST(KinematicConfounding, ScaleOnAllAxesAgainstBarOffsetWithOneRadius) {
  test::KinSimOptions so;
  so.length_offset_known = false;
  const auto poses = test::hemisphere_poses({0.150}, 6, 16, 11);
  const Diagnosis D = diagnose(test::kim_ballbar({{"actuator_scale", 0, {2e-4, 0, 0}},
                                                  {"actuator_scale", 1, {2e-4, 0, 0}},
                                                  {"actuator_scale", 2, {2e-4, 0, 0}}},
                                                 poses, so));
  EXPECT_LT(D.verdict, 0) << D.verdict_text;
  bool said = false;
  for (const auto& n : D.notes) said |= n.find("second bar radius") != std::string::npos && n.find("dl") != std::string::npos;
  EXPECT_TRUE(said) << ident::diagnosis_text(D);
  for (int i = 0; i < 3; ++i) {
    const auto* c = find(D, "actuator_scale", i);
    ASSERT_NE(c, nullptr);
    EXPECT_FALSE(c->identifiable);
    EXPECT_FALSE(c->significant);
  }
}

// Bad input: a data kind that cannot show an effect asked for by name, an
// effect without the columns it needs, too few samples to fit it.
TEST(KinematicBadInput, RefusalsAreClear) {
  const auto poses = ballbar_poses();
  const io::BallbarData b = test::kim_ballbar({}, poses);
  ident::DiagnoseOptions o;
  o.effects = {"coulomb_friction"};
  try {
    diagnose(b, o);
    FAIL() << "a dynamic effect on ball-bar data was accepted";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("cannot show"), std::string::npos) << e.what();
  }
  test::KinSimOptions so;
  so.with_dir = false;
  const io::BallbarData nodir = test::kim_ballbar({}, poses, so);
  try {
    ident::fit_kinematic(nodir, ctl::MachineModel::elkady().kinematics, {{"backlash", 1}});
    FAIL() << "backlash without direction columns was fitted";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("dir1"), std::string::npos) << e.what();
  }
  const std::vector<Vec3> few(poses.begin(), poses.begin() + 12);
  const io::BallbarData small = test::kim_ballbar({}, few);
  try {
    ident::fit_kinematic(small, ctl::MachineModel::elkady().kinematics, {{"guide_angular_error", 0}});
    FAIL() << "12 lengths fitted 9 base and 2 effect parameters";
  } catch (const Error& e) {
    const std::string m = e.what();
    EXPECT_TRUE(m.find("too few") != std::string::npos || m.find("needs more") != std::string::npos) << m;
  }
}

// Fit writes the effect into the kinematics: the new model's residual on the
// data and on held-out data falls to the noise; the fitted model compensates
// the effect in the inverse kinematics (the circular test's G falls).
TEST(KinematicFit, TheFittedModelExplainsHeldOutDataAndCompensatesTheCircle) {
  const std::vector<PlantedKinematic> planted{{"cyclic_error", 1, {4e-6, 0.016, 0.3}}};
  const io::BallbarData fit_data = test::kim_ballbar(planted, ballbar_poses(21));
  test::KinSimOptions so;
  so.seed = 22;
  const io::DataSet hold = test::kim_ballbar(planted, ballbar_poses(22), so);
  const auto nominal = ctl::MachineModel::elkady();
  const ident::KinematicFit F = ident::fit_kinematic(fit_data, nominal.kinematics, {{"cyclic_error", 1}}, {}, &hold);
  ASSERT_TRUE(F.holdout.has_value());
  std::printf("fit: before %.3f µm, base only %.3f µm, after %.3f µm; held out: base only %.3f µm, with the effect %.3f µm\n",
              F.on_fit.before * 1e6, F.base_only * 1e6, F.on_fit.after * 1e6, F.holdout->before * 1e6,
              F.holdout->after * 1e6);
  EXPECT_LT(F.on_fit.after, 1.2 * kBarSigma);
  EXPECT_LT(F.holdout->after, 1.2 * kBarSigma);
  EXPECT_GT(F.holdout->before, 2.0 * F.holdout->after);
  const auto& e = F.model.effects[1];
  EXPECT_NEAR(e.cyclic_amplitude, 4e-6, 0.3e-6);
  EXPECT_NEAR(e.cyclic_wavelength, 0.016, 1e-4);

  // Closed loop: the controller with the fitted model, on the true machine.
  ctl::MachineModel before = nominal, after = nominal;
  {
    const auto P = ident::prepare_kinematic(fit_data, nominal.kinematics);
    before.kinematics = P.model_of(P.base_value, P.given.effects);  // calibrated, no effect
  }
  after.kinematics = F.model;
  cal::CircularTestSpec spec;
  spec.closed_loop = false;
  spec.feed = 0.05;
  const auto truth = test::kim_truth_with(planted);
  const double g0 = cal::run_circular_test(truth, before, spec).G_bidirectional;
  const double g1 = cal::run_circular_test(truth, after, spec).G_bidirectional;
  std::printf("circular test G: calibrated base %.2f µm, with the fitted cyclic error %.2f µm\n", g0 * 1e6, g1 * 1e6);
  EXPECT_LT(g1, 0.5 * g0);
}

// Circle-like ball-bar data (a circular test read as a ball-bar file: CCW
// run then CW run about the pivot): compare finds the circle and its G, H, F
// agree with calibration's own circular test of the same machine.
TEST(KinematicCompare, CircleDataGetTheCircularTestFigures) {
  const auto truth = cal::kim_true_machine();
  const auto nominal = ctl::MachineModel::elkady();
  const Vec3 c(0.430, 0.430, 0.400);
  const double R = 0.150;
  std::vector<Vec3> poses;
  for (int dir : {+1, -1})
    for (int k = 0; k < 360; ++k) {
      const double a = dir * 2.0 * std::numbers::pi * k / 360.0;
      poses.push_back(c + R * Vec3(std::cos(a), std::sin(a), 0.0));
    }
  cal::CircularTestSpec spec;
  spec.closed_loop = false;
  const cal::CircularTestResult ref = cal::run_circular_test(truth, nominal, spec);
  cal::BallbarSimulation sim;
  sim.pivot_nominal = c;
  sim.pivot_true = ref.pivot;  // the pivot where the machine goes for the centre, as the test sets it up
  sim.noise = {cal::NoiseShape::uniform, 0.5e-6, 5};
  sim.inputs = cal::sequence_inputs(nominal, poses, 0.1);
  io::BallbarData b = cal::simulate_ballbar(truth, nominal, poses, sim);
  for (int k = 0; k < 720; ++k) b.extra.run.push_back(k < 360 ? 1 : 2);
  // The model's distance to the pivot as the user declares it (the centre).
  const auto P = ident::read_kinematic(b, nominal.kinematics);
  const ident::KinematicSummary s = ident::summarize_kinematic(P, P.residual_given);
  ASSERT_TRUE(s.circle.has_value()) << s.circle_note;
  std::printf("G from the file %.2f µm, from the circular test %.2f µm; H %.2f / %.2f µm\n",
              s.circle->G_bidirectional * 1e6, ref.G_bidirectional * 1e6, s.circle->H * 1e6, ref.H * 1e6);
  EXPECT_EQ(s.circle->spec.plane, ctl::CirclePlane::xy);
  EXPECT_NEAR(s.circle->spec.radius, R, 1e-3);
  EXPECT_NEAR(s.circle->G_bidirectional, ref.G_bidirectional, 2e-6 + 0.02 * ref.G_bidirectional);
  const std::string html = ident::kinematic_compare_html(P, s, "circle");
  EXPECT_NE(html.find("<svg"), std::string::npos);
  const auto js = nlohmann::json::parse(ident::kinematic_summary_json(P, s, "m.yaml"));
  EXPECT_EQ(js["circle"]["G"].get<double>(), s.circle->G_bidirectional) << "the JSON reads back exactly";
  EXPECT_EQ(js["circle"]["plane"], cal::plane_name(ctl::CirclePlane::xy));
}

// The JSON contract of issue 4 for kinematic data.
TEST(KinematicReport, JsonContractAndHtml) {
  const io::BallbarData b = test::kim_ballbar({{"cyclic_error", 2, {3e-6, 0.02, 1.0}}}, ballbar_poses());
  const Diagnosis D = diagnose(b);
  const auto js = nlohmann::json::parse(ident::diagnosis_json(D));
  EXPECT_EQ(js["kind"], "ballbar");
  EXPECT_EQ(js["samples"], D.samples);
  EXPECT_EQ(js["units"], "m");
  EXPECT_EQ(js["baseline"]["rms"].get<double>(), D.baseline_rms);
  ASSERT_EQ(js["candidates"].size(), D.candidates.size());
  for (const char* key : {"rms_after", "explained", "significant"}) EXPECT_TRUE(js["candidates"][0].contains(key)) << key;
  EXPECT_EQ(js["verdict"]["missing"], "cyclic_error");
  EXPECT_EQ(js["verdict"]["axis"], 3);
  const std::string html = ident::diagnosis_html(D);
  EXPECT_NE(html.find("cyclic_error[axis 3]"), std::string::npos);
  EXPECT_NE(html.find("<svg"), std::string::npos);
}

}  // namespace
}  // namespace cpm
