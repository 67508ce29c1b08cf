// SPDX-License-Identifier: Apache-2.0
// The four control laws, the force limit, and the real-time contract of a
// control step (no heap allocation, no exception, a status on bad input).
#include <gtest/gtest.h>

#include <cmath>
#include <random>

#include "cpm/control/controller.hpp"
#include "support/allocation_counter.hpp"
#include "support/random_models.hpp"

namespace cpm::ctl {
namespace {

ControlInput input_at(const Machine& m, const TrajectorySample& ref, const Vec3& dp, const Vec3& dv) {
  ControlInput in;
  in.ref = ref;
  EXPECT_TRUE(kin::inverse(m.kinematics(), ref.p + dp, {}, in.d));
  in.d_dot = ref.v + dv;  // nominal kinematics: J = I
  return in;
}

// One step from a fresh state (the drives just enabled): these tests are
// about the laws; a model without delay never reads the state.
Status step_once(const Controller& c, const ControlInput& in, ControlOutput& out) {
  ControllerState state;
  return c.step(in, state, out);
}

TEST(Controller, PdIsProportionalPlusDerivativeOfTheJointError) {
  const Machine m(MachineModel::elkady());
  const Gains g{Vec3(1000, 2000, 3000), Vec3(10, 20, 30)};
  const Controller c(m, ControlLaw::pd, g);
  TrajectorySample ref;
  ref.p = Vec3(0.4, 0.4, 0.35);
  ref.v = Vec3(0.1, 0.0, -0.1);
  const Vec3 dp(1e-3, -2e-3, 0.5e-3), dv(0.01, 0.02, -0.03);
  ControlOutput out;
  ASSERT_TRUE(step_once(c, input_at(m, ref, dp, dv), out));
  // e = q_d - q = -dp, e_dot = -dv (Elkady eq. 15).
  const Vec3 expect = -g.kp.cwiseProduct(dp) - g.kd.cwiseProduct(dv);
  EXPECT_LT((out.force - expect).norm(), 1e-9);
}

TEST(Controller, GravityAndFeedforwardAddTheModelAtTheReference) {
  const Machine m(MachineModel::elkady());
  TrajectorySample ref;
  ref.p = Vec3(0.45, 0.35, 0.3);
  ref.v = Vec3(0.1, 0.2, 0.0);
  ref.a = Vec3(-1.0, 0.5, 0.2);
  const Gains g = table3_gains(ControlLaw::pd_feedforward);
  ControlOutput pd, grav, ff;
  const ControlInput in = input_at(m, ref, Vec3(1e-4, 0, 0), Vec3::Zero());
  ASSERT_TRUE(step_once(Controller(m, ControlLaw::pd, g), in, pd));
  ASSERT_TRUE(step_once(Controller(m, ControlLaw::pd_gravity, g), in, grav));
  ASSERT_TRUE(step_once(Controller(m, ControlLaw::pd_feedforward, g), in, ff));
  RigidBodyTerms t;
  ASSERT_TRUE(m.rigid_body(ref.p, ref.v, t));
  EXPECT_LT((grav.force - pd.force - t.K).norm(), 1e-9);
  EXPECT_LT((ff.force - pd.force - (t.M * ref.a + t.Gv + t.K)).norm(), 1e-9);
}

TEST(Controller, ComputedTorqueOnTheReferenceIsTheInverseDynamics) {
  // With no error, eq. 18 reduces to M q_dd_d + G q_d + K: the model's force.
  MachineModel mm = MachineModel::elkady();
  add_effect(mm, "coulomb_friction", 1, {3.0});
  add_effect(mm, "force_gain", 2, {0.1});
  const Machine m(mm);
  TrajectorySample ref;
  ref.p = Vec3(0.5, 0.3, 0.4);
  ref.v = Vec3(-0.1, 0.2, 0.1);
  ref.a = Vec3(0.3, -0.4, 2.0);
  ControlOutput out;
  ASSERT_TRUE(step_once(Controller(m, ControlLaw::computed_torque, table3_gains(ControlLaw::computed_torque)),
                        input_at(m, ref, Vec3::Zero(), Vec3::Zero()), out));
  Vec3 f;
  ASSERT_TRUE(m.inverse_dynamics(ref.p, ref.v, ref.a, f));
  f.y() += 3.0 * std::tanh(0.2 / 1e-3);
  f.z() /= 1.1;
  EXPECT_LT((out.force - f).norm(), 1e-9);
}

TEST(Controller, ClampsEachActuatorToTheForceLimitAndSaysWhich) {
  const Machine m(MachineModel::elkady());
  const Controller c(m, ControlLaw::pd, table3_gains(ControlLaw::pd));
  TrajectorySample ref;
  ref.p = Vec3(0.4, 0.4, 0.35);
  ControlOutput out;
  ASSERT_TRUE(step_once(c, input_at(m, ref, Vec3(0.02, -0.02, 0.0), Vec3::Zero()), out));
  EXPECT_DOUBLE_EQ(out.force.x(), -120.0);
  EXPECT_DOUBLE_EQ(out.force.y(), 120.0);
  EXPECT_TRUE(out.saturated[0] && out.saturated[1] && !out.saturated[2]);
  EXPECT_NEAR(out.force_unlimited.x(), -12691.0 * 0.02, 1e-6);
}

TEST(Controller, CalibratedModelMapsTaskForcesThroughTheJacobianTranspose) {
  MachineModel mm = MachineModel::elkady();
  std::mt19937_64 rng(31);
  mm.kinematics = test::random_calibrated_kinematics(rng, false);
  const Machine m(mm);
  TrajectorySample ref;
  ref.p = Vec3(0.42, 0.38, 0.33);
  ControlInput in;
  ASSERT_TRUE(kin::inverse(m.kinematics(), ref.p, {}, in.d));
  in.ref = ref;
  ControlOutput out;
  ASSERT_TRUE(step_once(Controller(m, ControlLaw::computed_torque, table3_gains(ControlLaw::computed_torque)), in, out));
  Vec3 fp;
  ASSERT_TRUE(m.inverse_dynamics(ref.p, Vec3::Zero(), Vec3::Zero(), fp));
  Mat3 J;
  ASSERT_TRUE(kin::jacobian(m.kinematics(), in.d, ref.p, {}, J));
  EXPECT_LT((out.force - J.transpose() * fp).norm(), 1e-9);
  EXPECT_LT((out.estimate.p - ref.p).norm(), 1e-12);
  EXPECT_LT((out.d_ref - in.d).norm(), 1e-12);
}

TEST(Controller, BadInputGivesAStatusAndNoForce) {
  const Machine m(MachineModel::elkady());
  const Controller c(m, ControlLaw::computed_torque, table3_gains(ControlLaw::computed_torque));
  ControlInput in;
  in.ref.p = Vec3(0.4, 0.4, 0.35);
  in.d = Vec3(0.2, 0.2, 0.1);
  ControlOutput out;
  out.force = Vec3::Constant(5.0);
  in.ref.v.y() = NAN;
  EXPECT_EQ(step_once(c, in, out).fault, Fault::not_finite);
  EXPECT_EQ(out.force, Vec3::Zero());
  in.ref.v.y() = 0.0;
  in.d_dot.x() = INFINITY;
  EXPECT_EQ(step_once(c, in, out).fault, Fault::not_finite);
  in.d_dot.x() = 0.0;
  // Encoders that put the platform far outside limb 2's reach (x - L = 1.42 m > L1 + L2).
  in.d = Vec3(1.3, 0.2, 0.1);
  Status s = step_once(c, in, out);
  EXPECT_EQ(s.fault, Fault::limb_unreachable);
  EXPECT_EQ(s.index, 1);
  EXPECT_EQ(out.force, Vec3::Zero());
  // A reference out of reach, for a law that evaluates the model there.
  in.d = Vec3(0.2, 0.2, 0.1);
  in.ref.p = Vec3(1.5, 0.4, 0.35);
  s = step_once(Controller(m, ControlLaw::pd_gravity, table3_gains(ControlLaw::pd_gravity)), in, out);
  EXPECT_EQ(s.fault, Fault::limb_unreachable);
  EXPECT_EQ(out.force, Vec3::Zero());
  EXPECT_THROW(Controller(m, ControlLaw::pd, Gains{Vec3(-1, 0, 0), Vec3::Zero()}), Error);
}

TEST(Controller, AStepAllocatesNothing) {
  MachineModel mm = MachineModel::elkady();
  std::mt19937_64 rng(32);
  mm.kinematics = test::random_calibrated_kinematics(rng, true);
  add_effect(mm, "viscous_friction", 0, {5.0});
  add_effect(mm, "cogging", 1, {1.0, 0.02, 0.0});
  const Machine m(mm);
  const CircleTrajectory circle(CircleSpec{});
  for (ControlLaw law : {ControlLaw::pd, ControlLaw::pd_gravity, ControlLaw::pd_feedforward,
                         ControlLaw::computed_torque}) {
    const Controller c(m, law, table3_gains(law));
    ControlInput in;
    ControlOutput out;
    ControllerState state;
    in.kin.t = 10.0;
    std::size_t allocations = 0;
    for (int k = 0; k < 200; ++k) {
      in.ref = circle.sample(k * 1e-3);
      ASSERT_TRUE(kin::inverse(m.kinematics(), in.ref.p + Vec3(1e-5, 0, -1e-5), in.kin, in.d));
      in.d_dot = in.ref.v;
      const test::CountAllocations count;
      const Status s = c.step(in, state, out);
      allocations += count.count();
      ASSERT_TRUE(s) << describe(s);
    }
    EXPECT_EQ(allocations, 0u) << law_name(law);
  }
  // The counter itself works: a vector allocates.
  const test::CountAllocations count;
  std::vector<int> v(10);
  EXPECT_GE(count.count(), 1u);
}

TEST(Controller, LawNamesRoundTrip) {
  for (ControlLaw l : {ControlLaw::pd, ControlLaw::pd_gravity, ControlLaw::pd_feedforward, ControlLaw::computed_torque})
    EXPECT_EQ(law_from_name(law_name(l)), l);
  EXPECT_FALSE(law_from_name("pid"));
}

}  // namespace
}  // namespace cpm::ctl
