// SPDX-License-Identifier: Apache-2.0
// Identification on simulated motion logs: the filter and statistics against
// closed forms, planted effects recovered (ranked first, parameters within
// 3 sigma, residual at the noise floor), no false alarms on clean data,
// confounding reported, bad input refused, and the loop closed in the
// controller. Seeds are fixed; CPM_IDENT_SEEDS=N runs a longer sweep.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdlib>
#include <numbers>
#include <random>
#include <sstream>

#include <nlohmann/json.hpp>

#include "cpm/identification/diagnose.hpp"
#include "cpm/identification/fit.hpp"
#include "cpm/identification/report.hpp"
#include "cpm/identification/stats.hpp"
#include "independent/matrix.hpp"
#include "sim_data.hpp"

namespace cpm::ident {
namespace {

int sweep_seeds(int ci_default) {
  const char* e = std::getenv("CPM_IDENT_SEEDS");
  return e ? std::max(1, std::atoi(e)) : ci_default;
}

TEST(SavitzkyGolay, ReproducesAQuarticAndItsDerivativesHalfASampleLater) {
  const double c[5] = {0.3, -1.2, 0.7, 0.05, -0.004};
  auto f = [&](double x) { return c[0] + c[1] * x + c[2] * x * x + c[3] * x * x * x + c[4] * x * x * x * x; };
  auto f1 = [&](double x) { return c[1] + 2 * c[2] * x + 3 * c[3] * x * x + 4 * c[4] * x * x * x; };
  auto f2 = [&](double x) { return 2 * c[2] + 6 * c[3] * x + 12 * c[4] * x * x; };
  for (double off : {0.0, 0.5}) {
    const SgKernel s = savitzky_golay(7, 4, 0, off), d1 = savitzky_golay(7, 4, 1, off),
                   d2 = savitzky_golay(7, 4, 2, off);
    std::vector<double> y;
    for (int j = -7; j <= 7; ++j) y.push_back(f(3.0 + j));
    EXPECT_NEAR(s.apply(&y[7]), f(3.0 + off), 1e-9);
    EXPECT_NEAR(d1.apply(&y[7]), f1(3.0 + off), 1e-9);
    EXPECT_NEAR(d2.apply(&y[7]), f2(3.0 + off), 1e-9);
  }
  // A smoother passes DC and a derivative kernel removes it.
  const SgKernel s = savitzky_golay(10, 4, 0);
  EXPECT_NEAR(s.response(0.0), 1.0, 1e-12);
  EXPECT_LT(s.response(0.45), 0.2);
}

// Under a zero-order hold (acceleration a_j constant over [t_j, t_j+1), the
// motion integrated exactly), the Savitzky-Golay acceleration estimate from
// the sampled velocities or positions equals the force kernel applied to the
// held accelerations, to rounding; and a force linear in time over the
// intervals is filtered alike by the state kernel from its samples.
TEST(ZeroOrderHoldKernels, TheAccelerationEstimateIsTheForceKernelOnTheHeldAccelerations) {
  const int m = 12, n = 200, k = 100;
  const double dt = 1e-3;
  std::mt19937_64 rng(5);
  std::uniform_real_distribution<double> u(-3.0, 3.0);
  std::vector<double> a(n), v(n + 1, 0.0), d(n + 1, 0.0);
  v[0] = 0.05;
  d[0] = 0.3;
  for (int j = 0; j < n; ++j) {
    a[j] = u(rng);
    v[j + 1] = v[j] + a[j] * dt;
    d[j + 1] = d[j] + v[j] * dt + 0.5 * a[j] * dt * dt;
  }
  for (int derivative : {1, 2}) {
    const SgKernel est = savitzky_golay(m, 4, derivative, 0.5);
    const SgKernel g = zoh_force_kernel(est, derivative);
    const double a_hat = derivative == 1 ? est.apply(&v[k]) / dt : est.apply(&d[k]) / (dt * dt);
    const double a_force = g.apply(&a[k]);
    EXPECT_NEAR(a_force, a_hat, 1e-9 * (1.0 + std::fabs(a_hat))) << "derivative " << derivative;
    double sum = 0.0;
    for (double x : g.h) sum += x;
    EXPECT_NEAR(sum, 1.0, 1e-12);  // a steady acceleration passes unchanged
    EXPECT_EQ(g.h.back(), 0.0);    // 2m intervals between 2m+1 samples
    // A force linear in time: its interval means are the means of the ends.
    const SgKernel st = zoh_state_kernel(g);
    std::vector<double> f_sample(n + 1), f_mean(n);
    for (int j = 0; j <= n; ++j) f_sample[j] = 1.7 - 0.9 * j * dt;
    for (int j = 0; j < n; ++j) f_mean[j] = 0.5 * (f_sample[j] + f_sample[j + 1]);
    EXPECT_NEAR(st.apply(&f_sample[k]), g.apply(&f_mean[k]), 1e-12);
  }
}

TEST(Statistics, FTailAndIncompleteBetaAgainstTables) {
  EXPECT_NEAR(f_tail(4.96, 1, 10), 0.05, 5e-4);     // F(1,10) 95 % point
  EXPECT_NEAR(f_tail(2.3053, 5, 100), 0.05, 1e-3);  // F(5,100)
  EXPECT_NEAR(incomplete_beta(2.0, 3.0, 0.4), 0.5248, 1e-4);
  EXPECT_NEAR(normal_tail(1.959964), 0.025, 1e-6);
  // Effective sample size of white noise is n, of a random walk much less.
  std::mt19937_64 rng(3);
  std::normal_distribution<double> n(0, 1);
  std::vector<double> w(2000), rw(2000);
  double acc = 0;
  for (int k = 0; k < 2000; ++k) { w[k] = n(rng); acc += n(rng); rw[k] = acc; }
  EXPECT_GT(effective_samples({w}), 1800.0);
  EXPECT_LT(effective_samples({rw}), 100.0);
}

struct Planted {
  const char* name;
  int axis;                  // 0..2, -1 machine-wide
  std::vector<double> shape; // parameters at amplitude 1 (the linear one scaled)
  int amp_index;             // which parameter is the amplitude (-1: all scale together)
  double unit_amplitude;     // about what noise hides (4 standard errors), found below
};

// inertia_error as the first links' centre of mass lying s further out than
// mid-length: B and C change by about s (m1 L1 / 2, m1 g), A and E not
// (docs/model.md: m1 = 1.892994 kg, L1 = 0.5 m). A mass error would change A
// and E in a payload's ratio, and the diagnosis rightly names the simpler
// payload_mass for it until the B and C parts are significant on their own.
constexpr double kM1 = 1.892994, kL1 = 0.5;
const std::vector<double> kLinkBalanceShape = {0.0, kM1 * kL1 / 2.0, kM1 * ctl::kGravity, 0.0};

// The shape of a planted effect as the robustness matrix has it (one
// implementation of planted values and amplitude standard errors).
indep::EffectShape shape_of(const Planted& pe) { return {pe.name, pe.axis >= 0, pe.shape, pe.amp_index}; }

std::vector<double> planted_values(const Planted& pe, double amplitude) {
  return indep::planted_values(shape_of(pe), amplitude);
}

// The noise floor of the identification: residual RMS of the TRUE machine
// (with its planted effect, plane errors and all) on the same log.
double true_model_rms(const io::MotionData& d, const test::SimSpec& s) {
  ctl::MachineModel tm = ctl::MachineModel::elkady();
  tm.kinematics = test::kim_sized_planes(s.seed * 7919 + 3);
  for (const auto& [name, axis, values] : s.effects) ctl::add_effect(tm, name, axis, values);
  return motion_rms(d, tm);
}

// Standard error of the effect's amplitude on effect-free data when its shape
// is known (independent/matrix.hpp): 4 of these are what noise alone could hide.
double amplitude_standard_error(const MotionProblem& P, const Engine& E, const Planted& pe) {
  return indep::amplitude_standard_error(P, E, shape_of(pe), pe.axis);
}

class PlantedEffect : public ::testing::TestWithParam<int> {};

TEST_P(PlantedEffect, AtThreeAndTenTimesTheNoiseItIsFirstOnTheRightAxisWithinThreeSigma) {
  std::vector<Planted> all = {
      {"viscous_friction", 0, {1.0}, 0, 0},
      {"coulomb_friction", 1, {1.0}, 0, 0},
      {"stribeck_friction", 2, {1.0, 0.02}, 0, 0},
      {"cogging", 0, {1.0, 0.012, 0.5}, 0, 0},
      {"spring", 1, {1.0, 0.2}, 0, 0},
      {"force_gain", 0, {1.0}, 0, 0},
      {"payload_mass", -1, {1.0}, 0, 0},
      {"inertia_error", -1, kLinkBalanceShape, -1, 0},
      {"actuator_inertia", 1, {1.0}, 0, 0},
  };
  const Planted& pe = all[static_cast<std::size_t>(GetParam())];
  const ctl::Machine nominal(ctl::MachineModel::elkady());
  for (int seed = 1; seed <= sweep_seeds(1); ++seed) {
    test::SimSpec s;
    s.duration = 16.0;
    s.seed = 100 + seed;
    // What noise hides: 4 standard errors of the amplitude on effect-free data.
    const io::MotionData clean = test::simulate(s);
    DiagnoseOptions o;
    o.structure_search = false;
    {
      const MotionProblem P = prepare_motion(clean, nominal);
      const Engine E(motion_linear_problem(P));
      all[static_cast<std::size_t>(GetParam())].unit_amplitude = 4.0 * amplitude_standard_error(P, E, pe);
    }
    const double unit = all[static_cast<std::size_t>(GetParam())].unit_amplitude;
    for (double times : {3.0, 10.0}) {
      test::SimSpec sp = s;
      const std::vector<double> v = planted_values(pe, times * unit);
      sp.effects = {{pe.name, pe.axis, v}};
      const io::MotionData d = test::simulate(sp);
      const Diagnosis D = diagnose_motion(d, nominal, o);
      SCOPED_TRACE(std::string(pe.name) + " x" + std::to_string(times) + " seed " + std::to_string(sp.seed) +
                   " amplitude " + std::to_string(times * unit) + "\n" + diagnosis_text(D));
      ASSERT_GE(D.verdict, 0);
      EXPECT_EQ(D.verdict, 0);
      // The planted effect is the verdict, or, where these data cannot tell it
      // from the verdict (a few grams of payload act as their weight only, what
      // a drive gain on z also is), named beside it as an alternative; then the
      // verdict must say it is ambiguous and the planted one is checked below.
      const CandidateResult* named = &D.candidates[static_cast<std::size_t>(D.verdict)];
      const std::string planted_label = pe.axis >= 0 ? std::string(pe.name) + "[axis " + std::to_string(pe.axis + 1) + "]"
                                                     : std::string(pe.name);
      if (named->label() != planted_label) {
        const auto& alt = named->alternatives;
        EXPECT_NE(std::find(alt.begin(), alt.end(), planted_label), alt.end()) << "planted " << planted_label;
        EXPECT_TRUE(D.ambiguous);
        for (const auto& x : D.candidates)
          if (x.label() == planted_label) named = &x;
      }
      const CandidateResult& c = *named;
      EXPECT_EQ(c.effect, pe.name);
      EXPECT_EQ(c.axis, pe.axis);
      if (c.effect == pe.name) {
        for (std::size_t j = 0; j < v.size(); ++j) {
          if (pe.name == std::string("cogging") && j == 2) {
            const double dphi = std::remainder(c.params[j].value - v[j], 2 * std::numbers::pi);
            EXPECT_LE(std::fabs(dphi), 3.0 * c.params[j].std_error + 1e-9) << c.params[j].name;
          } else if (c.params[j].std_error >= 0) {
            EXPECT_LE(std::fabs(c.params[j].value - v[j]), 3.0 * c.params[j].std_error) << c.params[j].name;
          }
        }
        std::printf("%s x%.0f seed %d: rank %s", pe.name, times, static_cast<int>(sp.seed), c.label().c_str());
        for (std::size_t j = 0; j < v.size(); ++j)
          std::printf(", %s %.4g -> %.4g +- %.2g (%.1f sigma)", c.params[j].name.c_str(), v[j], c.params[j].value,
                      c.params[j].std_error,
                      c.params[j].std_error > 0 ? std::fabs(c.params[j].value - v[j]) / c.params[j].std_error : 0.0);
        std::printf("; rms_after %.4f N = %.3f x floor\n", c.rms_after, c.rms_after / D.noise_floor);
        // Residual within 20 % of the noise floor: the true machine's own residual on the same log
        // (base refit included in both, as the diagnosis does).
        const double floor = D.noise_floor;
        EXPECT_LE(c.rms_after, 1.2 * floor) << "true-model RMS " << true_model_rms(d, sp);
      }
    }
  }
}

// Every dynamic effect of docs/effects.md: viscous, Coulomb, Stribeck, cogging,
// spring, force gain, payload, inertia error, actuator inertia.
INSTANTIATE_TEST_SUITE_P(DynamicLibrary, PlantedEffect, ::testing::Range(0, 9));

// A breakaway force of several newtons, far above the noise: the force's
// sharp change at each reversal must not bias the fit (with a smoother of
// its own on the force side, noise-free f_s came out 0.45 % low and, with
// noise, 1 % low: 3.7 standard errors).
TEST(StribeckFriction, SeveralNewtonsOfBreakawayAreFittedWithoutBias) {
  const ctl::Machine nominal(ctl::MachineModel::elkady());
  DiagnoseOptions o;
  o.structure_search = false;
  o.effects = {"stribeck_friction"};
  for (bool noise : {false, true}) {
    test::SimSpec s;
    s.duration = 16.0;
    s.seed = 101;
    if (!noise) s.position_noise = s.velocity_noise = 0.0;
    s.effects = {{"stribeck_friction", 2, {4.0, 0.02}}};
    const Diagnosis D = diagnose_motion(test::simulate(s), nominal, o);
    const CandidateResult* c = nullptr;
    for (const auto& x : D.candidates)
      if (x.label() == "stribeck_friction[axis 3]") c = &x;
    ASSERT_NE(c, nullptr);
    const double fs = c->params[0].value, vs = c->params[1].value;
    std::printf("noise %d: f_s 4 -> %.4f +- %.4f N (%+.2f %%), v_s 0.02 -> %.5f +- %.5f m/s\n", noise ? 1 : 0, fs,
                c->params[0].std_error, 100.0 * (fs / 4.0 - 1.0), vs, c->params[1].std_error);
    if (noise) {
      EXPECT_LE(std::fabs(fs - 4.0), 3.0 * c->params[0].std_error);
      EXPECT_LE(std::fabs(vs - 0.02), 3.0 * c->params[1].std_error);
    } else {  // what is left is second order in the motion within one kernel width
      EXPECT_LT(std::fabs(fs / 4.0 - 1.0), 0.0025);
      EXPECT_LT(std::fabs(vs / 0.02 - 1.0), 0.0025);
    }
  }
}

TEST(NoMissingEffect, VerdictIsNoneAtLeast95PercentOfSeeds) {
  const ctl::Machine nominal(ctl::MachineModel::elkady());
  const int n = sweep_seeds(20);
  int none = 0;
  DiagnoseOptions o;
  for (int seed = 1; seed <= n; ++seed) {
    test::SimSpec s;
    s.duration = 10.0;
    s.seed = 500 + seed;
    const Diagnosis D = diagnose_motion(test::simulate(s), nominal, o);
    if (D.verdict < 0) ++none;
    else std::printf("seed %d: %s\n", static_cast<int>(s.seed), D.verdict_text.c_str());
  }
  EXPECT_GE(none, static_cast<int>(std::ceil(0.95 * n)));
}

// A drive whose reported velocity is noisy (2 mm/s): the acceleration comes
// from the positions, whose second derivative is noisier still. The noise of
// that estimate must not reach the base columns (it would attenuate the
// inertia, and the force-gain column, which is clean, would then be named in
// its place: 20 false alarms in these 20 logs before the columns got their own,
// longer estimate).
TEST(NoMissingEffect, AccelerationFromThePositionsRaisesNoFalseAlarm) {
  const ctl::Machine nominal(ctl::MachineModel::elkady());
  const int n = sweep_seeds(20);
  int none = 0;
  for (int seed = 1; seed <= n; ++seed) {
    test::SimSpec s;
    s.duration = 10.0;
    s.seed = 600 + seed;
    s.velocity_noise = 2e-3;
    const Diagnosis D = diagnose_motion(test::simulate(s), nominal);
    ASSERT_NE(D.motion.accel_source.find("positions"), std::string::npos) << D.motion.accel_source;
    if (D.verdict < 0) ++none;
    else std::printf("seed %d: %s\n", static_cast<int>(s.seed), D.verdict_text.c_str());
  }
  EXPECT_GE(none, static_cast<int>(std::ceil(0.95 * n)));
}

// Encoders far quieter than the default (noise-free, or quantized at 1 µm or
// 0.1 µm): what the model's own approximations leave (plane offsets, the
// filtering of nonlinear terms; 4e-4 N after a 0.4 kg payload) must not be
// named as an effect, and a change of the base (payload, inertia error) must
// be named as such, not credited to whichever candidate also refits the base
// and mops up that leftover (before: a spring of 0.01 N/m or a Stribeck
// breakaway of 0.001 N "explained" a 2.28 N payload).
TEST(QuietEncoders, NeitherInventAnEffectNorCreditTheBaseToAnother) {
  const ctl::Machine nominal(ctl::MachineModel::elkady());
  struct Regime { const char* name; double position_noise, velocity_noise, resolution; };
  const Regime regimes[] = {{"noise-free", 0, 0, 0}, {"1 um steps", 0, 0, 1e-6}, {"0.1 um steps, 2e-4 m/s", 0, 2e-4, 1e-7}};
  const std::vector<std::tuple<std::string, int, std::vector<double>>> plants[] = {
      {}, {{"payload_mass", -1, {0.4}}}, {{"inertia_error", -1, {0.0, 0.02, 0.3, 0.0}}}, {{"coulomb_friction", 1, {1.0}}}};
  for (const auto& rg : regimes)
    for (const auto& pl : plants) {
      test::SimSpec s;
      s.duration = 10.0;
      s.seed = 701;
      s.position_noise = rg.position_noise;
      s.velocity_noise = rg.velocity_noise;
      s.resolution = rg.resolution;
      s.effects = pl;
      const Diagnosis D = diagnose_motion(test::simulate(s), nominal);
      const std::string planted =
          pl.empty() ? "none"
                     : std::get<0>(pl[0]) + (std::get<1>(pl[0]) >= 0 ? "[axis " + std::to_string(std::get<1>(pl[0]) + 1) + "]" : "");
      const std::string got = D.verdict >= 0 ? D.candidates[static_cast<std::size_t>(D.verdict)].label() : "none";
      EXPECT_EQ(got, planted) << rg.name << ": " << D.verdict_text;
    }
}

// A drive gain on z, the axis that carries the weight: its column is 99.8 %
// the weight, which the base's E also explains, but the rest (the gain on z's
// inertia alone) measures it. At 3 % it is named on axis 3 (before, with
// columns over 99.5 % in the base span refused, the base smeared it into A on
// every axis and force_gain[axis 2] was named); at 1 % it is mostly "the
// weight is off", which a payload is too: the verdict says it cannot tell.
TEST(Confounding, ADriveGainOnTheWeightBearingAxisIsNamedOrSaidToBeAPayloadsTwin) {
  const ctl::Machine nominal(ctl::MachineModel::elkady());
  test::SimSpec s;
  s.duration = 16.0;
  s.seed = 301;
  s.effects = {{"force_gain", 2, {0.03}}};
  const Diagnosis D = diagnose_motion(test::simulate(s), nominal);
  ASSERT_GE(D.verdict, 0) << D.verdict_text;
  const CandidateResult& v = D.candidates[static_cast<std::size_t>(D.verdict)];
  EXPECT_EQ(v.label(), "force_gain[axis 3]") << D.verdict_text;
  EXPECT_LE(std::fabs(v.params[0].value - 0.03), 3.0 * v.params[0].std_error) << v.params[0].value;
  s.effects = {{"force_gain", 2, {0.01}}};
  const Diagnosis S = diagnose_motion(test::simulate(s), nominal);
  ASSERT_GE(S.verdict, 0) << S.verdict_text;
  const std::string named = S.candidates[static_cast<std::size_t>(S.verdict)].label();
  if (named != "force_gain[axis 3]") {
    EXPECT_TRUE(named == "payload_mass" || named == "inertia_error") << S.verdict_text;
    EXPECT_TRUE(S.ambiguous) << S.verdict_text;
    EXPECT_NE(S.verdict_text.find("force_gain[axis 3]"), std::string::npos) << S.verdict_text;
    EXPECT_NE(S.verdict_text.find("accelerate the other axes harder"), std::string::npos) << S.verdict_text;
  }
}

TEST(Confounding, ViscousAgainstCoulombAtOneSpeedIsReportedWithTheMeasurementThatSeparatesThem) {
  // Axis 1 sweeps back and forth at one constant speed: b v and f_c sgn(v) are the same column.
  struct Shuttle final : ctl::Trajectory {
    double T = 12.0, v = 0.08, A = 0.1;
    [[nodiscard]] double duration() const noexcept override { return T; }
    [[nodiscard]] ctl::TrajectorySample sample(double t) const noexcept override {
      // Triangle wave in x smoothed at the turns (short quintic blends), constant |v| elsewhere.
      ctl::TrajectorySample s;
      s.p = Vec3(0.425, 0.425, 0.36);
      const double period = 4.0 * A / v, ph = std::fmod(std::max(0.0, t), period) / period;
      const double tri = ph < 0.5 ? -A + 4 * A * ph : 3 * A - 4 * A * ph;
      const double slope = ph < 0.5 ? v : -v;
      const double ramp = std::min(1.0, t / 0.5);
      s.p.x() += ramp * tri;
      s.v.x() = t < 0.5 ? 0.0 : slope;
      return s;
    }
  } shuttle;
  test::SimSpec s;
  s.seed = 77;
  s.trajectory = &shuttle;
  s.effects = {{"coulomb_friction", 0, {0.8}}};
  const io::MotionData d = test::simulate(s);
  const Diagnosis D = diagnose_motion(d, ctl::Machine(ctl::MachineModel::elkady()));
  SCOPED_TRACE(diagnosis_text(D));
  bool reported = false;
  for (const auto& c : D.candidates)
    if (c.label() == "coulomb_friction[axis 1]")
      for (const auto& cf : c.confounded)
        if (cf.with == "viscous_friction[axis 1]" || cf.with == "stribeck_friction[axis 1]")
          reported |= cf.separate_by.find("another feed") != std::string::npos;
  EXPECT_TRUE(reported);
}

TEST(BadInput, KindsThatCannotShowAnEffectAndTooFewSamplesAreRefusedClearly) {
  try {
    check_effect_for_kind("backlash", "motion");
    ADD_FAILURE();
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("kinematic effect"), std::string::npos) << e.what();
  }
  EXPECT_THROW(check_effect_for_kind("coulomb_friction", "ballbar"), Error);
  EXPECT_THROW(check_effect_for_kind("friction", "motion"), Error);
  EXPECT_THROW(parse_fit_request("coulomb_friction"), Error);   // needs an axis
  EXPECT_THROW(parse_fit_request("payload_mass:2"), Error);     // takes none
  test::SimSpec s;
  s.duration = 0.12;
  const io::MotionData shortlog = test::simulate(s);
  try {
    diagnose_motion(shortlog, ctl::Machine(ctl::MachineModel::elkady()));
    ADD_FAILURE();
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("too few samples"), std::string::npos) << e.what();
  }
  // An effect on an axis that does not move: fit refuses instead of returning a wild number.
  ctl::CircleSpec cs;
  cs.ramp_time = 0.5;
  cs.cruise_time = 4.0;
  const ctl::CircleTrajectory xy(cs);  // z stays put
  test::SimSpec s2;
  s2.trajectory = &xy;
  const io::MotionData flat = test::simulate(s2);
  try {
    fit_motion(flat, ctl::MachineModel::elkady(), {parse_fit_request("cogging:3")});
    ADD_FAILURE();
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("axis 3"), std::string::npos) << e.what();
  }
}

TEST(ClosedLoop, FittingThePlantedEffectMakesTheControllerTrackTheCircleBetter) {
  // Point 6(a): truth with Coulomb friction on axis 2; the nominal controller
  // tracks a circle, the log is diagnosed and fitted, the controller with the
  // new model tracks the same circle better.
  ctl::CircleSpec cs;
  cs.ramp_time = 0.5;
  cs.cruise_time = 8.0;
  const ctl::CircleTrajectory circle(cs);
  test::SimSpec s;
  s.seed = 11;
  s.base_errors = false;  // kinematics calibrated: the tracking error is then the dynamics'
  s.trajectory = &circle;
  s.effects = {{"coulomb_friction", 1, {2.0}}};
  sim::RunResult before, after;
  const io::MotionData log = test::simulate(s, &before);
  const Diagnosis D = diagnose_motion(log, ctl::Machine(ctl::MachineModel::elkady()));
  ASSERT_GE(D.verdict, 0) << diagnosis_text(D);
  const CandidateResult& v = D.candidates[static_cast<std::size_t>(D.verdict)];
  EXPECT_EQ(v.label(), "coulomb_friction[axis 2]");
  const FitResult F = fit_motion(log, ctl::MachineModel::elkady(), {{v.effect, v.axis}});
  EXPECT_LT(F.on_fit.after, 0.5 * F.on_fit.before);
  ASSERT_TRUE(F.cross_validation.has_value());
  EXPECT_LT(F.cross_validation->after, 0.5 * F.cross_validation->before);
  test::simulate(s, &after, F.model);
  std::ostringstream fitted;  // (a string built with += trips GCC 12's -Wrestrict false positive)
  for (const auto& e : F.model.effects) {
    fitted << e.label() << ":";
    for (double p : e.param) fitted << " " << p;
    fitted << "\n";
  }
  EXPECT_LT(after.metrics.position_rmse, 0.7 * before.metrics.position_rmse)
      << "before " << before.metrics.position_rmse << " after " << after.metrics.position_rmse << "\n" << fitted.str();
}

// The paper's circle (175 mm at 1.57 rad/s) on a machine whose axis 2
// carries 5 kg of reflected rotor inertia: the computed-torque controller with
// actuator_inertia in its model tracks better than the nominal one and, on the
// circle entered by a 0.5 s speed ramp, as well as on a machine without the
// rotor. Elkady's abrupt start (the reference at full speed while the machine
// is at rest) saturates the drives and dominates that RMS. The figures are
// printed for docs/effects.md.
TEST(ClosedLoop, ActuatorInertiaInTheModelTracksThePapersCircleBetter) {
  ctl::MachineModel knows = ctl::MachineModel::elkady();
  ctl::add_effect(knows, "actuator_inertia", 1, {5.0});
  for (double ramp : {0.0, 0.5}) {
    ctl::CircleSpec cs;
    cs.ramp_time = ramp;
    const ctl::CircleTrajectory circle(cs);
    test::SimSpec s;
    s.seed = 12;
    s.base_errors = false;  // kinematics calibrated: the tracking error is then the dynamics'
    s.trajectory = &circle;
    sim::RunResult no_rotor, without, with;
    test::simulate(s, &no_rotor);
    s.effects = {{"actuator_inertia", 1, {5.0}}};
    test::simulate(s, &without);
    test::simulate(s, &with, knows);
    std::printf("circle (ramp %.1f s), truth actuator_inertia[axis 2] = 5 kg: position RMS %.2f um with it in the "
                "model, %.2f um without it; %.2f um on a machine without the rotor\n",
                ramp, with.metrics.position_rmse * 1e6, without.metrics.position_rmse * 1e6,
                no_rotor.metrics.position_rmse * 1e6);
    if (ramp > 0.0) {
      // Unsaturated: the model with the rotor cancels it, the nominal one leaves 5 kg x the circle's 0.43 m/s^2.
      EXPECT_LT(std::fabs(with.metrics.position_rmse - no_rotor.metrics.position_rmse),
                0.02 * no_rotor.metrics.position_rmse);
      EXPECT_GT(without.metrics.position_rmse, 10.0 * with.metrics.position_rmse);
    } else {
      // The abrupt start saturates the drives (120 N): a heavier axis 2 takes longer to catch the
      // reference whatever the model, so only "better than without" holds.
      EXPECT_GT(without.metrics.position_rmse, 1.1 * with.metrics.position_rmse);
    }
  }
}

// Must show (issue 4): Coulomb friction against a force-gain error when the
// velocity never changes sign. Axis 1 creeps one way at a varying speed
// (y, z do a Lissajous): a constant force on it is what a tilted plane puts
// into the weight, and a force gain can imitate it; the diagnosis must say
// it cannot tell (ambiguous, with "both directions"), not guess.
TEST(Confounding, CoulombAgainstForceGainWithOneDirectionIsAmbiguous) {
  struct Creep final : ctl::Trajectory {
    test::Lissajous base{12.0};
    [[nodiscard]] double duration() const noexcept override { return 12.0; }
    [[nodiscard]] ctl::TrajectorySample sample(double t) const noexcept override {
      ctl::TrajectorySample s = base.sample(t);
      const double tc = std::clamp(t, 0.0, 12.0);
      // v = r(t) (0.018 + 0.009 cos 1.5t), r = min(1, t): never below 0.009 m/s after the start.
      auto x_of = [](double u) {
        const double w = 1.5;
        if (u < 1.0) return 0.009 * u * u + 0.009 * (u * std::sin(w * u) / w + (std::cos(w * u) - 1.0) / (w * w));
        const double x1 = 0.009 + 0.009 * (std::sin(w) / w + (std::cos(w) - 1.0) / (w * w));
        return x1 + 0.018 * (u - 1.0) + 0.006 * (std::sin(w * u) - std::sin(w));
      };
      const double r = std::min(1.0, tc), dr = tc < 1.0 ? 1.0 : 0.0;
      s.p.x() = 0.30 + x_of(tc);
      s.v.x() = t > 12.0 ? 0.0 : r * (0.018 + 0.009 * std::cos(1.5 * tc));
      s.a.x() = t > 12.0 ? 0.0 : dr * (0.018 + 0.009 * std::cos(1.5 * tc)) - r * 0.0135 * std::sin(1.5 * tc);
      return s;
    }
  } creep;
  test::SimSpec s;
  s.seed = 91;
  s.trajectory = &creep;
  s.effects = {{"coulomb_friction", 0, {2.0}}};
  const io::MotionData d = test::simulate(s);
  double vmin = 1e9;
  for (std::size_t k = 1500; k + 1500 < d.v.size(); ++k) vmin = std::min(vmin, d.v[k][0]);
  const Diagnosis D = diagnose_motion(d, ctl::Machine(ctl::MachineModel::elkady()));
  SCOPED_TRACE(diagnosis_text(D));
  std::printf("min v1 %.4f m/s; verdict: %s (ambiguous %d)\n", vmin, D.verdict_text.c_str(), D.ambiguous ? 1 : 0);
  EXPECT_GT(vmin, 0.0);
  ASSERT_GE(D.verdict, 0);
  EXPECT_TRUE(D.ambiguous);
  EXPECT_NE(D.verdict_text.find("coulomb_friction[axis 1]"), std::string::npos);
  EXPECT_NE(D.verdict_text.find("force_gain[axis 1]"), std::string::npos);
  EXPECT_NE(D.verdict_text.find("move axis 1 in both directions"), std::string::npos);
  EXPECT_EQ(nlohmann::json::parse(diagnosis_json(D))["verdict"]["ambiguous"], true);
}

}  // namespace
}  // namespace cpm::ident
