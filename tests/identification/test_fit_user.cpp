// SPDX-License-Identifier: Apache-2.0
// cpm fit for user effects (identification/fit_user.hpp) on logs of the
// independent generator (tests/identification/independent), which plants
// the user effects in its own plant.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>

#include "cpm/identification/fit_user.hpp"
#include "generator.hpp"

namespace cpm::ident {
namespace {

indep::GeneratorSpec spec_with(const std::string& user, std::uint64_t seed) {
  indep::GeneratorSpec s;
  s.seed = seed;
  s.duration = 20.0;
  s.user_effects = {user};
  return s;
}

TEST(FitUser, ExpressionCTimesV1OnAxis2IsRecoveredWithinThreeStandardErrors) {
  const double c_true = 3.0;  // N s/m: a force on axis 2 that follows axis 1's velocity
  for (std::uint64_t seed : {11u, 12u, 13u}) {
    const indep::GeneratedLog g = indep::generate(spec_with("expression:2:c*v1:c=3", seed));
    ctl::MachineModel m = ctl::MachineModel::elkady();
    ctl::add_user_effect(m, "expression:2:c*v1:c=0");
    m.user_effects[0].params[0].lower = -100.0;
    m.user_effects[0].params[0].upper = 100.0;
    const UserFit F = fit_user_effect(g.log, m, 0);
    ASSERT_EQ(F.value.size(), 1u);
    std::printf("[ figures  ] seed %lu: c = %.4f +- %.4f N s/m (true %.1f); force RMS %.4f -> %.4f N, %d LM steps\n",
                static_cast<unsigned long>(seed), F.value[0], F.std_error[0], c_true, F.rms_before, F.rms_after,
                F.iterations);
    EXPECT_LT(std::abs(F.value[0] - c_true), 3.0 * F.std_error[0]);
    EXPECT_LT(F.std_error[0], 0.1 * c_true);  // determined, not a lucky wide interval
    EXPECT_LT(F.rms_after, F.rms_before);
    EXPECT_EQ(F.model.user_effects[0].params[0].value, F.value[0]);
  }
}

TEST(FitUser, AnExpressionOnTheWrongVariableFindsNothing) {
  // The same log, c*v3 fitted instead: c near 0 within its errors.
  const indep::GeneratedLog g = indep::generate(spec_with("expression:2:c*v1:c=3", 11));
  ctl::MachineModel m = ctl::MachineModel::elkady();
  ctl::add_user_effect(m, "expression:2:c*v3:c=0");
  const UserFit F = fit_user_effect(g.log, m, 0);
  std::printf("[ figures  ] c*v3 on a c*v1 log: c = %.4f +- %.4f N s/m\n", F.value[0], F.std_error[0]);
  EXPECT_LT(std::abs(F.value[0]), 1.0);  // a third of the true size on the other variable
}

// A local force excess on axis 2: a smooth bump of 4 N, 20 mm wide, at d2 = c.
double bump(double d, double c) { return 4.0 * std::exp(-std::pow((d - c) / 0.02, 2)); }

TEST(FitUser, PlantedTableBumpIsRecoveredWithinItsNoise) {
  // The truth: the bump tabulated every 2.5 mm (its own nodes, not the fit's).
  indep::GeneratorSpec probe = spec_with("expression:2:0*v1", 21);
  const indep::GeneratedLog p = indep::generate(probe);
  double lo = 1e9, hi = -1e9;
  for (const Vec3& d : p.log.d) {
    lo = std::min(lo, d[1]);
    hi = std::max(hi, d[1]);
  }
  const double centre = 0.5 * (lo + hi);
  std::string nodes, values;
  for (double x = lo - 0.01; x <= hi + 0.01; x += 0.0025) {
    nodes += (nodes.empty() ? "" : ",") + std::to_string(x);
    values += (values.empty() ? "" : ",") + std::to_string(bump(x, centre));
  }
  int within = 0, total = 0;
  for (std::uint64_t seed : {21u, 22u}) {
    const indep::GeneratedLog g = indep::generate(spec_with("table:2:d2:" + nodes + ":" + values, seed));
    ctl::MachineModel m = ctl::MachineModel::elkady();
    m.user_effects.push_back(table_over_data(g.log, 1, "d2", 25));
    const UserFit F = fit_user_effect(g.log, m, 0);
    const ctl::UserEffect& t = F.model.user_effects[0];
    double sum2 = 0.0, se2 = 0.0;
    for (std::size_t k = 0; k < t.nodes.size(); ++k) {
      const double err = t.values[k] - bump(t.nodes[k], centre);
      sum2 += err * err;
      se2 += F.std_error[k] * F.std_error[k];
      within += std::abs(err) < 3.0 * F.std_error[k] + 0.05 * 4.0 ? 1 : 0;  // its noise, or 5 % of the bump
      ++total;
    }
    const double rms_err = std::sqrt(sum2 / t.nodes.size()), rms_se = std::sqrt(se2 / t.nodes.size());
    std::printf("[ figures  ] seed %lu: table of %zu nodes over d2 [%.1f, %.1f] mm, GCV lambda %.3g (%.1f parameters): "
                "RMS error %.3f N, RMS standard error %.3f N (bump 4 N); force RMS %.4f -> %.4f N\n",
                static_cast<unsigned long>(seed), t.nodes.size(), lo * 1e3, hi * 1e3, F.lambda,
                F.effective_parameters, rms_err, rms_se, F.rms_before, F.rms_after);
    EXPECT_LT(rms_err, 0.1 * 4.0);
    EXPECT_LT(F.rms_after, F.rms_before);
  }
  EXPECT_GE(within, total * 9 / 10) << within << " of " << total << " nodes";
}

}  // namespace
}  // namespace cpm::ident
