// SPDX-License-Identifier: Apache-2.0
// User effects (table, expression; docs/effects.md "Effects you add") in the
// prepared Machine: the plant's forward dynamics, the controller's computed
// torque and the holding command, against the library effects they equal.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <random>

#include "cpm/control/controller.hpp"
#include "cpm/sim/closed_loop.hpp"
#include "support/allocation_counter.hpp"

namespace cpm::ctl {
namespace {

UserEffect expression(int axis, const std::string& formula, std::vector<UserParameter> params) {
  UserEffect e;
  e.kind = UserEffectKind::expression;
  e.axis = axis;
  e.formula = formula;
  e.params = std::move(params);
  return e;
}

UserEffect table(int axis, char input, int input_axis, std::vector<double> x, std::vector<double> y) {
  UserEffect e;
  e.kind = UserEffectKind::table;
  e.axis = axis;
  e.input = input;
  e.input_axis = input_axis;
  e.nodes = std::move(x);
  e.values = std::move(y);
  return e;
}

MachineModel with_library(const char* name, int axis, std::vector<double> values) {
  MachineModel m = MachineModel::elkady();
  add_effect(m, name, axis, values);
  return m;
}

MachineModel with_user(UserEffect e) {
  MachineModel m = MachineModel::elkady();
  m.user_effects.push_back(std::move(e));
  return m;
}

// The paper's circle under computed torque with Table 3's gains, 1 kHz.
sim::RunResult circle(const Machine& truth, const Machine& believed) {
  const Controller c(believed, ControlLaw::computed_torque, table3_gains(ControlLaw::computed_torque));
  sim::Plant plant(truth, sim::PlantOptions{});
  CircleSpec spec;
  spec.ramp_time = 0.5;
  spec.cruise_time = 2.0;
  return sim::run_closed_loop(c, plant, CircleTrajectory(spec), sim::LoopOptions{});
}

double worst_difference(const sim::RunResult& a, const sim::RunResult& b) {
  EXPECT_EQ(a.log.size(), b.log.size());
  double worst = 0.0;
  for (std::size_t k = 0; k < std::min(a.log.size(), b.log.size()); ++k)
    worst = std::max({worst, (a.log[k].p - b.log[k].p).norm(), (a.log[k].force - b.log[k].force).norm() * 1e-3});
  return worst;
}

TEST(UserEffects, ExpressionBTimesV2IsViscousFrictionOnAxis2) {
  const double b = 7.5;  // N s/m
  const Machine lib(with_library("viscous_friction", 1, {b}));
  const Machine user(with_user(expression(1, "b*v2", {{"b", "N s/m", b, 0.0, 100.0}})));
  const Vec3 d(0.1, 0.2, 0.15), v(0.3, -0.4, 0.2);
  EXPECT_NEAR((lib.effect_forces(d, v) - user.effect_forces(d, v)).norm(), 0.0, 1e-15);
  EXPECT_DOUBLE_EQ(user.effect_forces(d, v)[1], b * v[1]);
  // The same plant trajectory, each machine both truth and controller model.
  const sim::RunResult r_lib = circle(lib, lib), r_user = circle(user, user);
  ASSERT_TRUE(r_lib.ok() && r_user.ok());
  EXPECT_GT(r_lib.log.size(), 2500u);
  EXPECT_LT(worst_difference(r_lib, r_user), 1e-12);
}

TEST(UserEffects, TableWithALinearLawIsASpring) {
  // k (d - d_ref) sampled at two nodes spanning the stroke is the spring exactly.
  const double k = 300.0, d_ref = 0.15;  // N/m, m
  const Machine lib(with_library("spring", 2, {k, d_ref}));
  const Machine user(with_user(table(2, 'd', 2, {-0.1, 0.7}, {k * (-0.1 - d_ref), k * (0.7 - d_ref)})));
  std::mt19937_64 rng(5);
  std::uniform_real_distribution<double> u(0.0, 0.5);
  for (int n = 0; n < 100; ++n) {
    const Vec3 d(u(rng), u(rng), u(rng)), v(u(rng), -u(rng), u(rng));
    EXPECT_NEAR((lib.effect_forces(d, v) - user.effect_forces(d, v)).norm(), 0.0, 1e-11);
  }
  Vec3 h_lib, h_user;
  ASSERT_TRUE(lib.holding_command(Vec3(0.4, 0.4, 0.35), {}, h_lib));
  ASSERT_TRUE(user.holding_command(Vec3(0.4, 0.4, 0.35), {}, h_user));
  EXPECT_LT((h_lib - h_user).norm(), 1e-11);
  const sim::RunResult r_lib = circle(lib, lib), r_user = circle(user, user);
  ASSERT_TRUE(r_lib.ok() && r_user.ok());
  EXPECT_LT(worst_difference(r_lib, r_user), 1e-12);
}

TEST(UserEffects, TableHoldsItsEndValuesAndReadsAnotherAxis) {
  // A force on axis 2 that follows v1 (a cable carrier dragged by axis 1).
  const Machine m(with_user(table(1, 'v', 0, {-0.2, 0.0, 0.2}, {-3.0, 0.0, 5.0})));
  EXPECT_DOUBLE_EQ(m.effect_forces(Vec3::Zero(), Vec3(0.1, 9.0, 9.0))[1], 2.5);
  EXPECT_DOUBLE_EQ(m.effect_forces(Vec3::Zero(), Vec3(0.9, 0.0, 0.0))[1], 5.0);   // held beyond the last node
  EXPECT_DOUBLE_EQ(m.effect_forces(Vec3::Zero(), Vec3(-0.9, 0.0, 0.0))[1], -3.0); // and the first
  EXPECT_EQ(m.effect_forces(Vec3::Zero(), Vec3(0.1, 0, 0))[0], 0.0);
}

TEST(UserEffects, AccelerationInAFormulaIsSolvedImplicitly) {
  // A reflected inertia of m_r on axis 1 written as "m*a1": the plant must
  // satisfy M p_dd + Gv + K = J^-T (F - m_r a), a = J^-1 p_dd (J constant here).
  const double m_r = 0.8;  // kg
  const Machine m(with_user(expression(0, "m*a1", {{"m", "kg", m_r, 0.0, 10.0}})));
  ASSERT_TRUE(m.user_effects_use_acceleration());
  const Vec3 p(0.4, 0.42, 0.33), p_dot(0.1, -0.2, 0.05), F(3.0, -2.0, 40.0);
  Vec3 p_dd;
  ASSERT_TRUE(m.forward_dynamics(p, p_dot, F, {}, p_dd));
  RigidBodyTerms t;
  ASSERT_TRUE(m.rigid_body(p, p_dot, t));
  const Mat3& Ji = m.constant_jacobian_inverse();
  const Vec3 a = Ji * p_dd;
  const Vec3 residual = t.M * p_dd + t.Gv + t.K - Ji.transpose() * (F - Vec3(m_r * a[0], 0, 0));
  EXPECT_LT(residual.norm(), 1e-10);
  EXPECT_GT(std::abs(m_r * a[0]), 0.1);  // the term mattered
}

TEST(UserEffects, EvaluationAllocatesNothingInTheLoop) {
  MachineModel mm = MachineModel::elkady();
  mm.user_effects.push_back(expression(1, "c*v1 + s*sin(d2/0.01) + m*a3 + 0*t", {{"c", "N s/m", 3.0, -100, 100},
                                                                            {"s", "N", 0.5, -10, 10},
                                                                            {"m", "kg", 0.1, 0, 10}}));
  mm.user_effects.push_back(table(0, 'd', 0, {0.0, 0.1, 0.2, 0.3}, {0.0, 1.0, -1.0, 0.5}));
  const Machine m(mm);
  std::size_t allocations = 0;
  Vec3 sum = Vec3::Zero();
  for (int k = 0; k < 200; ++k) {
    const Vec3 d(0.1 + 1e-3 * k, 0.2, 0.15), v(0.2, 0.1, -0.1), a(1.0, 0.0, 2.0);
    const test::CountAllocations count;
    sum += m.effect_forces(d, v, a, 1e-3 * k);
    Vec3 p_dd;
    (void)m.forward_dynamics(Vec3(0.4, 0.4, 0.3), v, Vec3(1, 2, 30), {}, p_dd);
    allocations += count.count();
  }
  EXPECT_TRUE(sum.allFinite());
  EXPECT_EQ(allocations, 0u);
  // The counter counts here: preparing a machine with a formula allocates.
  const test::CountAllocations count;
  const Machine again(mm);
  EXPECT_GT(count.count(), 0u);
}

TEST(UserEffects, ACopiedMachineEvaluatesWithItsOwnVariables) {
  const Machine a(with_user(expression(2, "c*d3", {{"c", "N/m", 10.0, -1e3, 1e3}})));
  Machine b = a;
  const Machine c = std::move(b);
  EXPECT_DOUBLE_EQ(a.effect_forces(Vec3(0, 0, 0.2), Vec3::Zero())[2], 2.0);
  EXPECT_DOUBLE_EQ(c.effect_forces(Vec3(0, 0, 0.3), Vec3::Zero())[2], 3.0);
  EXPECT_DOUBLE_EQ(a.effect_forces(Vec3(0, 0, 0.1), Vec3::Zero())[2], 1.0);
}

std::string refusal(const UserEffect& e) {
  try {
    validate_user_effect(e, 3);
  } catch (const Error& err) {
    return err.what();
  }
  return "";
}

TEST(UserEffects, BadEffectsAreRefusedSayingWhereAndWhy) {
  EXPECT_EQ(refusal(expression(1, "c*x1", {{"c", "", 1.0, 0, 2}})),
            "user_effects[3].formula: unknown variable 'x1' in 'c*x1' (known: d1..d3, v1..v3, a1..a3, t, c)");
  const std::string parse = refusal(expression(1, "c*v1+", {{"c", "", 1.0, 0, 2}}));
  EXPECT_NE(parse.find("user_effects[3].formula: 'c*v1+' does not parse: Unexpected end of expression at position 6"),
            std::string::npos)
      << parse;
  EXPECT_EQ(refusal(expression(1, "c*v1", {{"c", "N s/m", 300.0, -100, 100}})),
            "user_effects[3].params.c.value: 300 N s/m is outside its bounds [-100, 100]");
  EXPECT_EQ(refusal(expression(1, "v1*v1", {{"v1", "", 1.0, 0, 2}})),
            "user_effects[3].params.v1: 'v1' is a variable's name (d1..d3, v1..v3, a1..a3, t)");
  EXPECT_EQ(refusal(table(1, 'd', 1, {0.0, 0.2, 0.1}, {0, 0, 0})),
            "user_effects[3].nodes[2]: nodes must be strictly increasing: 0.1 is not above 0.2");
  EXPECT_EQ(refusal(table(1, 'd', 1, {0.0, 0.2}, {0})), "user_effects[3].values: has 1 values for 2 nodes");
  EXPECT_EQ(refusal(table(4, 'd', 1, {0.0, 0.2}, {0, 1})), "user_effects[3].axis: must be 1, 2 or 3");
  EXPECT_EQ(refusal(expression(0, "1/d1", {})), "user_effects[3].formula: '1/d1' is not finite at rest (all variables 0)");
  // The Machine refuses them too, before any loop.
  EXPECT_THROW(Machine(with_user(expression(1, "q*v1", {}))), Error);
}

TEST(UserEffects, ControllerCompensatesATableForceItsModelHas) {
  // Truth: a local force excess of 6 N on axis 2 over 40 mm of its travel.
  const UserEffect bump = table(1, 'd', 1, {0.15, 0.17, 0.19, 0.21}, {0.0, 6.0, 6.0, 0.0});
  const Machine truth(with_user(bump));
  const Machine nominal(MachineModel::elkady());
  const sim::RunResult without = circle(truth, nominal), with = circle(truth, truth);
  ASSERT_TRUE(without.ok() && with.ok());
  std::printf("[ figures  ] circle RMSE with a 6 N table bump on axis 2: model without it %.3f um, with it %.3f um\n",
              without.metrics.position_rmse * 1e6, with.metrics.position_rmse * 1e6);
  EXPECT_LT(with.metrics.position_rmse, 0.5 * without.metrics.position_rmse);
}

}  // namespace
}  // namespace cpm::ctl

namespace cpm::ctl {
namespace {

TEST(UserEffects, TheCommandLineFormAddsEachKind) {
  MachineModel m = MachineModel::elkady();
  add_user_effect(m, "expression:2:c*v1:c=3");
  add_user_effect(m, "expression:1:v1 > 0 ? f : -f:f=2.5");  // a formula holding ':'
  add_user_effect(m, "table:3:v3:-0.1,0,0.1:-1,0,2");
  add_user_effect(m, "pitch_table:1:0,0.2,0.4:0,5e-6,12e-6");
  ASSERT_EQ(m.user_effects.size(), 3u);
  EXPECT_EQ(m.user_effects[0].formula, "c*v1");
  EXPECT_EQ(m.user_effects[0].axis, 1);
  EXPECT_EQ(m.user_effects[0].params[0].value, 3.0);
  EXPECT_EQ(m.user_effects[1].formula, "v1 > 0 ? f : -f");
  EXPECT_EQ(m.user_effects[2].input, 'v');
  EXPECT_EQ(m.user_effects[2].input_axis, 2);
  EXPECT_EQ(m.kinematics.effects[0].pitch_table.size, 3);
  const Machine machine(m);
  EXPECT_DOUBLE_EQ(machine.effect_forces(Vec3::Zero(), Vec3(0.1, 0, 0.05))[0], 2.5);
  EXPECT_DOUBLE_EQ(machine.effect_forces(Vec3::Zero(), Vec3(0.1, 0, 0.05))[1], 0.3);
  EXPECT_DOUBLE_EQ(machine.effect_forces(Vec3::Zero(), Vec3(0.1, 0, 0.05))[2], 1.0);
  EXPECT_THROW(add_user_effect(m, "table:2:a2:0,1:0,1"), Error);
  EXPECT_THROW(add_user_effect(m, "expression:4:c*v1:c=1"), Error);
  EXPECT_THROW(add_user_effect(m, "pitch_table:1:0,0.1:0"), Error);
}

}  // namespace
}  // namespace cpm::ctl

#include <thread>

namespace cpm::ctl {
namespace {

TEST(UserEffects, ThreadsEvaluatingOneMachineAtOnceGetTheirOwnAnswers) {
  // cpmd's loop and its server read the same Machine: a formula's variables
  // must not be shared between two evaluations running at the same time.
  const Machine m(with_user(expression(1, "c*v1 + 0*d3", {{"c", "N s/m", 2.0, -10, 10}})));
  std::vector<std::thread> threads;
  std::array<int, 4> wrong{};
  for (int id = 0; id < 4; ++id)
    threads.emplace_back([&, id] {
      for (int k = 0; k < 20000; ++k) {
        const double v1 = id + 1e-4 * k;
        if (m.effect_forces(Vec3::Zero(), Vec3(v1, 0, 0))[1] != 2.0 * v1) ++wrong[static_cast<std::size_t>(id)];
      }
    });
  for (auto& t : threads) t.join();
  for (int id = 0; id < 4; ++id) EXPECT_EQ(wrong[static_cast<std::size_t>(id)], 0) << "thread " << id;
}

}  // namespace
}  // namespace cpm::ctl
