// SPDX-License-Identifier: Apache-2.0
// Full-position calibration (Kim 4.1): exact recovery from the minimum of
// four poses, statistically honest recovery with noise, refusal of pose
// sets that cannot determine the planes, and the analytic Jacobian.
#include <gtest/gtest.h>

#include <random>

#include "cpm/calibration/poses.hpp"
#include "cpm/calibration/position.hpp"
#include "cpm/calibration/simulate.hpp"
#include "support/random_models.hpp"

using namespace cpm;
using namespace cpm::cal;

namespace {

// Measured positions of a true machine at encoder readings d: p = FK_true(d).
std::vector<Vec3> true_positions(const kin::KinematicModel& truth, const std::vector<Vec3>& d) {
  std::vector<Vec3> p;
  for (const Vec3& x : d) {
    Vec3 q;
    EXPECT_TRUE(kin::forward(truth, x, {}, q).ok());
    p.push_back(q);
  }
  return p;
}

std::vector<Vec3> random_readings(std::mt19937_64& rng, int n) {
  std::uniform_real_distribution<double> a(0.02, 0.38), c(0.02, 0.28);
  std::vector<Vec3> d;
  for (int k = 0; k < n; ++k) d.emplace_back(a(rng), a(rng), c(rng));
  return d;
}

}  // namespace

TEST(PositionCalibration, AnalyticSolutionIsExactFromFourPosesWithoutNoise) {
  std::mt19937_64 rng(11);
  for (int trial = 0; trial < 20; ++trial) {
    const kin::KinematicModel truth = test::random_calibrated_kinematics(rng, false);
    const std::vector<Vec3> d = random_readings(rng, 4);
    const std::vector<Vec3> p = true_positions(truth, d);
    const AnalyticSolution s = solve_positions_analytic(d, p, truth.d0);
    for (int i = 0; i < 3; ++i) {
      EXPECT_LT((s.planes[i].normal - truth.planes[i].normal).norm(), 1e-10) << "trial " << trial;
      EXPECT_NEAR(s.planes[i].scale, truth.planes[i].scale, 1e-10);
      EXPECT_NEAR(s.planes[i].offset, truth.planes[i].offset, 1e-11);
    }
  }
}

TEST(PositionCalibration, NonlinearRefinementKeepsTheExactSolution) {
  std::mt19937_64 rng(12);
  const kin::KinematicModel truth = test::random_calibrated_kinematics(rng, false);
  const std::vector<Vec3> d = random_readings(rng, 10);
  const PositionFit fit = fit_positions(kin::KinematicModel::nominal(), d, true_positions(truth, d));
  EXPECT_TRUE(fit.lm.converged) << fit.lm.reason;
  for (int i = 0; i < 3; ++i) {
    EXPECT_LT((fit.model.planes[i].normal - truth.planes[i].normal).norm(), 1e-11);
    EXPECT_NEAR(fit.model.planes[i].scale, truth.planes[i].scale, 1e-11);
    EXPECT_NEAR(fit.model.planes[i].offset, truth.planes[i].offset, 1e-12);
  }
  EXPECT_LT(fit.identifiability.residual_rms, 1e-12);
}

TEST(PositionCalibration, NoisyFitsAgreeWithTruthWithinTheirStandardErrors) {
  // Many random machines and seeds: the normalised errors (fitted - true)/se
  // must behave like a standard normal variable - almost all within 3 sigma,
  // mean square near 1 - which tests the standard errors as much as the fit.
  std::mt19937_64 rng(13);
  int total = 0, within3 = 0;
  double sum_z2 = 0.0, worst = 0.0;
  for (int trial = 0; trial < 30; ++trial) {
    const kin::KinematicModel truth = test::random_calibrated_kinematics(rng, false);
    const std::vector<Vec3> d = random_readings(rng, 25);
    std::vector<Vec3> p = true_positions(truth, d);
    std::normal_distribution<double> n(0.0, 5e-6);
    for (Vec3& q : p) q += Vec3(n(rng), n(rng), n(rng));
    const PositionFit fit = fit_positions(kin::KinematicModel::nominal(), d, p);
    ASSERT_TRUE(fit.lm.converged) << fit.lm.reason;
    const Identifiability& id = fit.identifiability;
    for (int i = 0; i < 3; ++i) {
      double ta, tb;
      tilts_from_normal(i, truth.planes[i].normal, ta, tb);
      const double t[4] = {ta, tb, truth.planes[i].scale, truth.planes[i].offset};
      for (int k = 0; k < 4; ++k) {
        const double z = (id.value[4 * i + k] - t[k]) / id.std_error[4 * i + k];
        sum_z2 += z * z;
        worst = std::max(worst, std::abs(z));
        within3 += std::abs(z) <= 3.0;
        ++total;
      }
    }
    EXPECT_NEAR(id.residual_sigma, 5e-6, 1.5e-6);
  }
  EXPECT_GE(within3, total - 2) << "of " << total;
  EXPECT_LT(worst, 4.5);
  EXPECT_NEAR(sum_z2 / total, 1.0, 0.3);
}

TEST(PositionCalibration, RefusesFewerThanFourPoses) {
  std::mt19937_64 rng(14);
  const std::vector<Vec3> d = random_readings(rng, 3);
  const std::vector<Vec3> p = true_positions(kin::KinematicModel::nominal(), d);
  try {
    solve_positions_analytic(d, p, kin::KinematicModel::nominal().d0);
    FAIL() << "three poses accepted";
  } catch (const DegeneratePoses& e) {
    EXPECT_NE(std::string(e.what()).find("at least 4 poses"), std::string::npos) << e.what();
  }
}

TEST(PositionCalibration, RefusesCoplanarPosesAndSaysWhereToAddPoses) {
  // Ten poses all at the same height z: the matrix of eq. 13 is singular.
  std::mt19937_64 rng(15);
  std::vector<Vec3> d = random_readings(rng, 10);
  for (Vec3& x : d) x.z() = 0.15;
  const std::vector<Vec3> p = true_positions(kin::KinematicModel::nominal(), d);
  try {
    fit_positions(kin::KinematicModel::nominal(), d, p);
    FAIL() << "coplanar poses accepted";
  } catch (const DegeneratePoses& e) {
    const std::string m = e.what();
    EXPECT_NE(m.find("eq. 13"), std::string::npos) << m;
    EXPECT_NE(m.find("in one plane"), std::string::npos) << m;
    EXPECT_NE(m.find("(0.00, 0.00, 1.00)"), std::string::npos) << m;  // add poses along z
  }
}

TEST(PositionCalibration, RefusesCollinearPoses) {
  std::vector<Vec3> d;
  for (int k = 0; k < 8; ++k) d.emplace_back(0.05 + 0.04 * k, 0.05 + 0.04 * k, 0.05 + 0.03 * k);
  const std::vector<Vec3> p = true_positions(kin::KinematicModel::nominal(), d);
  try {
    fit_positions(kin::KinematicModel::nominal(), d, p);
    FAIL() << "collinear poses accepted";
  } catch (const DegeneratePoses& e) {
    EXPECT_NE(std::string(e.what()).find("on a line"), std::string::npos) << e.what();
  }
}

TEST(PositionCalibration, AnalyticJacobianMatchesFiniteDifferences) {
  std::mt19937_64 rng(16);
  const kin::KinematicModel truth = test::random_calibrated_kinematics(rng, false);
  const std::vector<Vec3> d = random_readings(rng, 6);
  const std::vector<Vec3> p = true_positions(kin::KinematicModel::nominal(), d);
  VecX r;
  MatX J;
  position_residuals(truth.planes, truth.d0, d, p, r, &J);
  for (int j = 0; j < 12; ++j) {
    const int i = j / 4, k = j % 4;
    auto shifted = [&](double h) {
      auto pl = truth.planes;
      double ta, tb;
      tilts_from_normal(i, pl[i].normal, ta, tb);
      if (k == 0) pl[i].normal = normal_from_tilts(i, ta + h, tb);
      if (k == 1) pl[i].normal = normal_from_tilts(i, ta, tb + h);
      if (k == 2) pl[i].scale += h;
      if (k == 3) pl[i].offset += h;
      VecX rr;
      position_residuals(pl, truth.d0, d, p, rr, nullptr);
      return rr;
    };
    const double h = 1e-6;
    const VecX fd = (shifted(h) - shifted(-h)) / (2 * h);
    EXPECT_LT((fd - J.col(j)).cwiseAbs().maxCoeff(), 1e-8) << "column " << j;
  }
}

TEST(PositionCalibration, PlannedOptimalPosesDetermineEveryParameter) {
  const ctl::MachineModel m = ctl::MachineModel::elkady();
  const auto poses = optimal_position_poses(m, 12);
  ASSERT_EQ(poses.size(), 12u);
  std::vector<Vec3> d, p;
  for (const PlannedPose& q : poses) {
    EXPECT_TRUE(kin::check_pose(m.kinematics, m.strokes, q.p, {}).ok());
    d.push_back(q.d);
    p.push_back(q.p);
  }
  const AnalyticSolution s = solve_positions_analytic(d, p, m.kinematics.d0);
  for (int i = 0; i < 3; ++i) EXPECT_LT(s.condition[i], 10.0);
}
