// SPDX-License-Identifier: Apache-2.0
// Calibrated plane kinematics (Kim eqs. 1-7) with the effects of docs/effects.md.
#include <gtest/gtest.h>

#include <cmath>
#include <numbers>
#include <random>

#include "cpm/kinematics/kinematic_effects.hpp"
#include "cpm/kinematics/plane_model.hpp"
#include "cpm/kinematics/workspace.hpp"
#include "support/random_models.hpp"

namespace cpm::kin {
namespace {

TEST(PlaneModel, NominalIsKimEquation1) {
  const KinematicModel m = KinematicModel::nominal();
  const Vec3 d(0.1, 0.2, 0.05);
  Vec3 p, d2;
  Mat3 J;
  ASSERT_TRUE(forward(m, d, {}, p));
  EXPECT_LT((p - (d + Vec3(0.2250, 0.2250, 0.2268))).norm(), 1e-15);
  ASSERT_TRUE(inverse(m, p, {}, d2));
  EXPECT_LT((d2 - d).norm(), 1e-15);
  ASSERT_TRUE(jacobian(m, d, p, {}, J));
  EXPECT_LT((J - Mat3::Identity()).norm(), 1e-15);
}

TEST(PlaneModel, PlatformPointLiesOnEveryLimbPlane) {
  // Kim eq. 4: u_i^T p = (d_i + d0_i) c_i + n_i for each limb.
  std::mt19937_64 rng(10);
  for (int k = 0; k < 100; ++k) {
    const KinematicModel m = test::random_calibrated_kinematics(rng, false);
    const Vec3 d(0.05 + 0.3 * (k % 7) / 7.0, 0.1 + 0.02 * (k % 5), 0.02 + 0.25 * (k % 3) / 3.0);
    Vec3 p;
    ASSERT_TRUE(forward(m, d, {}, p));
    for (int i = 0; i < 3; ++i)
      EXPECT_NEAR(m.planes[i].normal.dot(p), (d[i] + m.d0[i]) * m.planes[i].scale + m.planes[i].offset,
                  1e-14);
  }
}

class RandomModels : public ::testing::TestWithParam<bool> {};

TEST_P(RandomModels, ForwardAfterInverseIsTheIdentity) {
  const bool effects = GetParam();
  std::mt19937_64 rng(effects ? 12 : 11);
  std::uniform_int_distribution<int> dir(0, 1);
  for (int k = 0; k < 300; ++k) {
    const KinematicModel m = test::random_calibrated_kinematics(rng, effects);
    const Vec3 p = test::random_platform_point(rng);
    KinematicInputs in;
    for (auto& s : in.dir) s = dir(rng) ? 1 : -1;
    in.t = 100.0 * (k % 10);
    Vec3 d, p2, d2;
    ASSERT_TRUE(inverse(m, p, in, d));
    ASSERT_TRUE(forward(m, d, in, p2));
    EXPECT_LT((p2 - p).norm(), 1e-12) << "model " << k;
    ASSERT_TRUE(inverse(m, p2, in, d2));
    EXPECT_LT((d2 - d).norm(), 1e-12) << "model " << k;
  }
}

TEST_P(RandomModels, JacobianIsTheDerivativeOfForwardKinematics) {
  const bool effects = GetParam();
  std::mt19937_64 rng(effects ? 14 : 13);
  const double h = 1e-7;
  for (int k = 0; k < 100; ++k) {
    const KinematicModel m = test::random_calibrated_kinematics(rng, effects);
    const Vec3 p0 = test::random_platform_point(rng);
    KinematicInputs in;
    in.t = 50.0;
    Vec3 d, p, pp, pm;
    Mat3 J, fd;
    ASSERT_TRUE(inverse(m, p0, in, d));
    ASSERT_TRUE(forward(m, d, in, p));
    ASSERT_TRUE(jacobian(m, d, p, in, J));
    for (int j = 0; j < 3; ++j) {
      ASSERT_TRUE(forward(m, d + h * Vec3::Unit(j), in, pp));
      ASSERT_TRUE(forward(m, d - h * Vec3::Unit(j), in, pm));
      fd.col(j) = (pp - pm) / (2 * h);
    }
    EXPECT_LT((J - fd).cwiseAbs().maxCoeff(), 1e-7) << "model " << k;
  }
}

TEST_P(RandomModels, InverseJacobianIsTheDerivativeOfInverseKinematics) {
  const bool effects = GetParam();
  std::mt19937_64 rng(effects ? 16 : 15);
  const double h = 1e-7;
  for (int k = 0; k < 100; ++k) {
    const KinematicModel m = test::random_calibrated_kinematics(rng, effects);
    const Vec3 p = test::random_platform_point(rng);
    KinematicInputs in;
    in.t = 50.0;
    Vec3 d, dp, dm;
    Mat3 J, J_inv, fd;
    ASSERT_TRUE(inverse(m, p, in, d));
    ASSERT_TRUE(inverse_jacobian(m, d, p, in, J_inv));
    for (int j = 0; j < 3; ++j) {
      ASSERT_TRUE(inverse(m, p + h * Vec3::Unit(j), in, dp));
      ASSERT_TRUE(inverse(m, p - h * Vec3::Unit(j), in, dm));
      fd.col(j) = (dp - dm) / (2 * h);
    }
    EXPECT_LT((J_inv - fd).cwiseAbs().maxCoeff(), 1e-7) << "model " << k;
    Mat3 J_inv_newton;  // the by-product of the inverse kinematics' Newton solve
    ASSERT_TRUE(inverse(m, p, in, dp, &J_inv_newton));
    EXPECT_LT((J_inv_newton - J_inv).cwiseAbs().maxCoeff(), 1e-12) << "model " << k;
    ASSERT_TRUE(jacobian(m, d, p, in, J));
    EXPECT_LT((J * J_inv - Mat3::Identity()).cwiseAbs().maxCoeff(), 1e-12) << "model " << k;
  }
}

INSTANTIATE_TEST_SUITE_P(WithAndWithoutEffects, RandomModels, ::testing::Bool());

TEST(KinematicEffects, EachMatchesItsEquation) {
  // docs/effects.md, written out again for one limb at a time.
  const Vec3 u = Vec3(1.0, 0.001, -0.002).normalized();
  const double d = 0.1234, t = 300.0;
  constexpr double kTwoPi = 2.0 * std::numbers::pi;
  LimbKinematicEffects e;
  e.backlash = 40e-6;
  EXPECT_DOUBLE_EQ(effective_displacement(e, d, +1, t), d - 20e-6);
  EXPECT_DOUBLE_EQ(effective_displacement(e, d, -1, t), d + 20e-6);
  e = {};
  e.cyclic_amplitude = 3e-6;
  e.cyclic_wavelength = 5e-3;
  e.cyclic_phase = 0.7;
  EXPECT_DOUBLE_EQ(effective_displacement(e, d, 1, t), d + 3e-6 * std::sin(kTwoPi * d / 5e-3 + 0.7));
  e = {};
  e.thermal_expansion = 2e-5;
  e.thermal_time_constant = 900.0;
  EXPECT_NEAR(effective_displacement(e, d, 1, t), d * (1 + 2e-5 * (1 - std::exp(-t / 900.0))), 1e-17);
  e = {};
  e.actuator_scale = 3e-4;
  EXPECT_NEAR(effective_displacement(e, d, 1, t), 1.0003 * d, 1e-17);
  e = {};
  e.guide_ka = 2e-3;
  e.guide_kb = -1e-3;
  // Limb 2 (index 1): the other axes are x and z.
  const Vec3 expect = (u + d * Vec3(2e-3, 0.0, -1e-3)).normalized();
  EXPECT_LT((effective_normal(e, 1, u, d) - expect).norm(), 1e-16);
}

TEST(KinematicEffects, LimbTwistShiftsThePlaneBySineOfElbow) {
  KinematicModel m = KinematicModel::nominal();
  m.effects[0].twist = 1e-3;
  const Vec3 p(0.45, 0.40, 0.35);
  Vec3 d, d_nom;
  ASSERT_TRUE(inverse(m, p, {}, d));
  ASSERT_TRUE(inverse(KinematicModel::nominal(), p, {}, d_nom));
  LimbPose pose;
  ASSERT_TRUE(solve_limbs(m.limbs, p, pose));
  // u^T p = (d + d0) + n + alpha L2 sin(phi) with u = e_x, c = 1.
  EXPECT_NEAR(d[0], d_nom[0] - 1e-3 * m.limbs.L2 * std::sin(pose.elbow()[0]), 1e-15);
  EXPECT_DOUBLE_EQ(d[1], d_nom[1]);
}

TEST(KinematicEffects, NamesAndParametersRoundTrip) {
  for (int k = 0; k < kKinematicEffectTypes; ++k) {
    const auto t = static_cast<KinematicEffectType>(k);
    const auto& in = info(t);
    ASSERT_EQ(kinematic_effect_from_name(in.name), t);
    LimbKinematicEffects e;
    std::array<double, 3> v{};
    for (int j = 0; j < in.n_params; ++j) v[j] = 0.5 * (in.params[j].lower + in.params[j].upper) + 1e-4 * (j + 1);
    set_params(e, t, v);
    EXPECT_EQ(get_params(e, t), v) << in.name;
  }
  EXPECT_FALSE(kinematic_effect_from_name("no_such_effect"));
}

TEST(PlaneModel, ValidateRefusesBadModelsSayingWhere) {
  auto expect_error = [](const KinematicModel& m, const std::string& part) {
    try {
      m.validate();
      ADD_FAILURE() << "accepted a bad model, expected: " << part;
    } catch (const Error& e) {
      EXPECT_NE(std::string(e.what()).find(part), std::string::npos) << e.what();
    }
  };
  KinematicModel m = KinematicModel::nominal();
  m.planes[1].normal = Vec3(0.0, 2.0, 0.0);
  expect_error(m, "limb 2");
  m = KinematicModel::nominal();
  m.planes[2].scale = std::nan("");
  expect_error(m, "limb 3");
  m = KinematicModel::nominal();
  m.planes[2].normal = Vec3(0.0, 1.0, 0.0);  // parallel to limb 2's plane
  expect_error(m, "limb 3");
  m = KinematicModel::nominal();
  m.effects[0].cyclic_amplitude = 1e-6;  // no wavelength
  expect_error(m, "wavelength");
  m = KinematicModel::nominal();
  m.effects[0].backlash = -1e-6;
  expect_error(m, "backlash");
}

TEST(PlaneModel, RefusesNonFiniteInput) {
  const KinematicModel m = KinematicModel::nominal();
  Vec3 out;
  Mat3 J;
  EXPECT_EQ(forward(m, Vec3(0.1, NAN, 0.1), {}, out).fault, Fault::not_finite);
  EXPECT_EQ(inverse(m, Vec3(INFINITY, 0.3, 0.3), {}, out).fault, Fault::not_finite);
  EXPECT_EQ(jacobian(m, Vec3(0.1, 0.1, 0.1), Vec3(NAN, 0, 0), {}, J).fault, Fault::not_finite);
  KinematicInputs in;
  in.t = NAN;
  EXPECT_EQ(forward(m, Vec3(0.1, 0.1, 0.1), in, out).fault, Fault::not_finite);
}

TEST(Workspace, SaysWhichLimitAPoseBreaks) {
  const KinematicModel m = KinematicModel::nominal();
  const Strokes s;
  Status st = check_pose(m, s, Vec3(0.4, 0.4, 0.35), {});
  EXPECT_TRUE(st.ok()) << describe(st);
  // x = 0.2 is 25 mm before the x stroke starts (d1 = -0.025).
  st = check_pose(m, s, Vec3(0.2, 0.4, 0.35), {});
  EXPECT_EQ(st.fault, Fault::stroke_low);
  EXPECT_EQ(st.index, 0);
  EXPECT_NEAR(st.value, -0.025, 1e-12);
  EXPECT_NE(describe(st).find("actuator 1"), std::string::npos);
  // z = 0.53 is beyond the z stroke of 0.3 m (d3 = 0.3032).
  st = check_pose(m, s, Vec3(0.4, 0.4, 0.53), {});
  EXPECT_EQ(st.fault, Fault::stroke_high);
  EXPECT_EQ(st.index, 2);
  EXPECT_EQ(check_pose(m, s, Vec3(NAN, 0.4, 0.4), {}).fault, Fault::not_finite);
  WorkspaceMargins margins;
  ASSERT_TRUE(check_pose(m, s, Vec3(0.3, 0.5, 0.4), {}, &margins));
  EXPECT_NEAR(margins.stroke_low.x(), 0.075, 1e-12);
  EXPECT_NEAR(margins.stroke_high.y(), 0.125, 1e-12);
  EXPECT_GT(margins.elbow.minCoeff(), 0.05);
}

}  // namespace
}  // namespace cpm::kin
