// SPDX-License-Identifier: Apache-2.0
// The solver and the statistics under the calibration: LM against problems
// with known minima, the Student t quantile against tabulated values, the
// identifiability analysis against a problem whose covariance is known in
// closed form.
#include <gtest/gtest.h>

#include <cmath>
#include <random>

#include "cpm/calibration/identifiability.hpp"
#include "cpm/calibration/least_squares.hpp"

using namespace cpm;
using namespace cpm::cal;

TEST(LevenbergMarquardt, FindsRosenbrocksMinimumFromTheClassicStart) {
  // r = (10 (x2 - x1^2), 1 - x1): minimum 0 at (1, 1).
  const ResidualFunction f = [](const VecX& x, VecX& r, MatX* J) {
    r.resize(2);
    r << 10.0 * (x[1] - x[0] * x[0]), 1.0 - x[0];
    if (J) {
      J->resize(2, 2);
      *J << -20.0 * x[0], 10.0, -1.0, 0.0;
    }
  };
  VecX x(2);
  x << -1.2, 1.0;
  const LmReport rep = levenberg_marquardt(f, x, {});
  EXPECT_TRUE(rep.converged) << rep.reason;
  EXPECT_NEAR(x[0], 1.0, 1e-10);
  EXPECT_NEAR(x[1], 1.0, 1e-10);
  EXPECT_LT(rep.final_cost, 1e-20);
  EXPECT_GT(rep.initial_cost, 1.0);
}

TEST(LevenbergMarquardt, FitsAnExponentialWithNoiseToTheLinearisedOptimum) {
  // y = a exp(b t) + noise; at the optimum J^T r = 0.
  std::mt19937_64 rng(3);
  std::normal_distribution<double> n(0.0, 0.01);
  std::vector<double> t, y;
  for (int k = 0; k < 50; ++k) {
    t.push_back(0.05 * k);
    y.push_back(2.0 * std::exp(-1.3 * t.back()) + n(rng));
  }
  const ResidualFunction f = [&](const VecX& x, VecX& r, MatX* J) {
    r.resize(50);
    if (J) J->resize(50, 2);
    for (int k = 0; k < 50; ++k) {
      const double e = std::exp(x[1] * t[k]);
      r[k] = x[0] * e - y[k];
      if (J) {
        (*J)(k, 0) = e;
        (*J)(k, 1) = x[0] * t[k] * e;
      }
    }
  };
  VecX x(2);
  x << 1.0, 0.0;
  const LmReport rep = levenberg_marquardt(f, x, {});
  EXPECT_TRUE(rep.converged) << rep.reason;
  VecX r;
  MatX J;
  f(x, r, &J);
  EXPECT_LT((J.transpose() * r).cwiseAbs().maxCoeff(), 1e-10);
  EXPECT_NEAR(x[0], 2.0, 0.05);
  EXPECT_NEAR(x[1], -1.3, 0.05);
}

TEST(StudentT, QuantilesMatchTables) {
  EXPECT_NEAR(student_t_quantile(0.95, 1), 12.7062, 1e-3);
  EXPECT_NEAR(student_t_quantile(0.95, 10), 2.22814, 1e-4);
  EXPECT_NEAR(student_t_quantile(0.99, 5), 4.03214, 1e-4);
  EXPECT_NEAR(student_t_quantile(0.95, 100000), 1.95996, 1e-4);
}

TEST(Identifiability, StraightLineFitHasTheTextbookCovariance) {
  // y = a + b t: cov = s^2 (X^T X)^-1 in closed form.
  const int N = 20;
  MatX J(N, 2);
  VecX r(N);
  std::mt19937_64 rng(5);
  std::normal_distribution<double> n(0.0, 1.0);
  for (int k = 0; k < N; ++k) {
    J(k, 0) = 1.0;
    J(k, 1) = k;
    r[k] = n(rng);
  }
  // Make r a least-squares residual (orthogonal to the columns).
  r -= J * (J.transpose() * J).ldlt().solve(J.transpose() * r);
  VecX x(2);
  x << 1.0, 2.0;
  const Identifiability id = analyse_identifiability(J, r, x, {"a", "b"}, {"m", "m/s"});
  const double s2 = r.squaredNorm() / (N - 2);
  const MatX cov = s2 * (J.transpose() * J).inverse();
  EXPECT_NEAR(id.std_error[0], std::sqrt(cov(0, 0)), 1e-12);
  EXPECT_NEAR(id.std_error[1], std::sqrt(cov(1, 1)), 1e-12);
  EXPECT_NEAR(id.correlation(0, 1), cov(0, 1) / std::sqrt(cov(0, 0) * cov(1, 1)), 1e-12);
  EXPECT_EQ(id.dof, N - 2);
  EXPECT_NEAR(id.ci_high[1] - id.value[1], student_t_quantile(0.95, N - 2) * id.std_error[1], 1e-12);
  EXPECT_TRUE(id.weak.empty());
}

TEST(Identifiability, NamesACombinationTheDataCannotSee) {
  // Columns 0 and 1 identical: only their sum is determined.
  MatX J(10, 3);
  for (int k = 0; k < 10; ++k) {
    J(k, 0) = J(k, 1) = std::sin(0.3 * k) + 1.0;
    J(k, 2) = k;
  }
  VecX r = VecX::Constant(10, 1e-3);
  VecX x = VecX::Zero(3);
  const Identifiability id = analyse_identifiability(J, r, x, {"p", "q", "s"}, {"1", "1", "1"});
  ASSERT_EQ(id.weak.size(), 1u);
  EXPECT_TRUE(id.weak[0].undetermined);
  EXPECT_FALSE(std::isfinite(id.std_error[0]));
  EXPECT_FALSE(std::isfinite(id.std_error[1]));
  EXPECT_TRUE(std::isfinite(id.std_error[2]));
  ASSERT_FALSE(id.warnings.empty());
  EXPECT_NE(id.warnings[0].find("cannot be determined"), std::string::npos);
  EXPECT_NE(id.warnings[0].find("p"), std::string::npos);
  EXPECT_NE(id.warnings[0].find("q"), std::string::npos);
}
