// SPDX-License-Identifier: Apache-2.0
// cpm excite's design (excitation.hpp): within the limits, periodic, and,
// on the simulated machine, better than a plain multi-sine of the same
// duration: the standard errors of the fitted effects smaller (1.35x in the
// median over Coulomb, viscous friction and payload; the 2x is not reached).
#include <gtest/gtest.h>

#include <algorithm>
#include <cstdio>

#include "cpm/identification/excitation.hpp"
#include "cpm/identification/fit.hpp"
#include "cpm/identification/model_loop.hpp"
#include "identification/sim_data.hpp"

namespace cpm::ident {
namespace {

ExcitationOptions quick() {
  ExcitationOptions o;
  o.period = 4.0;
  o.periods = 3;
  o.harmonics = 5;
  o.iterations = 60;
  return o;
}

TEST(Excitation, DesignStaysWithinTheLimitsStartsAndEndsAtRestAndRepeatsItsPeriod) {
  const ctl::Machine model(ctl::MachineModel::elkady());
  ExcitationLimits L;
  const ExcitationOptions o = quick();
  const ExcitationDesign D = design_excitation(model, L, o);
  const MultiSine& m = D.trajectory;
  EXPECT_NEAR(m.duration(), 2 * o.ramp + o.periods * o.period, 1e-12);
  // Every millisecond within the box, the speed and the acceleration (the planner's own check passes too).
  double vmax = 0, amax = 0;
  for (double t = 0; t <= m.duration(); t += 1e-3) {
    const auto s = m.sample(t);
    for (int i = 0; i < 3; ++i) {
      EXPECT_GE(s.p[i], L.workspace_min[i]);
      EXPECT_LE(s.p[i], L.workspace_max[i]);
    }
    vmax = std::max(vmax, s.v.norm());
    amax = std::max(amax, s.a.norm());
  }
  EXPECT_LE(vmax, L.velocity);
  EXPECT_LE(amax, L.acceleration);
  EXPECT_NO_THROW(ctl::validate_trajectory(m, model, 1e-3, L.velocity, L.acceleration));
  EXPECT_LE(D.figures.peak_force, L.force);
  // At rest at both ends, the same motion one period later in the middle.
  EXPECT_LT(m.sample(0).v.norm(), 1e-12);
  EXPECT_LT(m.sample(m.duration()).v.norm(), 1e-12);
  for (double t = o.ramp; t < o.ramp + o.period; t += 0.37)
    EXPECT_LT((m.sample(t).p - m.sample(t + o.period).p).norm(), 1e-9) << t;
  // Every axis reverses within a period.
  for (int i = 0; i < 3; ++i) {
    int reversals = 0;
    double prev = m.sample(o.ramp).v[i];
    for (double t = o.ramp; t < o.ramp + o.period; t += 1e-3) {
      const double v = m.sample(t).v[i];
      if (v * prev < 0) ++reversals;
      prev = v;
    }
    EXPECT_GE(reversals, 2) << "axis " << i + 1;
  }
  // The optimiser improved the D-criterion over its start.
  EXPECT_GT(D.figures.log_det, D.start.log_det);
}

// The optimised design against the flat-spectrum Schroeder multi-sine of the
// same harmonics, duration and peak displacement, both played by the
// computed-torque controller on a true machine with Coulomb friction on axis
// 1, viscous friction on axis 3 and a 0.4 kg payload; the standard errors of
// those three fitted parameters compared.
TEST(Excitation, OptimisedDesignLowersTheStandardErrorsOfAPlainMultiSine) {
  const ctl::Machine model(ctl::MachineModel::elkady());
  ExcitationLimits L;
  ExcitationOptions o = quick();
  o.period = 5.0;
  o.harmonics = 4;
  o.iterations = 200;
  const ExcitationDesign D = design_excitation(model, L, o);
  // The plain multi-sine at the optimised design's peak displacement per axis (or less, within the limits).
  const MultiSine flat = schroeder_multisine(model, L, o);
  const Vec3 s = D.trajectory.peak_displacement().cwiseQuotient(flat.peak_displacement());
  const MultiSine plain = scale_to_limits(flat.scaled(s.cwiseMin(Vec3::Ones())), model, L);
  std::printf("peak displacement (mm): optimised %.1f %.1f %.1f, plain %.1f %.1f %.1f\n",
              D.trajectory.peak_displacement().x() * 1e3, D.trajectory.peak_displacement().y() * 1e3,
              D.trajectory.peak_displacement().z() * 1e3, plain.peak_displacement().x() * 1e3,
              plain.peak_displacement().y() * 1e3, plain.peak_displacement().z() * 1e3);
  const std::vector<FitRequest> req = {parse_fit_request("coulomb_friction:1"), parse_fit_request("viscous_friction:3"),
                                       parse_fit_request("payload_mass")};
  auto fitted = [&](const MultiSine& m) {
    test::SimSpec spec;
    spec.seed = 3;
    spec.trajectory = &m;
    spec.effects = {{"coulomb_friction", 0, {3.0}}, {"viscous_friction", 2, {20.0}}, {"payload_mass", -1, {0.4}}};
    return fit_motion(test::simulate(spec), ctl::MachineModel::elkady(), req, {}, nullptr, false);
  };
  const FitResult a = fitted(D.trajectory), b = fitted(plain);
  std::vector<double> ratio;
  const double truth[3] = {3.0, 20.0, 0.4};
  for (std::size_t j = 0; j < 3; ++j) {
    const ParamEstimate& pa = a.effects[j].params[0];
    const ParamEstimate& pb = b.effects[j].params[0];
    std::printf("%-26s optimised %.5g +- %.3g, plain %.5g +- %.3g: standard error %.2fx smaller\n",
                a.effects[j].label().c_str(), pa.value, pa.std_error, pb.value, pb.std_error,
                pb.std_error / pa.std_error);
    ratio.push_back(pb.std_error / pa.std_error);
    // Both recover the planted value within 2 % (the plane errors of the true machine bias the fit a little).
    EXPECT_NEAR(pa.value, truth[j], 0.02 * truth[j]);
    EXPECT_NEAR(pb.value, truth[j], 0.02 * truth[j]);
  }
  {
    const ExcitationFigures fp = excitation_figures(plain, model, o);
    std::vector<double> r;
    for (Eigen::Index j = 0; j < fp.std_error.size(); ++j) r.push_back(fp.std_error(j) / D.figures.std_error(j));
    std::sort(r.begin(), r.end());
    std::printf("design columns: %zu, median ratio of the predicted standard errors %.2f (min %.2f max %.2f)\n", r.size(), r[r.size() / 2], r.front(), r.back());
  }
  std::sort(ratio.begin(), ratio.end());
  std::printf("median ratio %.2f; design: %d candidates, D-criterion %.1f -> %.1f, sum -log sigma %.1f -> %.1f, "
              "condition %.3g -> %.3g; peak speed %.0f / %.0f mm/s, acceleration %.2f / %.2f m/s^2\n",
              ratio[1], D.evaluations, D.start.log_det, D.figures.log_det, D.start.log_std_errors,
              D.figures.log_std_errors, D.start.condition, D.figures.condition, D.figures.peak_speed * 1e3,
              excitation_figures(plain, model, o).peak_speed * 1e3, D.figures.peak_acceleration,
              excitation_figures(plain, model, o).peak_acceleration);
  // Measured 1.35x (issue 28 asks 2x: not reached, docs/identification.md);
  // this bar fails if the optimiser stops improving on its start.
  EXPECT_GE(ratio[1], 1.25);
}

// What cpm identify will run on cpmd, in-process: the designed experiment
// played on the machine of issue 28 (Coulomb 3 N on axis 1, viscous 20 N s/m
// on axis 3, a 0.4 kg payload), then the loop on its log: every planted
// effect named, each within 2 %, the waterfall down to the noise floor.
TEST(Excitation, TheLoopOnTheDesignedExperimentNamesEveryPlantedEffect) {
  const ctl::Machine model(ctl::MachineModel::elkady());
  ExcitationOptions o = quick();
  o.period = 5.0;
  o.harmonics = 4;
  const ExcitationDesign D = design_excitation(model, ExcitationLimits{}, o);
  test::SimSpec spec;
  spec.seed = 11;
  spec.trajectory = &D.trajectory;
  spec.effects = {{"coulomb_friction", 0, {3.0}}, {"viscous_friction", 2, {20.0}}, {"payload_mass", -1, {0.4}}};
  const LoopResult R = run_loop(io::DataSet(test::simulate(spec)), ctl::MachineModel::elkady());
  std::fputs(loop_text(R).c_str(), stdout);
  EXPECT_FALSE(R.outside_library);
  EXPECT_LE(R.steps.back().rms, 1.2 * R.steps.back().noise_floor);
  bool coulomb = false, viscous = false, payload = false;
  for (const ctl::DynamicEffect& e : R.model.effects) {
    if (e.type == ctl::DynamicEffectType::coulomb_friction && e.axis == 0) {
      coulomb = true;
      EXPECT_NEAR(e.param[0], 3.0, 0.06);
    }
    if (e.type == ctl::DynamicEffectType::viscous_friction && e.axis == 2) {
      viscous = true;
      EXPECT_NEAR(e.param[0], 20.0, 0.4);
    }
    // The payload as itself or in the base refit (dA = m / 2, dE = m g).
    if (e.type == ctl::DynamicEffectType::payload_mass) {
      payload = true;
      EXPECT_NEAR(e.param[0], 0.4, 0.008);
    }
    if (e.type == ctl::DynamicEffectType::inertia_error) {
      payload = true;
      EXPECT_NEAR(e.param[0], 0.2, 0.004);
      EXPECT_NEAR(e.param[3], 0.4 * ctl::kGravity, 0.02 * 0.4 * ctl::kGravity);
    }
  }
  EXPECT_TRUE(coulomb);
  EXPECT_TRUE(viscous);
  EXPECT_TRUE(payload);
}

TEST(Excitation, SeparateDesignDecorrelatesTheTwoNamedEffects) {
  const ctl::Machine model(ctl::MachineModel::elkady());
  ExcitationOptions o = quick();
  o.iterations = 40;
  o.separate = {"viscous_friction:2", "coulomb_friction:2"};
  const ExcitationDesign D = design_excitation(model, ExcitationLimits{}, o);
  std::printf("1 - rho^2 of viscous and Coulomb friction on axis 2: %.3f -> %.3f\n", D.start.separation,
              D.figures.separation);
  EXPECT_GT(D.figures.separation, D.start.separation);
}

TEST(Excitation, BadOptionsAreRefusedByName) {
  const ctl::Machine model(ctl::MachineModel::elkady());
  ExcitationOptions o = quick();
  o.periods = 1;
  try {
    design_excitation(model, ExcitationLimits{}, o);
    FAIL() << "one period accepted";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("--periods"), std::string::npos) << e.what();
  }
  o = quick();
  o.separate = {"viscous_friction:2", "cogging:2"};
  o.iterations = 1;
  EXPECT_THROW(design_excitation(model, ExcitationLimits{}, o), Error);
}

}  // namespace
}  // namespace cpm::ident
