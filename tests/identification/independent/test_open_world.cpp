// SPDX-License-Identifier: Apache-2.0
// The open world on logs of the independent generator: the honest noise floor
// against the residual of the true model, a force outside the library found on
// its axis and variable, the two defects of issue 26 (an effect fitted to 0
// named as missing; the loop stopping at a small structure beside a library
// effect that explains most).
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>

#include "cpm/identification/fit.hpp"
#include "cpm/identification/model_loop.hpp"
#include "cpm/io/model_file.hpp"
#include "generator.hpp"
#include "matrix.hpp"

namespace cpm::indep {
namespace {

// The largest speed an axis reaches on a log (m/s), as the generator made it.
double peak_speed(const GeneratedLog& g, int axis) {
  double vmax = 0.0;
  for (const Vec3& v : g.v_true) vmax = std::max(vmax, std::fabs(v[axis]));
  return vmax;
}

GeneratorSpec spec(Timing t, NoisePlacement n, std::uint64_t seed) {
  GeneratorSpec s;
  s.timing = t;
  s.noise = n;
  s.rate = 1000.0;
  s.duration = 15.0;
  s.seed = seed;
  return s;
}

ident::Diagnosis diagnose(const GeneratedLog& g) {
  return ident::diagnose_motion(g.log, ctl::Machine(ctl::MachineModel::elkady()));
}

double rms3(const Vec3& v) { return std::sqrt(v.squaredNorm() / 3.0); }

// The floor from the residual's high band agrees with the residual RMS of the
// true model (the nominal model plus what was planted), on null logs and on
// logs with an effect the model lacks, where the residual RMS is far above it.
TEST(OpenWorld, HonestFloorIsTheTrueModelsResidual) {
  for (NoisePlacement n : {NoisePlacement::plant, NoisePlacement::command})
    for (std::uint64_t seed : {3u, 4u}) {
      GeneratorSpec s = spec(Timing::zoh, n, seed);
      for (bool planted : {false, true}) {
        s.effects.clear();
        if (planted) s.effects = {{"viscous_friction", 1, {8.0}}};
        const GeneratedLog g = generate(s);
        const ident::Diagnosis D = diagnose(g);
        const double truth = ident::motion_rms(g.log, true_model(s.effects));
        const double given = ident::motion_rms(g.log, ctl::MachineModel::elkady());
        const double floor = rms3(D.axis_floor);
        std::printf("%s seed %d %s: floor %.4f N, true model %.4f N (%.3f), model as given %.4f N\n", noise_name(n),
                    static_cast<int>(seed), planted ? "viscous 8 N s/m on axis 2" : "null", floor, truth,
                    floor / truth, given);
        EXPECT_NEAR(floor / truth, 1.0, 0.05);
        if (planted) {
          EXPECT_GT(given, 3.0 * truth);
        }
        EXPECT_FALSE(D.noise_floor_source.empty());
      }
    }
}

// A cable carrier: a force on axis 2 that follows axis 1's velocity, at 10x
// the floor: outside_library on axis 2 following v1, no library effect named.
TEST(OpenWorld, CableCarrierIsOutsideTheLibraryOnItsAxisAndVariable) {
  GeneratorSpec s = spec(Timing::zoh, NoisePlacement::plant, 5);
  const GeneratedLog g0 = generate(s);
  const ident::Diagnosis D0 = diagnose(g0);
  const double vmax = peak_speed(g0, 0);
  const double c = 10.0 * D0.axis_floor[1] / vmax;
  s.outside = {{OutsideForce::Kind::cross_velocity, 1, 0, c, 0.0, 1.0}};
  const ident::Diagnosis D = diagnose(generate(s));
  std::printf("verdict: %s\n", D.verdict_text.c_str());
  for (const auto& f : D.structure) std::printf("  structure left: %s (%.1f sigma)\n", f.text.c_str(), f.z);
  ASSERT_FALSE(D.outside_library.empty());
  const ident::StructureFinding& f = D.outside_library.front();
  EXPECT_EQ(f.axis, 1);
  EXPECT_EQ(f.coordinate, "v1");
  EXPECT_EQ(f.shape, "linear");
  EXPECT_NEAR(f.slope, c, 0.15 * c);
  EXPECT_EQ(D.verdict, -1) << D.candidates[0].label();
}

// A tight spot over a short stretch of axis 3 (a Gaussian bump, 1/30 of the
// travel wide, 10x the floor at its peak): outside_library on axis 3 around
// the bump's place, no library effect named.
TEST(OpenWorld, LocalBumpLeadsOnItsAxisAndPlace) {
  GeneratorSpec s = spec(Timing::zoh, NoisePlacement::plant, 8);
  const GeneratedLog g0 = generate(s);
  const ident::Diagnosis D0 = diagnose(g0);
  const double lo = g0.d_min[2], hi = g0.d_max[2], centre = lo + (hi - lo) / 3.0;
  s.outside = {{OutsideForce::Kind::bump, 2, -1, 10.0 * D0.axis_floor[2], centre, (hi - lo) / 30.0}};
  const ident::Diagnosis D = diagnose(generate(s));
  std::printf("bump at %.1f mm: %s\n", centre * 1e3, D.verdict_text.c_str());
  for (const auto& f : D.structure) std::printf("  structure left: %s (%.1f sigma)\n", f.text.c_str(), f.z);
  ASSERT_FALSE(D.outside_library.empty());
  EXPECT_EQ(D.outside_library.front().axis, 2);
  EXPECT_NEAR(D.outside_library.front().location, centre, (hi - lo) / 15.0);
  EXPECT_EQ(D.verdict, -1) << D.candidates[0].label();
  // What the library made of it before the bump was fitted is said as partial.
  EXPECT_FALSE(D.partial.empty());
}

// A bump at 3x the floor under command noise, whose flank the scan also sees
// as a step: both beat the library on the model as given, and the check that
// each stays with the other fitted looked for the bump behind the step, lost
// it with the step, and left cogging and a spring to take the axis (the
// open-world matrix's seed 2, axis 1, zoh/command at 1000 Hz).
TEST(OpenWorld, BumpSeenAlsoAsAStepIsKept) {
  GeneratorSpec s = spec(Timing::zoh, NoisePlacement::command, 2 * 7919 + 17);
  const GeneratedLog g0 = generate(s);
  const ident::Diagnosis D0 = diagnose(g0);
  const double lo = g0.d_min[0], hi = g0.d_max[0], centre = lo + (hi - lo) / 3.0;
  s.outside = {{OutsideForce::Kind::bump, 0, -1, 3.0 * D0.axis_floor[0], centre, (hi - lo) / 30.0}};
  const ident::Diagnosis D = diagnose(generate(s));
  std::printf("bump of %.3f N at %.1f mm: %s\n", 3.0 * D0.axis_floor[0], centre * 1e3, D.verdict_text.c_str());
  ASSERT_FALSE(D.outside_library.empty());
  EXPECT_EQ(D.outside_library.front().kind, "bump");
  EXPECT_EQ(D.outside_library.front().axis, 0);
  EXPECT_NEAR(D.outside_library.front().location, centre, (hi - lo) / 15.0);
  EXPECT_EQ(D.verdict, -1) << D.candidates[static_cast<std::size_t>(std::max(D.verdict, 0))].label();
}

// A 10x bump at 250 Hz pulls the alignment of a zero-order hold to half a
// period when it is left out of it; what the misalignment left was named
// viscous friction (on axis 2, beside a bump on axis 1). The alignment is
// redone with the outside finding fitted beside it.
TEST(OpenWorld, BumpDoesNotPullTheAlignment) {
  GeneratorSpec s = spec(Timing::zoh, NoisePlacement::command, 2 * 7919 + 17);
  s.rate = 250.0;
  const GeneratedLog g0 = generate(s);
  const ident::Diagnosis D0 = diagnose(g0);
  const double lo = g0.d_min[0], hi = g0.d_max[0], centre = lo + (hi - lo) / 3.0;
  s.outside = {{OutsideForce::Kind::bump, 0, -1, 10.0 * D0.axis_floor[0], centre, (hi - lo) / 30.0}};
  const ident::Diagnosis D = diagnose(generate(s));
  std::printf("alignment %.3f periods (null log %.3f): %s\n", D.alignment.tau / D.alignment.period,
              D0.alignment.tau / D0.alignment.period, D.verdict_text.c_str());
  ASSERT_FALSE(D.outside_library.empty());
  EXPECT_EQ(D.outside_library.front().axis, 0);
  EXPECT_EQ(D.verdict, -1) << D.candidates[static_cast<std::size_t>(std::max(D.verdict, 0))].label();
  // Zero-order hold: 0; within a quarter period as on the null log.
  EXPECT_LT(std::fabs(D.alignment.tau), 0.25 * D.alignment.period);
}

// Defect (a): Coulomb and Stribeck friction together on the vertical axis
// behind a one-period delay. No effect fitted to 0 (at its bound 0) may be
// named as missing.
TEST(OpenWorld, NoEffectFittedToZeroIsNamedMissing) {
  for (NoisePlacement n : {NoisePlacement::plant, NoisePlacement::command}) {
    GeneratorSpec s = spec(Timing::delay1, n, 2);
    s.effects = {{"coulomb_friction", 2, {3.0}}, {"stribeck_friction", 2, {4.0, 0.02}}};
    const ident::Diagnosis D = diagnose(generate(s));
    std::printf("%s: %s\n", noise_name(n), D.verdict_text.c_str());
    for (int j : D.found()) {
      const ident::CandidateResult& c = D.candidates[static_cast<std::size_t>(j)];
      ASSERT_FALSE(c.params.empty());
      EXPECT_FALSE(c.params[0].value == 0.0) << c.label() << " named with value 0";
      EXPECT_FALSE(c.params[0].at_bound && std::fabs(c.params[0].value) < 1e-12) << c.label();
    }
  }
}

// Defect (a), the pair itself: Coulomb and Stribeck friction together on the
// vertical axis behind a one-period delay, at sizes like the issue's. Both are
// named on axis 3 within 10 % (or 3 standard errors) of what was planted,
// nothing else is named (the delay, when named, at one period), the alignment
// is at one period, and the residual left is the true model's (nominal +
// planted + the delay). Where the true model itself reaches the floor (2 N at
// 10 mm/s), the axis-3 residual is within 20 % of it; at 4 N and 20 mm/s the
// rows slower than 5 mm/s leave 3x the floor under the true model too (the
// friction columns' error at reversals, "Stick-slip" in the docs), so there
// the true model's residual is the bar.
TEST(OpenWorld, CoulombAndStribeckTogetherAreBothNamed) {
  struct Pair {
    double fc, fs, vs;
    bool floor_reachable;
  };
  for (const Pair& p : {Pair{3.0, 4.0, 0.02, false}, Pair{3.0, 2.0, 0.01, true}})
    for (NoisePlacement n : {NoisePlacement::plant, NoisePlacement::command}) {
      GeneratorSpec s = spec(Timing::delay1, n, 2);
      s.effects = {{"coulomb_friction", 2, {p.fc}}, {"stribeck_friction", 2, {p.fs, p.vs}}};
      const GeneratedLog g = generate(s);
      const ident::Diagnosis D = diagnose(g);
      std::printf("Coulomb %.1f N + Stribeck %.1f N at %.0f mm/s, %s: %s\n", p.fc, p.fs, p.vs * 1e3, noise_name(n),
                  D.verdict_text.c_str());
      const double T = D.alignment.period;
      auto near = [](const ident::ParamEstimate& q, double truth) {
        return std::fabs(q.value - truth) <= std::max(0.1 * truth, 3.0 * q.std_error);
      };
      bool coulomb = false, stribeck = false;
      for (int j : D.found()) {
        const ident::CandidateResult& c = D.candidates[static_cast<std::size_t>(j)];
        ASSERT_FALSE(c.params.empty()) << c.label();
        if (c.effect == "coulomb_friction" && c.axis == 2) {
          coulomb = true;
          EXPECT_TRUE(near(c.params[0], p.fc)) << c.label() << " f_c " << c.params[0].value;
        } else if (c.effect == "stribeck_friction" && c.axis == 2) {
          stribeck = true;
          ASSERT_EQ(c.params.size(), 2u);
          EXPECT_TRUE(near(c.params[0], p.fs)) << c.label() << " f_s " << c.params[0].value;
          EXPECT_TRUE(near(c.params[1], p.vs)) << c.label() << " v_s " << c.params[1].value;
        } else if (c.effect == "actuation_delay") {
          EXPECT_NEAR(c.params[0].value, T, std::max(0.15 * T, 3.0 * c.params[0].std_error));
        } else {
          ADD_FAILURE() << "named beside the pair: " << c.label();
        }
      }
      EXPECT_TRUE(coulomb && stribeck) << D.verdict_text;
      EXPECT_TRUE(D.outside_library.empty()) << D.outside_library.front().text;
      EXPECT_NEAR(D.alignment.tau, T, std::max(0.15 * T, 3.0 * D.alignment.std_error));
      std::vector<PlantedEffect> truth_effects = s.effects;
      truth_effects.push_back({"actuation_delay", -1, {T}});
      const double truth = ident::motion_rms(g.log, true_model(truth_effects));
      std::printf("  residual %.4f N (true model %.4f N); axis 3: %.4f N, floor %.4f N (%.2f x)\n",
                  rms3(D.axis_residual_rms), truth, D.axis_residual_rms[2], D.axis_floor[2],
                  D.axis_residual_rms[2] / D.axis_floor[2]);
      EXPECT_LT(rms3(D.axis_residual_rms), 1.02 * truth);
      if (p.floor_reachable) {
        EXPECT_LT(D.axis_residual_rms[2], 1.2 * D.axis_floor[2]);
      }
    }
}

// Defect (b) and issue 28 point 4: cogging that explains most of the residual
// beside a small force outside the library: the loop adds the cogging first,
// then stops at the outside finding and offers it as a user effect.
TEST(OpenWorld, LoopAddsTheLibraryEffectBeforeStoppingAtTheOutsideFinding) {
  GeneratorSpec s = spec(Timing::zoh, NoisePlacement::plant, 6);
  const GeneratedLog g0 = generate(s);
  const ident::Diagnosis D0 = diagnose(g0);
  const double vmax = peak_speed(g0, 1);
  const double c = 6.0 * D0.axis_floor[0] / vmax;
  s.effects = {{"cogging", 0, {1.5, 0.012, 0.5}}};
  s.outside = {{OutsideForce::Kind::cross_velocity, 0, 1, c, 0.0, 1.0}};
  const GeneratedLog g = generate(s);
  const ident::LoopResult R = ident::run_loop(g.log, ctl::MachineModel::elkady());
  std::printf("%s", ident::loop_text(R).c_str());
  ASSERT_GE(R.steps.size(), 2u) << R.stop;
  ASSERT_FALSE(R.added.empty());
  EXPECT_EQ(R.added.front().effect, "cogging");
  EXPECT_EQ(R.added.front().axis, 0);
  EXPECT_TRUE(R.outside_library) << R.stop;
  EXPECT_EQ(R.suggestion.kind, "expression");
  EXPECT_EQ(R.suggestion.axis, 0);
  EXPECT_EQ(R.suggestion.formula, "c*v2");
  ASSERT_EQ(R.suggestion.params.size(), 1u);
  EXPECT_NEAR(R.suggestion.params[0].second, c, 0.2 * c);
}

// The user's loop in the open world on a log of this generator: cogging on
// axis 1 (the library) and a tight spot on axis 3 at 10x its floor (outside
// it). The loop names the cogging, offers the bump as a table effect over d3,
// and, allowed to add tables, adds it, fits it and ends within 20 % of the
// noise floor; the model file with the table reads back equal.
TEST(OpenWorld, LoopAddsTheBumpAsATableDownToTheNoiseFloor) {
  GeneratorSpec s = spec(Timing::zoh, NoisePlacement::plant, 8);
  const GeneratedLog g0 = generate(s);
  const ident::Diagnosis D0 = diagnose(g0);
  const double lo = g0.d_min[2], hi = g0.d_max[2], centre = lo + (hi - lo) / 3.0;
  s.effects = {{"cogging", 0, {1.5, 0.012, 0.5}}};
  s.outside = {{OutsideForce::Kind::bump, 2, -1, 10.0 * D0.axis_floor[2], centre, (hi - lo) / 30.0}};
  const GeneratedLog g = generate(s);
  const ident::LoopResult R = ident::run_loop(g.log, ctl::MachineModel::elkady(), {}, 6, {"table"});
  std::printf("%s", ident::loop_text(R).c_str());
  ASSERT_FALSE(R.added.empty()) << R.stop;
  EXPECT_EQ(R.added.front().effect, "cogging");
  EXPECT_EQ(R.added.front().axis, 0);
  ASSERT_EQ(R.user_added.size(), 1u) << R.stop;
  EXPECT_EQ(R.user_added.front().kind, "table");
  EXPECT_EQ(R.user_added.front().axis, 2);
  EXPECT_EQ(R.user_added.front().input, "d3");
  ASSERT_EQ(R.model.user_effects.size(), 1u);
  ASSERT_GE(R.steps.size(), 3u);
  for (std::size_t j = 1; j < R.steps.size(); ++j) EXPECT_LT(R.steps[j].rms, R.steps[j - 1].rms) << j;
  std::printf("final RMS %.4f N, floor %.4f N (%.3f x)\n", R.steps.back().rms, R.steps.back().noise_floor,
              R.steps.back().rms / R.steps.back().noise_floor);
  EXPECT_LE(R.steps.back().rms, 1.2 * R.steps.back().noise_floor);
  io::ModelFile mf;
  mf.model = R.model;
  const io::ModelFile back = io::parse_model_file(io::render_model_file(mf), "out.yaml");
  EXPECT_EQ(back.model.user_effects, R.model.user_effects);
}

// A force of axis 1's own speed that peaks at low speed and dies away above
// (c v1 exp(-(v1/w)^2) on the project's own simulator, planted as an
// expression), on a circle: there d2 - centre = v1 / w, so the scan may lead
// with d2 or v1, and the other must be listed alike. Before, the lead was d2
// "seen alike in d1 d3", and beside it the verdict named spring[axis 1]
// (-25 N/m at its rest-position bound) and actuator_inertia[axis 1] (-4.3 kg)
// as missing, with a -90 % drive gain.
GeneratorSpec hump_on_a_circle(double size) {
  GeneratorSpec s = spec(Timing::zoh, NoisePlacement::plant, 7);
  s.circle_radius = 0.1;
  s.circle_omega = 1.5;  // rad/s: |v| up to 0.15 m/s
  if (size > 0.0) s.outside = {{OutsideForce::Kind::velocity_hump, 0, -1, size, 0.0, 0.15 / 8.0}};
  return s;
}

const ident::AlikeVariable* alike(const ident::StructureFinding& f, const std::string& var) {
  for (const auto& a : f.alike)
    if (a.var == var) return &a;
  return nullptr;
}

// On the generator's own path (three sines per axis; the circle, where the
// delay is not determined, below).
TEST(OpenWorld, HumpInItsOwnSpeedNamesNoLibraryEffect) {
  GeneratorSpec s = spec(Timing::zoh, NoisePlacement::plant, 7);
  const GeneratedLog g0 = generate(s);
  const ident::Diagnosis D0 = diagnose(g0);
  const double vmax = peak_speed(g0, 0);
  s.outside = {{OutsideForce::Kind::velocity_hump, 0, -1, 15.0 * D0.axis_floor[0], 0.0, vmax / 8.0}};
  const ident::Diagnosis D = diagnose(generate(s));
  std::printf("hump: %s\n", D.verdict_text.c_str());
  ASSERT_FALSE(D.outside_library.empty());
  const ident::StructureFinding& f = D.outside_library.front();
  EXPECT_EQ(f.axis, 0);
  const bool v1 = f.coordinate == "v1" || alike(f, "v1");
  EXPECT_TRUE(v1) << f.text;
  // Nothing of the library named as missing beside it; what was fitted to an
  // unphysical value is said as partial, with why.
  EXPECT_TRUE(D.found().empty()) << D.verdict_text;
  for (const auto& u : D.partial_unphysical) EXPECT_FALSE(u.why.empty()) << u.label();
  EXPECT_NE(D.verdict_text.find("To settle it"), std::string::npos);
  EXPECT_TRUE(D0.outside_library.empty()) << D0.verdict_text;
  EXPECT_TRUE(D0.found().empty()) << D0.verdict_text;
}

// A clean zoh log on the one-frequency circle: there a delay is one column
// with the phase of the zoh's half period (and with a spring or an inertia),
// so the data cannot name one. Before, the verdict was "actuation_delay
// ~6 ms"; it must be none, or say the delay is not determined.
TEST(OpenWorld, NullCircleNamesNoDelay) {
  const ident::Diagnosis D = diagnose(generate(hump_on_a_circle(0.0)));
  std::printf("null circle: %s\n", D.verdict_text.c_str());
  EXPECT_TRUE(D.found().empty()) << D.verdict_text;
  EXPECT_TRUE(D.outside_library.empty()) << D.verdict_text;
}

// The 15x hump of its own speed on the same circle: with the false delay it
// was not found; at the model's own alignment it leads on axis 1.
TEST(OpenWorld, HumpOnTheCircleIsFoundOnItsAxis) {
  const ident::Diagnosis D0 = diagnose(generate(hump_on_a_circle(0.0)));
  const ident::Diagnosis D = diagnose(generate(hump_on_a_circle(15.0 * D0.axis_floor[0])));
  std::printf("hump on a circle: %s\n", D.verdict_text.c_str());
  ASSERT_FALSE(D.outside_library.empty()) << D.verdict_text;
  EXPECT_EQ(D.outside_library.front().axis, 0) << D.verdict_text;
}

// The alike listing: on the circle d2 and v1 are affine in each other, and a
// smooth force of one is listed with the other (|corr| >= 0.9 stated); d1, at
// 90 degrees to both (corr ~ 0), is not listed for its correlation.
TEST(OpenWorld, VariablesAffineInTheLeadAreListedAlike) {
  const ident::Diagnosis D0 = diagnose(generate(hump_on_a_circle(0.0)));
  GeneratorSpec s = hump_on_a_circle(0.0);
  // A carrier dragged at low speed by axis 1, on axis 3 (which holds still).
  s.outside = {{OutsideForce::Kind::cross_velocity_hump, 2, 0, 15.0 * D0.axis_floor[2], 0.0, 0.15 / 6.0}};
  const ident::Diagnosis D = diagnose(generate(s));
  std::printf("hump of v1 on axis 3, on a circle: %s\n", D.verdict_text.c_str());
  ASSERT_FALSE(D.outside_library.empty());
  const ident::StructureFinding& f = D.outside_library.front();
  EXPECT_EQ(f.axis, 2);
  ASSERT_TRUE(f.coordinate == "v1" || f.coordinate == "d2") << f.text;
  const std::string partner = f.coordinate == "v1" ? "d2" : "v1";
  const ident::AlikeVariable* a = alike(f, partner);
  ASSERT_NE(a, nullptr) << f.text;
  EXPECT_GT(std::fabs(a->correlation), 0.9);
  EXPECT_NE(std::find(f.also_in.begin(), f.also_in.end(), partner), f.also_in.end());
  if (const ident::AlikeVariable* d1 = alike(f, "d1")) {
    EXPECT_LT(std::fabs(d1->correlation), 0.9);
  }
  // The verdict says the data cannot tell them apart, and how to.
  EXPECT_NE(D.verdict_text.find("cannot tell"), std::string::npos);
  EXPECT_NE(D.verdict_text.find("to tell " + f.coordinate + " from " + partner), std::string::npos);
}

// A friction on axis 1 whose level rises along its travel (0.3 to 1 of its
// size, 10x the floor, turning over 2 mm/s). On a circle the level's change,
// sign(v1) (d1 - c), averages to nothing at every value of d1, d2 or v1, and
// the verdict named a Coulomb friction of a fraction of the mean level beside
// structure on axes 2 and 3 (periodic in d2, in time), with a -90 % drive gain
// and a -4.5 kg rotor inertia. Now: position_friction on axis 1 and nothing on
// the other axes, no library effect named. (On the circle sign(v1) is
// sign(d2 - c), which the plane tilts share: the level's mean is not
// determined there, only its rise; the levels are checked on the generator's
// own path.)
GeneratorSpec friction_map(std::uint64_t seed, bool circle, double& size, double& lo, double& hi) {
  GeneratorSpec s = spec(Timing::zoh, NoisePlacement::plant, seed);
  if (circle) {
    s.circle_radius = 0.1;
    s.circle_omega = 1.5;
  }
  const GeneratedLog g0 = generate(s);
  lo = g0.d_min[0];
  hi = g0.d_max[0];
  size = 10.0 * diagnose(g0).axis_floor[0];
  s.outside = {{OutsideForce::Kind::position_friction, 0, -1, size, 0.5 * (lo + hi), 0.5 * (hi - lo)}};
  return s;
}

const ident::StructureFinding& friction_map_found(const ident::Diagnosis& D) {
  std::printf("%s\n", D.verdict_text.c_str());
  for (const auto& f : D.structure) std::printf("  structure left: %s (%.1f sigma)\n", f.text.c_str(), f.z);
  for (const auto& o : D.outside_library) EXPECT_EQ(o.axis, 0) << o.text;
  EXPECT_EQ(D.verdict, -1) << D.candidates[0].label();
  if (D.outside_library.empty()) throw Error("no outside_library finding");
  const ident::StructureFinding& f = D.outside_library.front();
  EXPECT_EQ(f.kind, "position_friction");
  EXPECT_EQ(f.axis, 0);
  EXPECT_EQ(f.coordinate, "d1");
  EXPECT_EQ(f.values.size(), 7u);
  return f;
}

TEST(OpenWorld, FrictionMapOnTheCircleIsFoundOnItsAxis) {
  double size = 0.0, lo = 0.0, hi = 0.0;
  const ident::Diagnosis D = diagnose(generate(friction_map(7, true, size, lo, hi)));
  const ident::StructureFinding& f = friction_map_found(D);
  EXPECT_GT(f.values.back() - f.values.front(), 0.35 * size);  // truth 0.7 size
}

TEST(OpenWorld, FrictionMapLevelsAndTheExpressionOffered) {
  double size = 0.0, lo = 0.0, hi = 0.0;
  const ident::Diagnosis D = diagnose(generate(friction_map(7, false, size, lo, hi)));
  const ident::StructureFinding& f = friction_map_found(D);
  // The level at the ends of the stroke covered (truth 0.65 size -+ 0.35 size at the true ends).
  auto truth = [&](double d) { return size * (0.65 + 0.35 * (d - 0.5 * (lo + hi)) / (0.5 * (hi - lo))); };
  EXPECT_NEAR(f.values.front(), truth(f.nodes.front()), 0.15 * size);
  EXPECT_NEAR(f.values.back(), truth(f.nodes.back()), 0.15 * size);
  const ident::SuggestedUserEffect u = ident::suggest_user_effect(f);
  EXPECT_EQ(u.kind, "expression");
  EXPECT_EQ(u.axis, 0);
  EXPECT_NO_THROW(ident::user_effect_of(u)) << u.formula;
  ASSERT_EQ(u.params.size(), 4u);
  const double mid = truth(0.5 * (f.lo + f.hi)), rise = truth(f.hi) - mid;
  EXPECT_NEAR(u.params[0].second, mid, 0.15 * size) << u.text;   // c0: the level mid-stroke
  EXPECT_NEAR(u.params[1].second, rise, 0.15 * size) << u.text;  // c1: its rise to each end
}

// Logs of the open-world matrix (cpm_robustness --outside, 15 s; seed k there
// is the generator's seed 7919 k + 17), rebuilt by hand: the hump planted at
// `multiple` times the null log's own floor on its axis, a sixth of the speed
// reached wide, as the matrix plants it.
struct MatrixHump {
  const ident::Diagnosis null_log, hump;
};

MatrixHump matrix_hump(Timing t, NoisePlacement n, int seed, double rate, int axis, int from_axis, double multiple) {
  GeneratorSpec s = spec(t, n, static_cast<std::uint64_t>(seed) * 7919ULL + 17ULL);
  s.rate = rate;
  const GeneratedLog g0 = generate(s);
  ident::Diagnosis D0 = diagnose(g0);
  const double vmax = peak_speed(g0, from_axis);
  const auto kind = axis == from_axis ? OutsideForce::Kind::velocity_hump : OutsideForce::Kind::cross_velocity_hump;
  s.outside = {{kind, axis, axis == from_axis ? -1 : from_axis, multiple * D0.axis_floor[axis], 0.0, vmax / 6.0}};
  return {std::move(D0), diagnose(generate(s))};
}

void expect_outside_on(const ident::Diagnosis& D, int axis, const std::string& var) {
  ASSERT_FALSE(D.outside_library.empty()) << D.verdict_text;
  const ident::StructureFinding& f = D.outside_library.front();
  EXPECT_EQ(f.axis, axis) << D.verdict_text;
  EXPECT_TRUE(f.coordinate == var || std::find(f.also_in.begin(), f.also_in.end(), var) != f.also_in.end())
      << f.text;
  EXPECT_TRUE(D.found().empty()) << D.verdict_text;
}

// 250 Hz, zoh, plant noise, seed 3: a 3x hump of v1 on axis 2. With the hump's
// table fitted on axis 2 the alignment came out 1.35 ms (0.72 ms on the log
// without it) and the misalignment, on an axis that moves nearly
// sinusoidally, left viscous_friction[axis 2] named beside the finding
// (b = 0.20 +- 0.054 N s/m; the null log gives 0.19 at that alignment too).
TEST(OpenWorld, CrossSpeedHumpAt250HzNamesNoViscousFrictionFromTheAlignment) {
  const MatrixHump m = matrix_hump(Timing::zoh, NoisePlacement::plant, 3, 250.0, 1, 0, 3.0);
  std::printf("null: %s\nhump of v1 on axis 2, 250 Hz: %s\n", m.null_log.verdict_text.c_str(), m.hump.verdict_text.c_str());
  EXPECT_TRUE(m.null_log.found().empty()) << m.null_log.verdict_text;
  expect_outside_on(m.hump, 1, "v1");
}

// 4000 Hz, zoh, command noise, seed 2: a 3x hump of v3 on axis 3, peaking at
// 31 mm/s. The early comparison against the library fitted it as a degree-5
// polynomial, which misses so narrow a hump: stribeck_friction[axis 3]
// (v_s 81 mm/s) won and 8.6 sigma of the hump stayed behind, below the
// strong finding's size.
TEST(OpenWorld, NarrowSpeedHumpAt4000HzIsNotNamedStribeck) {
  const MatrixHump m = matrix_hump(Timing::zoh, NoisePlacement::command, 2, 4000.0, 2, 2, 3.0);
  std::printf("null: %s\nhump of v3 on axis 3, 4000 Hz: %s\n", m.null_log.verdict_text.c_str(), m.hump.verdict_text.c_str());
  EXPECT_TRUE(m.null_log.found().empty()) << m.null_log.verdict_text;
  expect_outside_on(m.hump, 2, "v3");
}

}  // namespace
}  // namespace cpm::indep
