// SPDX-License-Identifier: Apache-2.0
// The pitch table of a limb (d~ = d + e(d), docs/effects.md "Effects you add"):
// forward and inverse kinematics and the Jacobian carry it.
#include <gtest/gtest.h>

#include <cmath>
#include <random>

#include "cpm/kinematics/plane_model.hpp"
#include "support/random_models.hpp"

namespace cpm::kin {
namespace {

PitchTable table_of(const std::vector<double>& x, const std::vector<double>& y) {
  PitchTable t;
  t.size = static_cast<int>(x.size());
  for (int k = 0; k < t.size; ++k) {
    t.node[k] = x[k];
    t.error[k] = y[k];
  }
  return t;
}

TEST(PitchTable, InterpolatesLinearlyAndHoldsBeyondTheEnds) {
  const PitchTable t = table_of({0.0, 0.1, 0.3}, {0.0, 2e-6, -2e-6});
  double s = 0.0;
  EXPECT_DOUBLE_EQ(t(0.05, &s), 1e-6);
  EXPECT_DOUBLE_EQ(s, 2e-5);
  EXPECT_NEAR(t(0.2, &s), 0.0, 1e-20);
  EXPECT_DOUBLE_EQ(s, -2e-5);
  EXPECT_DOUBLE_EQ(t(-0.5, &s), 0.0);  // held at the first value
  EXPECT_EQ(s, 0.0);
  EXPECT_DOUBLE_EQ(t(0.7, &s), -2e-6);  // held at the last value
  EXPECT_EQ(s, 0.0);
}

TEST(PitchTable, LinearLawEqualsActuatorScale) {
  // e(d) = s d over the whole stroke is the actuator_scale effect s.
  const double s = 4e-4;
  std::mt19937_64 rng(3);
  for (int k = 0; k < 20; ++k) {
    KinematicModel scaled = test::random_calibrated_kinematics(rng, false);
    KinematicModel tabled = scaled;
    const int axis = k % 3;
    scaled.effects[axis].actuator_scale = s;
    tabled.effects[axis].pitch_table = table_of({-0.2, 0.1, 0.4, 0.7}, {-0.2 * s, 0.1 * s, 0.4 * s, 0.7 * s});
    ASSERT_NO_THROW(tabled.validate());
    const Vec3 d(0.05 + 0.04 * (k % 3), 0.12 + 0.01 * k, 0.2 - 0.005 * k);
    Vec3 p1, p2, d1, d2;
    Mat3 J1, J2, Ji1, Ji2;
    ASSERT_TRUE(forward(scaled, d, {}, p1));
    ASSERT_TRUE(forward(tabled, d, {}, p2));
    EXPECT_LT((p1 - p2).norm(), 1e-15);
    ASSERT_TRUE(inverse(scaled, p1, {}, d1, &Ji1));
    ASSERT_TRUE(inverse(tabled, p1, {}, d2, &Ji2));
    EXPECT_LT((d1 - d2).norm(), 1e-14);
    EXPECT_LT((Ji1 - Ji2).norm(), 1e-12);
    ASSERT_TRUE(jacobian(scaled, d, p1, {}, J1));
    ASSERT_TRUE(jacobian(tabled, d, p2, {}, J2));
    EXPECT_LT((J1 - J2).norm(), 1e-12);
  }
}

TEST(PitchTable, BumpRoundTripsAndJacobianIsTheDerivative) {
  // A 10 um bump over 100 mm of axis 2's travel, nodes every 10 mm.
  std::vector<double> x, y;
  for (int k = 0; k <= 40; ++k) {
    x.push_back(0.01 * k);
    y.push_back(10e-6 * std::exp(-std::pow((0.01 * k - 0.2) / 0.05, 2)));
  }
  KinematicModel m = KinematicModel::nominal();
  m.effects[1].pitch_table = table_of(x, y);
  ASSERT_NO_THROW(m.validate());
  const Vec3 d(0.1, 0.183, 0.2);  // inside a segment: the interpolant is differentiable there
  Vec3 p, d_back;
  ASSERT_TRUE(forward(m, d, {}, p));
  // Nominal planes: p_y = d~_y + d0_y exactly.
  double slope = 0.0;
  const double e = m.effects[1].pitch_table(d[1], &slope);
  EXPECT_NEAR(p.y(), d[1] + e + m.d0[1], 1e-15);
  ASSERT_TRUE(inverse(m, p, {}, d_back));
  EXPECT_LT((d_back - d).norm(), 1e-14);
  Mat3 J;
  ASSERT_TRUE(jacobian(m, d, p, {}, J));
  const double h = 1e-6;
  Vec3 pp, pm;
  ASSERT_TRUE(forward(m, d + Vec3(0, h, 0), {}, pp));
  ASSERT_TRUE(forward(m, d - Vec3(0, h, 0), {}, pm));
  EXPECT_NEAR(J(1, 1), (pp.y() - pm.y()) / (2 * h), 1e-9);
  EXPECT_NEAR(J(1, 1), 1.0 + slope, 1e-15);
}

TEST(PitchTable, RefusesBadTablesNamingTheLimbAndTheNode) {
  KinematicModel m = KinematicModel::nominal();
  m.effects[2].pitch_table = table_of({0.0, 0.2, 0.1}, {0.0, 0.0, 0.0});
  try {
    m.validate();
    FAIL() << "accepted nodes that go back";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("limb 3"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("node 2"), std::string::npos) << e.what();
  }
  m.effects[2].pitch_table = table_of({0.0}, {0.0});
  EXPECT_THROW(m.validate(), Error);
  m.effects[2].pitch_table = table_of({0.0, 0.001}, {0.0, 0.001});  // slope 1: not a pitch error
  EXPECT_THROW(m.validate(), Error);
}

}  // namespace
}  // namespace cpm::kin
