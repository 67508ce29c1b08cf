// SPDX-License-Identifier: Apache-2.0
// The limb solver checked against itself (finite differences), against the
// paper's own Gamma and against docs/model.md's reference angles.
#include <gtest/gtest.h>

#include <cmath>
#include <numbers>
#include <random>

#include "cpm/kinematics/limbs.hpp"
#include "support/random_models.hpp"

namespace cpm::kin {
namespace {

constexpr double kDeg = std::numbers::pi / 180.0;

TEST(Limbs, DefaultAssemblyModesGiveMachineMdReferenceAngles) {
  const LimbGeometry g = LimbGeometry::elkady();
  LimbPose pose;
  ASSERT_TRUE(solve_limbs(g, Vec3(0.600, 0.425, 0.300), pose));
  // docs/model.md gives the angles to 0.01 degree.
  EXPECT_NEAR(pose.theta()[0], 89.41 * kDeg, 0.006 * kDeg);
  EXPECT_NEAR(pose.theta()[1], 19.17 * kDeg, 0.006 * kDeg);
  EXPECT_NEAR(pose.theta()[2], 2.89 * kDeg, 0.006 * kDeg);
}

TEST(Limbs, LinksHaveTheirLengths) {
  // Rebuild M_i from theta with docs/model.md's formulas and check |B - M| = L2.
  const LimbGeometry g = LimbGeometry::elkady();
  std::mt19937_64 rng(1);
  for (int k = 0; k < 200; ++k) {
    const Vec3 p = test::random_platform_point(rng);
    LimbPose pose;
    ASSERT_TRUE(solve_limbs(g, p, pose));
    const double t1 = pose.theta()[0], t2 = pose.theta()[1], t3 = pose.theta()[2];
    const Eigen::Vector2d M1(g.L1 * std::cos(t1), g.L1 * std::sin(t1));
    const Eigen::Vector2d B1(p.y() - g.L, p.z());
    const Eigen::Vector2d M2(g.L1 * std::sin(t2), g.L1 * std::cos(t2));
    const Eigen::Vector2d B2(p.x() - g.L, p.z());
    const Eigen::Vector2d M3(g.L1 * std::cos(t3), g.D - g.L1 * std::sin(t3));
    const Eigen::Vector2d B3(p.x(), p.y() + g.L);
    EXPECT_NEAR((B1 - M1).norm(), g.L2, 1e-12);
    EXPECT_NEAR((B2 - M2).norm(), g.L2, 1e-12);
    EXPECT_NEAR((B3 - M3).norm(), g.L2, 1e-12);
  }
}

// Elkady's eq. 1, typed from the paper, as an independent check of our Gamma.
Mat3 elkady_gamma(const LimbGeometry& g, const Vec3& p, const Vec3& th) {
  const double x = p.x(), y = p.y(), z = p.z(), L = g.L, L1 = g.L1, D = g.D;
  const double s1 = std::sin(th[0]), c1 = std::cos(th[0]);
  const double s2 = std::sin(th[1]), c2 = std::cos(th[1]);
  const double s3 = std::sin(th[2]), c3 = std::cos(th[2]);
  Mat3 G;
  const double d1 = ((y - L) * s1 - z * c1) * L1;
  const double d2 = L1 * (z * s2 + (L - x) * c2);
  const double d3 = (x * s3 + c3 * (y - D + L)) * L1;
  G << 0.0, (y - L1 * c1 - L) / d1, (z - L1 * s1) / d1,
       (x - L1 * s2 - L) / d2, 0.0, (z - L1 * c2) / d2,
       (x - L1 * c3) / d3, (y - D + L1 * s3 + L) / d3, 0.0;
  return -G;
}

TEST(Limbs, GammaMatchesElkadyEquation1) {
  const LimbGeometry g = LimbGeometry::elkady();
  std::mt19937_64 rng(2);
  for (int k = 0; k < 200; ++k) {
    const Vec3 p = test::random_platform_point(rng);
    LimbPose pose;
    ASSERT_TRUE(solve_limbs(g, p, pose));
    EXPECT_LT((pose.Gamma - elkady_gamma(g, p, pose.theta())).norm(), 1e-10 * pose.Gamma.norm());
  }
}

TEST(Limbs, GammaIsTheDerivativeOfTheLimbAngles) {
  const LimbGeometry g = LimbGeometry::elkady();
  std::mt19937_64 rng(3);
  const double h = 1e-6;
  for (int k = 0; k < 100; ++k) {
    const Vec3 p = test::random_platform_point(rng);
    LimbPose pose, plus, minus;
    ASSERT_TRUE(solve_limbs(g, p, pose));
    Mat3 fd;
    for (int j = 0; j < 3; ++j) {
      ASSERT_TRUE(solve_limbs(g, p + h * Vec3::Unit(j), plus));
      ASSERT_TRUE(solve_limbs(g, p - h * Vec3::Unit(j), minus));
      fd.col(j) = (plus.theta() - minus.theta()) / (2 * h);
    }
    EXPECT_LT((pose.Gamma - fd).cwiseAbs().maxCoeff(), 1e-6 * (1.0 + pose.Gamma.cwiseAbs().maxCoeff()));
  }
}

TEST(Limbs, GammaDotIsTheTimeDerivativeOfGamma) {
  const LimbGeometry g = LimbGeometry::elkady();
  std::mt19937_64 rng(4);
  std::uniform_real_distribution<double> uv(-0.5, 0.5);
  const double h = 1e-6;
  for (int k = 0; k < 100; ++k) {
    const Vec3 p = test::random_platform_point(rng);
    const Vec3 v(uv(rng), uv(rng), uv(rng));
    LimbMotion m;
    LimbPose plus, minus;
    ASSERT_TRUE(solve_limb_motion(g, p, v, m));
    ASSERT_TRUE(solve_limbs(g, p + h * v, plus));
    ASSERT_TRUE(solve_limbs(g, p - h * v, minus));
    const Mat3 fd = (plus.Gamma - minus.Gamma) / (2 * h);
    EXPECT_LT((m.Gamma_dot - fd).cwiseAbs().maxCoeff(), 1e-5 * (1.0 + fd.cwiseAbs().maxCoeff()));
    EXPECT_LT((m.theta_dot - m.pose.Gamma * v).norm(), 1e-12);
  }
}

TEST(Limbs, ElbowGradientMatchesFiniteDifferences) {
  const LimbGeometry g = LimbGeometry::elkady();
  std::mt19937_64 rng(5);
  const double h = 1e-6;
  for (int k = 0; k < 100; ++k) {
    const Vec3 p = test::random_platform_point(rng);
    Mat3 grad, fd;
    ASSERT_TRUE(elbow_gradient(g, p, grad));
    for (int j = 0; j < 3; ++j) {
      LimbPose plus, minus;
      ASSERT_TRUE(solve_limbs(g, p + h * Vec3::Unit(j), plus));
      ASSERT_TRUE(solve_limbs(g, p - h * Vec3::Unit(j), minus));
      fd.col(j) = (plus.elbow() - minus.elbow()) / (2 * h);
    }
    EXPECT_LT((grad - fd).cwiseAbs().maxCoeff(), 1e-6 * (1.0 + fd.cwiseAbs().maxCoeff()));
  }
}

TEST(Limbs, ModesStayContinuousAlongAMotion) {
  // Along a straight line through the workspace the angles change smoothly:
  // no jump from one assembly mode to the other.
  const LimbGeometry g = LimbGeometry::elkady();
  const Vec3 a(0.28, 0.30, 0.26), b(0.58, 0.55, 0.47);
  LimbPose prev;
  ASSERT_TRUE(solve_limbs(g, a, prev));
  for (int k = 1; k <= 1000; ++k) {
    LimbPose cur;
    ASSERT_TRUE(solve_limbs(g, a + (b - a) * (k / 1000.0), cur));
    EXPECT_LT((cur.theta() - prev.theta()).cwiseAbs().maxCoeff(), 2.0 * kDeg);
    prev = cur;
  }
}

TEST(Limbs, RefusesUnreachableSingularAndNonFinitePoints) {
  const LimbGeometry g = LimbGeometry::elkady();
  LimbPose pose;
  // Limb 3 reaches from A3 = (0, D) to B3 = (x, y + L): straight at L1 + L2.
  const double dy = 0.425 + g.L - g.D;
  const double x_straight = std::sqrt(std::pow(g.L1 + g.L2, 2) - dy * dy);
  Status s = solve_limbs(g, Vec3(x_straight - 1e-4, 0.425, 0.3), pose);
  EXPECT_EQ(s.fault, Fault::near_singularity);
  EXPECT_EQ(s.index, 2);
  s = solve_limbs(g, Vec3(x_straight + 1e-3, 0.425, 0.3), pose);
  EXPECT_EQ(s.fault, Fault::limb_unreachable);
  EXPECT_EQ(s.index, 2);
  EXPECT_NE(describe(s).find("limb 3"), std::string::npos);
  s = solve_limbs(g, Vec3(0.4, std::nan(""), 0.3), pose);
  EXPECT_EQ(s.fault, Fault::not_finite);
  LimbMotion m;
  EXPECT_EQ(solve_limb_motion(g, Vec3(0.4, 0.4, 0.3), Vec3(0, INFINITY, 0), m).fault, Fault::not_finite);
}

}  // namespace
}  // namespace cpm::kin
