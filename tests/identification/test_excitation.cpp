// SPDX-License-Identifier: Apache-2.0
// cpm excite's design (excitation.hpp): within the limits, periodic, and,
// on the simulated machine, better than a plain multi-sine of the same
// duration: the standard errors of the design's regressor fitted on each log
// smaller (seed 1: 2.34x in the median over its 19 effect parameters within
// the same limits, 3.04x against the plain one as large as the design, 1.32x
// within the plain one's peak displacement; the 2x within the same
// limits on seeds 1-5, not on seed 6: 1.94x; docs/identification.md).
#include <gtest/gtest.h>

#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <cstdlib>

#include "cpm/identification/excitation.hpp"
#include "cpm/identification/fit.hpp"
#include "cpm/identification/model_loop.hpp"
#include "identification/sim_data.hpp"
#include "support/planted_effects.hpp"

namespace cpm::ident {
namespace {

ExcitationOptions quick() {
  ExcitationOptions o;
  o.period = 4.0;
  o.periods = 3;
  o.harmonics = 5;
  o.iterations = 60;
  o.refine = 40;
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

// The optimised design against the flat-spectrum Schroeder multi-sine (the
// plain one, as large as the limits allow) over the same duration, played by
// the computed-torque controller on the same true machine (Coulomb friction on
// axis 1, viscous friction on axis 3, a 0.4 kg payload, encoder noise). The
// standard errors are those of the design's regressor fitted on each log
// (every library effect's column beside the base, with the noise each log
// shows), compared column by column. Two designs: within the same limits
// (the design may take a larger amplitude than the plain one can), and
// within a box no larger than the plain one's peak displacement on every axis;
// and a second plain one, as large as the first design (its frequencies
// lowered as the limits require), against that design.
TEST(Excitation, OptimisedDesignAgainstAPlainMultiSineOfTheSameDuration) {
  const ctl::Machine model(ctl::MachineModel::elkady());
  ExcitationLimits L;
  ExcitationOptions o = quick();
  o.period = 5.0;
  o.harmonics = 4;
  o.iterations = 300;
  o.refine = 400;
  o.searches = 2;
  // The full form, by hand: CPM_EXCITE_ITERATIONS=400 (cpm excite's default), CPM_EXCITE_SEED=2,
  // CPM_EXCITE_REFINE=400 (the pattern search's designs; cpm excite's default 200),
  // CPM_EXCITE_SEARCHES=1 (cpm excite's default), CPM_EXCITE_CRITERION=0..1 (log_det, std_errors),
  // CPM_EXCITE_SKIP_BOXED=1 (no design within the plain one's box: half the time) ...
  if (const char* c = std::getenv("CPM_EXCITE_ITERATIONS")) o.iterations = std::atoi(c);
  if (const char* c = std::getenv("CPM_EXCITE_SEED")) o.seed = std::strtoull(c, nullptr, 10);
  if (const char* c = std::getenv("CPM_EXCITE_REFINE")) o.refine = std::atoi(c);
  if (const char* c = std::getenv("CPM_EXCITE_CRITERION")) o.criterion = static_cast<ExcitationOptions::Criterion>(std::atoi(c));
  if (const char* c = std::getenv("CPM_EXCITE_SEARCHES")) o.searches = std::atoi(c);
  const bool skip_boxed = std::getenv("CPM_EXCITE_SKIP_BOXED") != nullptr;
  const MultiSine plain = schroeder_multisine(model, L, o);
  ExcitationLimits same = L;
  const Vec3 room = plain.peak_displacement() / L.margin;
  same.workspace_min = plain.centre() - room;
  same.workspace_max = plain.centre() + room;
  const ExcitationDesign full = design_excitation(model, L, o);
  ExcitationOptions ob = o;
  if (skip_boxed) ob.iterations = ob.refine = 0;
  const ExcitationDesign boxed = design_excitation(model, same, ob);
  auto log_of = [&](const MultiSine& m) {
    test::SimSpec spec;
    spec.seed = 3;
    spec.trajectory = &m;
    spec.effects = {{"coulomb_friction", 0, {3.0}}, {"viscous_friction", 2, {20.0}}, {"payload_mass", -1, {0.4}}};
    return test::simulate(spec);
  };
  const io::MotionData lp = log_of(plain);
  const RegressorFit fp = fit_design_regressor(lp, model);
  auto compare = [&](const char* what, const ExcitationDesign& D) {
    const MultiSine& m = D.trajectory;
    EXPECT_DOUBLE_EQ(m.duration(), plain.duration());
    const Vec3 pd = m.peak_displacement(), pp = plain.peak_displacement();
    std::printf("%s: peak displacement %.1f %.1f %.1f mm (plain %.1f %.1f %.1f), peak speed %.0f mm/s (plain %.0f), "
                "acceleration %.2f m/s^2 (plain %.2f), %.1f s each\n",
                what, pd.x() * 1e3, pd.y() * 1e3, pd.z() * 1e3, pp.x() * 1e3, pp.y() * 1e3, pp.z() * 1e3,
                D.figures.peak_speed * 1e3, D.start.peak_speed * 1e3, D.figures.peak_acceleration,
                D.start.peak_acceleration, m.duration());
    for (int i = 0; i < 3; ++i) {
      const Passes& q = m.passes()[static_cast<std::size_t>(i)];
      std::printf("  axis %d passes: stroke %.1f mm, speeds", i + 1, q.stroke * 1e3);
      for (std::size_t j = 0; j < q.share.size(); ++j) std::printf(" %.0f", m.pass_speed(i, j) * 1e3);
      std::printf(" mm/s\n");
    }
    const RegressorFit fd = fit_design_regressor(log_of(m), model);
    EXPECT_EQ(fd.columns, fp.columns);
    std::vector<double> r;
    for (Eigen::Index j = 0; j < fd.std_error.size(); ++j) {
      r.push_back(fp.std_error(j) / fd.std_error(j));
      const Eigen::Index k = j + D.figures.base_columns;
      std::printf("  %-28s +- %.3g (plain +- %.3g): %.2fx (predicted %.2fx)\n", fd.columns[static_cast<std::size_t>(j)].c_str(),
                  fd.std_error(j), fp.std_error(j), r.back(), D.start.std_error(k) / D.figures.std_error(k));
    }
    std::sort(r.begin(), r.end());
    const double median = r[r.size() / 2];
    std::printf("%s: median ratio of the fitted standard errors %.3f over %zu parameters (min %.2f, max %.2f); "
                "residual RMS %.4f N (plain %.4f); D-criterion %.1f (plain %.1f), %d designs\n",
                what, median, r.size(), r.front(), r.back(), fd.residual_rms, fp.residual_rms, D.figures.log_det,
                D.start.log_det, D.evaluations);
    return median;
  };
  const double m_full = compare("within the same limits", full);
  const double m_boxed = compare("within the plain one's peak displacement", boxed);
  // The second reference: the plain multi-sine as large as the optimised
  // design (its peak displacement), its frequencies lowered where the limits
  // require (fewer, longer periods in the same time).
  const Vec3 peak = full.trajectory.peak_displacement();
  const MultiSine wide = schroeder_multisine_at_peak(model, L, o, peak);
  EXPECT_DOUBLE_EQ(wide.duration(), plain.duration());
  const ExcitationFigures fw = excitation_figures(wide, model, o);
  EXPECT_LE(fw.peak_speed, L.margin * L.velocity * (1 + 1e-9));
  EXPECT_LE(fw.peak_acceleration, L.margin * L.acceleration * (1 + 1e-9));
  const RegressorFit fpw = fit_design_regressor(log_of(wide), model);
  const RegressorFit ff = fit_design_regressor(log_of(full.trajectory), model);
  std::vector<double> rw;
  for (Eigen::Index j = 0; j < ff.std_error.size(); ++j) rw.push_back(fpw.std_error(j) / ff.std_error(j));
  std::sort(rw.begin(), rw.end());
  const double m_wide = rw[rw.size() / 2];
  const Vec3 pw = wide.peak_displacement();
  std::printf("against the plain one at the optimised design's peak displacement (%.1f %.1f %.1f mm of %.1f %.1f %.1f; "
              "%d period(s) of %.1f s, peak speed %.0f mm/s, acceleration %.2f m/s^2): median ratio %.3f "
              "(min %.2f, max %.2f); residual RMS %.4f N\n",
              pw.x() * 1e3, pw.y() * 1e3, pw.z() * 1e3, peak.x() * 1e3, peak.y() * 1e3, peak.z() * 1e3, wide.periods(),
              wide.period(), fw.peak_speed * 1e3, fw.peak_acceleration, m_wide, rw.front(), rw.back(),
              fpw.residual_rms);
  for (int i = 0; i < 3; ++i) EXPECT_LE(boxed.trajectory.peak_displacement()[i], plain.peak_displacement()[i] * (1 + 1e-9));
  // Measured on seed 1: 2.34x, 1.32x and 3.04x (two searches of 150 random
  // designs, then 200 of the pattern search); seeds 2-6: 2.19x, 2.22x, 2.91x,
  // 2.08x, 1.94x (seed 7: 2.26x) within the same limits, 2.54x-3.33x against the plain one as
  // large. One search of 150 + 200: 2.11x, 1.90x, 2.21x, 2.91x, 1.83x (seeds
  // 1-5); without the pattern search 1.80x and 1.18x (seed 1): the first two
  // bars fail if the passes or the refinement stop paying. The 2x
  // within the same limits does not hold on seed 6, so that bar stays under it.
  EXPECT_GE(m_full, 1.95);
  if (!skip_boxed) {
    EXPECT_GE(m_boxed, 1.25);
  }
  EXPECT_GE(m_wide, 2.0);
}

// What cpm identify will run on cpmd, in-process: the designed experiment
// played on the machine of issue 28 (Coulomb 3 N on axis 1, viscous 20 N s/m
// on axis 3, a 0.4 kg payload) with an actuation delay of one period (1 ms),
// then the loop on its log: every planted effect named, each within 2 % (the
// delay within 2 % or 3 standard errors), the waterfall down to the noise floor.
TEST(Excitation, TheLoopOnTheDesignedExperimentNamesEveryPlantedEffect) {
  const ctl::Machine model(ctl::MachineModel::elkady());
  ExcitationOptions o = quick();
  o.period = 5.0;
  o.harmonics = 4;
  const ExcitationDesign D = design_excitation(model, ExcitationLimits{}, o);
  test::SimSpec spec;
  spec.seed = 11;
  spec.trajectory = &D.trajectory;
  spec.effects = {{"coulomb_friction", 0, {3.0}},
                  {"viscous_friction", 2, {20.0}},
                  {"payload_mass", -1, {0.4}},
                  {"actuation_delay", -1, {1e-3}}};
  const LoopResult R = run_loop(io::DataSet(test::simulate(spec)), ctl::MachineModel::elkady());
  std::fputs(loop_text(R).c_str(), stdout);
  EXPECT_FALSE(R.outside_library);
  EXPECT_LE(R.steps.back().rms, 1.2 * R.steps.back().noise_floor);
  double delay_se = -1.0;
  for (const auto& f : R.fitted)
    if (f.name == "effects.actuation_delay.tau") delay_se = f.std_error;
  test::expect_planted_effects_named(R.model.effects, 1e-3, delay_se);
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
