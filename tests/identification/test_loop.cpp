// SPDX-License-Identifier: Apache-2.0
// The user's loop as one command (model_loop.hpp): several effects planted at once,
// the loop names every one, and the waterfall ends within 20 % of the noise
// floor, on a motion log and on ball-bar data.
#include <gtest/gtest.h>

#include <algorithm>

#include "cpm/identification/kinematic.hpp"
#include "cpm/identification/model_loop.hpp"
#include "cpm/io/model_file.hpp"
#include "identification/kin_data.hpp"
#include "identification/sim_data.hpp"

namespace cpm::ident {
namespace {

bool added(const LoopResult& R, const std::string& effect, int axis) {
  return std::any_of(R.added.begin(), R.added.end(),
                     [&](const FitRequest& r) { return r.effect == effect && r.axis == axis; });
}

TEST(Loop, ThreeDynamicEffectsAtOnceAreAddedOneByOneDownToTheNoiseFloor) {
  test::SimSpec s;
  s.duration = 16.0;
  s.seed = 77;
  s.effects = {{"coulomb_friction", 0, {0.6}}, {"actuation_delay", -1, {1e-3}}, {"viscous_friction", 2, {2.0}}};
  const LoopResult R = run_loop(io::DataSet(test::simulate(s)), ctl::MachineModel::elkady());
  std::fputs(loop_text(R).c_str(), stdout);
  EXPECT_TRUE(added(R, "coulomb_friction", 0));
  EXPECT_TRUE(added(R, "actuation_delay", -1));
  EXPECT_TRUE(added(R, "viscous_friction", 2));
  EXPECT_EQ(R.added.size(), 3u);
  EXPECT_FALSE(R.outside_library);
  ASSERT_GE(R.steps.size(), 4u);
  // The waterfall falls at every step and ends within 20 % of the noise floor.
  for (std::size_t j = 1; j < R.steps.size(); ++j) EXPECT_LT(R.steps[j].rms, R.steps[j - 1].rms) << j;
  EXPECT_LE(R.steps.back().rms, 1.2 * R.steps.back().noise_floor);
  // The model it leaves carries the delay and the two frictions.
  const ctl::Machine m(R.model);
  EXPECT_NEAR(m.actuation_delay(), 1e-3, 1e-4);
  EXPECT_NE(loop_html(R, "sim").find("<svg"), std::string::npos);
}

TEST(Loop, TwoKinematicEffectsAtOnceOnBallBarDataAreBothAdded) {
  // Backlash on axis 1 and a cyclic error on axis 2, on Kim's machine, two bar radii, both directions.
  const std::vector<test::PlantedKinematic> planted = {{"backlash", 0, {6e-6, 0, 0}},
                                                      {"cyclic_error", 1, {4e-6, 0.016, 0.3}}};
  test::KinSimOptions so;
  so.seed = 5;
  const io::BallbarData b = test::kim_ballbar(planted, test::hemisphere_poses({0.100, 0.150}, 6, 16, 7), so);
  const LoopResult R = run_loop(io::DataSet(b), ctl::MachineModel::elkady());
  std::fputs(loop_text(R).c_str(), stdout);
  EXPECT_TRUE(added(R, "backlash", 0));
  EXPECT_TRUE(added(R, "cyclic_error", 1));
  ASSERT_GE(R.steps.size(), 3u);
  EXPECT_LE(R.steps.back().rms, 1.2 * R.steps.back().noise_floor);
}

// The open world (issue 26): Coulomb friction 3 N on axis 1 (the library) and
// a cable carrier's drag on axis 2 that follows axis 1's velocity, 25 N s/m
// (no library effect): the loop names the friction, finds the drag on axis 2
// against v1 and, allowed to, adds it as an expression effect and fits it; the
// waterfall ends within 20 % of the noise floor. Not allowed, it stops above.
test::SimSpec cable_carrier_log() {
  test::SimSpec s;
  s.duration = 16.0;
  s.seed = 26;
  s.effects = {{"coulomb_friction", 0, {3.0}}};
  s.user_effects = {"expression:2:c*v1:c=25"};
  return s;
}

TEST(Loop, OpenWorldAddsTheOutsideFindingAsAnExpressionDownToTheNoiseFloor) {
  const io::DataSet log(test::simulate(cable_carrier_log()));
  const LoopResult R = run_loop(log, ctl::MachineModel::elkady(), {}, 6, {"expression", "table"});
  std::fputs(loop_text(R).c_str(), stdout);
  EXPECT_TRUE(added(R, "coulomb_friction", 0));
  ASSERT_EQ(R.user_added.size(), 1u);
  const SuggestedUserEffect& u = R.user_added.front();
  EXPECT_EQ(u.axis, 1);
  ASSERT_EQ(u.kind, "expression") << u.text;
  EXPECT_EQ(u.formula, "c*v1");
  ASSERT_EQ(R.model.user_effects.size(), 1u);
  const ctl::UserEffect& e = R.model.user_effects.front();
  EXPECT_EQ(e.axis, 1);
  ASSERT_EQ(e.params.size(), 1u);
  EXPECT_NEAR(e.params.front().value, 25.0, 2.5);
  std::printf("c = %.3f N s/m (planted 25)\n", e.params.front().value);
  EXPECT_FALSE(R.outside_library);
  ASSERT_GE(R.steps.size(), 3u);
  EXPECT_EQ(R.steps.back().added, "expression[axis 2]: c*v1");
  for (std::size_t j = 1; j < R.steps.size(); ++j) EXPECT_LT(R.steps[j].rms, R.steps[j - 1].rms) << j;
  EXPECT_LE(R.steps.back().rms, 1.2 * R.steps.back().noise_floor);
  // The model it leaves, measured as the model as given was (nothing refitted).
  const double left = motion_rms(std::get<io::MotionData>(log), R.model);
  std::printf("the model left, nothing refitted: %.4f N RMS (%.3f x the floor)\n", left,
              left / R.steps.back().noise_floor);
  // The model the loop writes holds the user effect and reads back equal.
  io::ModelFile mf;
  mf.model = R.model;
  const io::ModelFile back = io::parse_model_file(io::render_model_file(mf), "out.yaml");
  EXPECT_EQ(back.model.user_effects, R.model.user_effects);
  EXPECT_EQ(back.model.effects.size(), R.model.effects.size());
  EXPECT_NE(loop_json(R, "sim", "out.yaml").find("\"user_effects_added\""), std::string::npos);

  // The controller compensates it: the paper's circle on the true machine
  // (its planes as the model's: the motion log does not calibrate them, and
  // their static error would hide the forces' part), the controller's model
  // with the user effect and without it.
  // The paper's circle starts at full speed from rest (its transient is the
  // same with either model); the ramped one does not.
  for (const double ramp : {0.0, 0.5}) {
    ctl::CircleSpec spec;
    spec.ramp_time = ramp;
    const ctl::CircleTrajectory circle(spec);
    test::SimSpec c = cable_carrier_log();
    c.trajectory = &circle;
    c.base_errors = false;
    ctl::MachineModel without = R.model;
    without.user_effects.clear();
    sim::RunResult with_run, without_run;
    test::simulate(c, &with_run, R.model);
    test::simulate(c, &without_run, without);
    const double e_with = with_run.metrics.position_rmse, e_without = without_run.metrics.position_rmse;
    std::printf("circle (ramp %.1f s), tracking RMSE: %.4f mm with the user effect in the model, %.4f mm without\n",
                ramp, e_with * 1e3, e_without * 1e3);
    EXPECT_LT(e_with, (ramp > 0.0 ? 0.05 : 0.7) * e_without) << ramp;
  }
}

TEST(Loop, OpenWorldWithoutAllowStopsAtTheFindingWellAboveTheFloor) {
  const io::DataSet log(test::simulate(cable_carrier_log()));
  const LoopResult R = run_loop(log, ctl::MachineModel::elkady());
  std::fputs(loop_text(R).c_str(), stdout);
  EXPECT_TRUE(added(R, "coulomb_friction", 0));
  EXPECT_TRUE(R.user_added.empty());
  EXPECT_TRUE(R.model.user_effects.empty());
  EXPECT_TRUE(R.outside_library);
  EXPECT_EQ(R.suggestion.kind, "expression");
  EXPECT_EQ(R.suggestion.axis, 1);
  EXPECT_EQ(R.suggestion.formula, "c*v1");
  EXPECT_GT(R.steps.back().rms, 1.2 * R.steps.back().noise_floor);
}

}  // namespace
}  // namespace cpm::ident

namespace cpm::ident {
namespace {

// Issue 28, item 4: the diagnosis after Coulomb friction was added led with
// "axis 1: the residual differs by -0.00946 N between moving forward and
// backward (13 sigma)" beside 3 N of friction, with a viscous friction and a
// payload still significant in it, and the loop stopped there. Reproduced as
// that diagnosis: the loop goes on with the two, and only a finding that
// matters, or one with nothing of the library left, stops it.
struct TinyFinding {
  Diagnosis D;
  LoopResult R;
  TinyFinding() {
    D.noise_floor = 0.004;  // N: the finding is above it, at 13 sigma
    StructureFinding f;
    f.kind = "direction";
    f.axis = 0;
    f.size = -0.00946;
    f.z = 13.0;
    f.text = "axis 1: the residual differs by -0.00946 N between moving forward and backward (13 sigma)";
    D.outside_library.push_back(f);
    auto cand = [](const char* effect, int axis, bool significant, double rms) {
      CandidateResult c;
      c.effect = effect;
      c.axis = axis;
      c.significant = significant;
      c.fitted = Eigen::VectorXd::Constant(300, rms);
      return c;
    };
    D.candidates = {cand("viscous_friction", 2, true, 0.8), cand("payload_mass", -1, true, 0.5),
                    cand("spring", 1, false, 0.002)};
    R.added = {{"coulomb_friction", 0}};
    R.steps = {{"", 3.1, 0.004, ""}, {"coulomb_friction[axis 1]", 0.95, 0.004, ""}};
  }
};

TEST(LoopStop, ATinyFindingBesideSignificantEffectsDoesNotStopTheLoop) {
  TinyFinding t;
  std::vector<FitRequest> next;
  EXPECT_EQ(loop_stop_reason(t.D, t.R, next), "");
  ASSERT_EQ(next.size(), 2u);
  EXPECT_EQ(next[0].effect, "viscous_friction");
  EXPECT_EQ(next[0].axis, 2);
  EXPECT_EQ(next[1].effect, "payload_mass");
  // 9.46 mN against the 2.95 N the Coulomb friction explained: 0.3 %, under 2 %.
  EXPECT_TRUE(finding_too_small(t.D.outside_library[0], t.D, 2.95));
  EXPECT_FALSE(finding_too_small(t.D.outside_library[0], t.D, 0.3));
}

TEST(LoopStop, AFindingThatMattersOrNothingLeftStopsTheLoop) {
  {
    // 0.5 N: 17 % of what the friction explained: it stops, naming it.
    TinyFinding t;
    t.D.outside_library[0].size = 0.5;
    std::vector<FitRequest> next;
    EXPECT_NE(loop_stop_reason(t.D, t.R, next).find("something no library effect describes remains"), std::string::npos);
  }
  {
    // The tiny finding with nothing significant of the library left: it stops there.
    TinyFinding t;
    for (auto& c : t.D.candidates) c.significant = false;
    std::vector<FitRequest> next;
    EXPECT_NE(loop_stop_reason(t.D, t.R, next).find("-0.00946 N"), std::string::npos);
  }
}

// The machine of the issue (Coulomb 3 N on axis 1, viscous 20 N s/m on axis
// 3, a 0.4 kg payload) in five runs with different noise: each completes with
// the three effects and nothing outside the library. (These logs do not raise
// the tiny finding; the test above is the one that fails without the rule.)
TEST(LoopStop, FiveRunsInARowOfTheThreeEffectsAllComplete) {
  for (std::uint64_t seed = 1; seed <= 5; ++seed) {
    SCOPED_TRACE(seed);
    test::SimSpec s;
    s.duration = 10.0;
    s.seed = 100 + seed;
    s.effects = {{"coulomb_friction", 0, {3.0}}, {"viscous_friction", 2, {20.0}}, {"payload_mass", -1, {0.4}}};
    const LoopResult R = run_loop(io::DataSet(test::simulate(s)), ctl::MachineModel::elkady());
    std::string names;
    for (const FitRequest& r : R.added) names += " " + r.effect + (r.axis >= 0 ? ":" + std::to_string(r.axis + 1) : "");
    std::printf("seed %d: added%s; %.4f N -> %.4f N (floor %.4f N); stop: %s\n", static_cast<int>(seed), names.c_str(),
                R.steps.front().rms, R.steps.back().rms, R.steps.back().noise_floor, R.stop.c_str());
    EXPECT_TRUE(added(R, "coulomb_friction", 0));
    EXPECT_TRUE(added(R, "viscous_friction", 2));
    // The payload as itself, or as the base refit that holds it (dA = m / 2, dE = m g: docs/effects.md).
    EXPECT_TRUE(added(R, "payload_mass", -1) || added(R, "inertia_error", -1));
    for (const ctl::DynamicEffect& e : R.model.effects) {
      if (e.type == ctl::DynamicEffectType::payload_mass) {
        EXPECT_NEAR(e.param[0], 0.4, 0.008);
      }
      if (e.type == ctl::DynamicEffectType::inertia_error) {
        std::printf("  inertia_error: dA %.4f kg, dE %.4f N (0.4 kg: 0.2 kg, %.4f N)\n", e.param[0], e.param[3],
                    0.4 * ctl::kGravity);
        EXPECT_NEAR(e.param[0], 0.2, 0.008);  // 0.194..0.199 kg measured: the base refit shares A with B, C
        EXPECT_NEAR(e.param[3], 0.4 * ctl::kGravity, 0.02 * 0.4 * ctl::kGravity);
      }
      if (e.type == ctl::DynamicEffectType::coulomb_friction) {
        EXPECT_NEAR(e.param[0], 3.0, 0.06);
      }
      if (e.type == ctl::DynamicEffectType::viscous_friction) {
        EXPECT_NEAR(e.param[0], 20.0, 0.4);
      }
    }
    EXPECT_FALSE(R.outside_library);
    EXPECT_LE(R.steps.back().rms, 1.2 * R.steps.back().noise_floor);
  }
}

}  // namespace
}  // namespace cpm::ident
