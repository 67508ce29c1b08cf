// SPDX-License-Identifier: Apache-2.0
// cpm compare as MATLAB's compare and resid know it (report.hpp): on two
// simulated logs of the nominal machine, one with nothing missing from the
// model and one with dry friction on axis 2 the model lacks, the fit per
// axis and the residual's autocorrelation against its 99 % band: inside it
// without the effect, far outside with it.
#include <gtest/gtest.h>

#include <cstdio>

#include "cpm/identification/align.hpp"
#include "cpm/identification/report.hpp"
#include "identification/sim_data.hpp"

namespace cpm::ident {
namespace {

struct Judged {
  ResidualSummary s;
  ResidualCorrelation c;
  Alignment A;
};

Judged judge(const io::MotionData& data) {
  const ctl::Machine model(ctl::MachineModel::elkady());
  const MotionOptions mo;
  MotionProblem P = prepare_motion(data, model, mo);
  Judged j;
  j.A = align_motion(data, model, mo);
  P.set_delay(j.A.reference);
  j.s = summarize(P, P.residual);
  j.c = residual_correlation(P, P.residual, 20);
  return j;
}

TEST(Resid, AutocorrelationInsideTheBandsWithoutAMissingEffectOutsideWithOne) {
  test::SimSpec clean;
  clean.duration = 20.0;
  clean.base_errors = false;  // the model is the truth but for the encoders' noise
  test::SimSpec missing = clean;
  missing.effects = {{"coulomb_friction", 1, {2.0}}};
  const Judged a = judge(test::simulate(clean)), b = judge(test::simulate(missing));
  for (const Judged* j : {&a, &b}) {
    std::printf("%s: fit %.2f %.2f %.2f %%; %d rows, band +-%.3f; autocorrelation outside at %d %d %d of %d lags "
                "(largest |r| %.3f %.3f %.3f)\n",
                j == &a ? "nothing missing" : "coulomb_friction[axis 2] missing", j->s.fit_percent[0],
                j->s.fit_percent[1], j->s.fit_percent[2], j->c.rows, j->c.band, j->c.auto_outside[0],
                j->c.auto_outside[1], j->c.auto_outside[2], j->c.lags, j->c.auto_largest[0], j->c.auto_largest[1],
                j->c.auto_largest[2]);
  }
  ASSERT_EQ(a.c.lags, 20);
  EXPECT_NEAR(a.c.band, 2.5758 / std::sqrt(a.c.rows), 1e-12);
  EXPECT_DOUBLE_EQ(a.c.autocorrelation[0][0], 1.0);
  // Nothing missing: at 99 % about 1 lag in 100 falls outside; 60 lags here.
  EXPECT_LE(a.c.auto_outside[0] + a.c.auto_outside[1] + a.c.auto_outside[2], 3);
  // Dry friction missing on axis 2: its residual is the friction's square wave, correlated over many lags.
  EXPECT_GE(b.c.auto_outside[1], 15);
  EXPECT_GT(b.c.auto_largest[1], 5.0 * b.c.band);
  // and it follows the velocity's sign: correlated with the velocity.
  EXPECT_GT(b.c.cross_outside[1][1], 10);
  // The fit: what the encoders' noise leaves without (about 0.07 N of a force
  // that swings by a few N: 91-97 %), far less on axis 2 with the friction
  // missing (2 N of a square wave: 12 %), the other axes unchanged.
  for (int i = 0; i < 3; ++i) EXPECT_GT(a.s.fit_percent[i], 85.0) << i;
  EXPECT_LT(b.s.fit_percent[1], a.s.fit_percent[1] - 50.0);
  EXPECT_NEAR(b.s.fit_percent[0], a.s.fit_percent[0], 2.0);
}

TEST(Resid, FitPercentIsNrmseBased) {
  // y = model + residual on made-up rows: fit = 100 (1 - |e| / |y - mean y|).
  MotionProblem P;
  const int R = 4;
  P.sample = {0, 1, 2, 3};
  P.t = {0.0, 0.001, 0.002, 0.003};
  P.d.assign(R, Vec3::Zero());
  P.v.assign(R, Vec3::Zero());
  P.model_force = Eigen::VectorXd::Zero(3 * R);
  Eigen::VectorXd e = Eigen::VectorXd::Zero(3 * R);
  const double y[R] = {1.0, 3.0, 5.0, 7.0}, yhat[R] = {1.5, 2.5, 5.5, 6.5};
  for (int r = 0; r < R; ++r) {
    P.model_force(3 * r) = yhat[r];
    e(3 * r) = y[r] - yhat[r];
  }
  const ResidualSummary s = summarize(P, e, 2);
  // |e| = 1, |y - mean| = sqrt(9 + 1 + 1 + 9) = sqrt(20).
  EXPECT_NEAR(s.fit_percent[0], 100.0 * (1.0 - 1.0 / std::sqrt(20.0)), 1e-12);
}

TEST(Resid, CompareSaysWhatTheAlignmentMeans) {
  Alignment A;
  A.period = 1e-3;
  A.model_tau = 0.0;
  A.tau = 1.453e-3;
  A.reference = 0.5e-3;
  const std::string t = alignment_text(A);
  EXPECT_NE(t.find("acts 1.453 ms after t_k"), std::string::npos) << t;
  EXPECT_NE(t.find("compared at 0.500 ms, the nearest it can take: the other 0.953 ms is a delay it misses"),
            std::string::npos)
      << t;
  A.tau = A.reference = 0.2e-3;
  EXPECT_NE(alignment_text(A).find("how the log was sampled. Compared there."), std::string::npos) << alignment_text(A);
}

}  // namespace
}  // namespace cpm::ident
