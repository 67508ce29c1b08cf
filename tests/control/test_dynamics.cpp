// SPDX-License-Identifier: Apache-2.0
// Elkady's dynamics checked against itself and the effects against docs/effects.md.
#include <gtest/gtest.h>

#include <cmath>
#include <random>

#include "cpm/control/machine.hpp"
#include "support/random_models.hpp"

namespace cpm::ctl {
namespace {

TEST(Dynamics, InertiaConstantsFollowMachineMd) {
  const InertiaConstants c = InertiaConstants::from_masses(LinkMasses{}, 0.5);
  const double m1 = 1.892994, m2 = 0.695528, m3 = 0.2, m4 = 0.3, g = 9.81, L1 = 0.5;
  EXPECT_DOUBLE_EQ(c.A, 0.5 * (m1 + 2 * m2 + m3 + m4));
  EXPECT_DOUBLE_EQ(c.B, (m1 / 6 + m2 / 4) * L1 * L1);
  EXPECT_DOUBLE_EQ(c.C, 0.5 * (m1 + m2) * g * L1);
  EXPECT_DOUBLE_EQ(c.E, (m1 + 2 * m2 + m3 + m4) * g);
}

TEST(Dynamics, MassMatrixIsSymmetricPositiveDefiniteOverTheWorkspace) {
  const Machine m(MachineModel::elkady());
  const int n = 12;
  int checked = 0;
  for (int i = 0; i <= n; ++i)
    for (int j = 0; j <= n; ++j)
      for (int k = 0; k <= n; ++k) {
        const Vec3 p(0.23 + 0.39 * i / n, 0.23 + 0.39 * j / n, 0.23 + 0.29 * k / n);
        RigidBodyTerms t;
        if (!m.rigid_body(p, Vec3::Zero(), t)) continue;  // outside the limbs' reach
        ++checked;
        EXPECT_LT((t.M - t.M.transpose()).norm(), 1e-12 * t.M.norm());
        const Eigen::SelfAdjointEigenSolver<Mat3> eig(t.M);
        // M = 2A I + 2B Gamma^T Gamma: every eigenvalue is at least 2A.
        EXPECT_GE(eig.eigenvalues().minCoeff(), 2.0 * m.inertia().A * (1.0 - 1e-12));
      }
  EXPECT_GT(checked, 1500);
}

TEST(Dynamics, GravityIsTheGradientOfThePotential) {
  // K(q) = dV/dq with V = -C (sin t11 + cos t21) - E z (Elkady eq. 5).
  const Machine m(MachineModel::elkady());
  std::mt19937_64 rng(21);
  const double h = 1e-6;
  for (int k = 0; k < 100; ++k) {
    const Vec3 p = test::random_platform_point(rng);
    RigidBodyTerms t;
    ASSERT_TRUE(m.rigid_body(p, Vec3::Zero(), t));
    Vec3 grad;
    for (int j = 0; j < 3; ++j) {
      double vp, vm;
      ASSERT_TRUE(m.potential_energy(p + h * Vec3::Unit(j), vp));
      ASSERT_TRUE(m.potential_energy(p - h * Vec3::Unit(j), vm));
      grad[j] = (vp - vm) / (2 * h);
    }
    EXPECT_LT((t.K - grad).norm(), 1e-6 * t.K.norm());
  }
}

TEST(Dynamics, MassAndCoriolisComeFromTheKineticEnergy) {
  // Lagrange: M q_dd + G q_d = d/dt (dT/dq_d) - dT/dq. Check along a motion
  // p(t) = p0 + v t + a t^2 / 2 by finite differences of T.
  const Machine m(MachineModel::elkady());
  std::mt19937_64 rng(22);
  std::uniform_real_distribution<double> u(-0.4, 0.4);
  const double h = 1e-5;
  auto dT_dqd = [&](const Vec3& p, const Vec3& v) {
    Vec3 g;
    for (int j = 0; j < 3; ++j) {
      double tp, tm;
      EXPECT_TRUE(m.kinetic_energy(p, v + h * Vec3::Unit(j), tp));
      EXPECT_TRUE(m.kinetic_energy(p, v - h * Vec3::Unit(j), tm));
      g[j] = (tp - tm) / (2 * h);
    }
    return g;
  };
  for (int k = 0; k < 30; ++k) {
    const Vec3 p0 = test::random_platform_point(rng);
    const Vec3 v(u(rng), u(rng), u(rng)), a(u(rng), u(rng), u(rng));
    const Vec3 ddt = (dT_dqd(p0 + h * v + 0.5 * h * h * a, v + h * a) -
                      dT_dqd(p0 - h * v + 0.5 * h * h * a, v - h * a)) / (2 * h);
    Vec3 dT_dq;
    for (int j = 0; j < 3; ++j) {
      double tp, tm;
      ASSERT_TRUE(m.kinetic_energy(p0 + h * Vec3::Unit(j), v, tp));
      ASSERT_TRUE(m.kinetic_energy(p0 - h * Vec3::Unit(j), v, tm));
      dT_dq[j] = (tp - tm) / (2 * h);
    }
    RigidBodyTerms t;
    ASSERT_TRUE(m.rigid_body(p0, v, t));
    const Vec3 lagrange = ddt - dT_dq;
    EXPECT_LT((t.M * a + t.Gv - lagrange).norm(), 1e-4 * (1.0 + lagrange.norm())) << k;
  }
}

TEST(DynamicEffects, EachForceMatchesItsEquation) {
  // docs/effects.md, with sgn_eps(v) = tanh(v / 1e-3).
  auto sgn = [](double v) { return std::tanh(v / 1e-3); };
  const double d = 0.173, v = -0.042;
  auto force = [&](const char* name, std::vector<double> p) {
    MachineModel mm;
    add_effect(mm, name, 1, p);
    return effect_force(mm.effects[0], d, v);
  };
  EXPECT_DOUBLE_EQ(force("viscous_friction", {12.5}), 12.5 * v);
  EXPECT_DOUBLE_EQ(force("coulomb_friction", {4.0}), 4.0 * sgn(v));
  EXPECT_DOUBLE_EQ(force("stribeck_friction", {3.0, 0.01}), 3.0 * std::exp(-std::pow(v / 0.01, 2)) * sgn(v));
  EXPECT_DOUBLE_EQ(force("cogging", {1.5, 0.02, 0.3}), 1.5 * std::sin(2 * M_PI * d / 0.02 + 0.3));
  EXPECT_DOUBLE_EQ(force("spring", {200.0, 0.1}), 200.0 * (d - 0.1));
  EXPECT_EQ(force("force_gain", {0.1}), 0.0);  // acts through the drive, not as a force
}

TEST(DynamicEffects, GradientsMatchFiniteDifferences) {
  const double d = 0.173, v = 0.0123, h = 1e-7;
  for (int k = 0; k < kDynamicEffectTypes; ++k) {
    const auto type = static_cast<DynamicEffectType>(k);
    const DynamicEffectInfo& in = info(type);
    if (!in.per_axis || type == DynamicEffectType::force_gain) continue;
    DynamicEffect e;
    e.type = type;
    e.axis = 0;
    for (int j = 0; j < in.n_params; ++j) e.param[j] = std::max(in.params[j].lower, 0.0) + 0.01 * (j + 1) + 0.02;
    for (int j = 0; j < in.n_params; ++j) {
      DynamicEffect ep = e, em = e;
      ep.param[j] += h;
      em.param[j] -= h;
      const double fd = (effect_force(ep, d, v) - effect_force(em, d, v)) / (2 * h);
      EXPECT_NEAR(effect_force_gradient(e, j, d, v), fd, 1e-6 * (1 + std::abs(fd))) << in.name << " " << j;
    }
  }
}

TEST(DynamicEffects, PayloadAddsMassTimesAccelerationMinusGravity) {
  MachineModel with = MachineModel::elkady();
  add_effect(with, "payload_mass", -1, {0.8});
  const Machine a(MachineModel::elkady()), b(with);
  const Vec3 p(0.45, 0.40, 0.35), v(0.1, -0.2, 0.05), acc(1.0, -2.0, 3.0);
  Vec3 fa, fb;
  ASSERT_TRUE(a.inverse_dynamics(p, v, acc, fa));
  ASSERT_TRUE(b.inverse_dynamics(p, v, acc, fb));
  EXPECT_LT((fb - fa - 0.8 * (acc - Vec3(0, 0, kGravity))).norm(), 1e-12);
}

TEST(DynamicEffects, InertiaErrorShiftsTheConstants) {
  MachineModel with = MachineModel::elkady();
  add_effect(with, "inertia_error", -1, {0.1, -0.01, 0.2, 1.5});
  const Machine a(MachineModel::elkady()), b(with);
  EXPECT_DOUBLE_EQ(b.inertia().A, a.inertia().A + 0.1);
  EXPECT_DOUBLE_EQ(b.inertia().B, a.inertia().B - 0.01);
  EXPECT_DOUBLE_EQ(b.inertia().C, a.inertia().C + 0.2);
  EXPECT_DOUBLE_EQ(b.inertia().E, a.inertia().E + 1.5);
}

TEST(DynamicEffects, ForceGainAndEffectSumsPerAxis) {
  MachineModel mm = MachineModel::elkady();
  add_effect(mm, "force_gain", 2, {0.05});
  add_effect(mm, "coulomb_friction", 0, {2.0});
  add_effect(mm, "viscous_friction", 0, {10.0});
  const Machine m(mm);
  EXPECT_EQ(m.drive_gain(), Vec3(1.0, 1.0, 1.05));
  const Vec3 f = m.effect_forces(Vec3(0.1, 0.1, 0.1), Vec3(0.5, 0.5, 0.5));
  EXPECT_NEAR(f.x(), 2.0 * std::tanh(500.0) + 5.0, 1e-12);
  EXPECT_EQ(f.y(), 0.0);
  EXPECT_EQ(f.z(), 0.0);
}

TEST(DynamicEffects, RefusesUnphysicalValuesNamingTheParameter) {
  auto expect_error = [](const char* name, int axis, std::vector<double> p, const std::string& part) {
    MachineModel mm;
    try {
      add_effect(mm, name, axis, p);
      ADD_FAILURE() << name << " accepted";
    } catch (const Error& e) {
      EXPECT_NE(std::string(e.what()).find(part), std::string::npos) << e.what();
    }
  };
  expect_error("coulomb_friction", 0, {-1.0}, "f_c");
  expect_error("viscous_friction", 1, {NAN}, "not a finite");
  expect_error("payload_mass", -1, {-5.0}, "dm");
  expect_error("stribeck_friction", 2, {1.0, 0.0}, "v_s");
  expect_error("cogging", 0, {1.0}, "expects 3 values");
  expect_error("payload_mass", 1, {0.5}, "all axes");
  expect_error("nonsense", 0, {1.0}, "unknown effect");
  expect_error("backlash", -1, {1e-5}, "axis");
  expect_error("backlash", 0, {-1e-5}, "outside");
}

TEST(Machine, RefusesABadModelSayingWhat) {
  MachineModel mm;
  mm.force_limit = 0.0;
  EXPECT_THROW(Machine{mm}, Error);
  mm = MachineModel::elkady();
  mm.masses.m2 = -1.0;
  try {
    Machine m{mm};
    ADD_FAILURE();
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("m2"), std::string::npos);
  }
  mm = MachineModel::elkady();
  add_effect(mm, "inertia_error", -1, {-10.0, 0, 0, 0});  // A would be negative
  EXPECT_THROW(Machine{mm}, Error);
}

TEST(Machine, TaskStateUsesTheCalibratedKinematics) {
  MachineModel mm = MachineModel::elkady();
  std::mt19937_64 rng(23);
  mm.kinematics = test::random_calibrated_kinematics(rng, false);
  const Machine m(mm);
  const Vec3 d(0.2, 0.15, 0.1), dd(0.1, -0.05, 0.02);
  TaskState s;
  ASSERT_TRUE(m.task_state(d, dd, {}, s));
  Vec3 p;
  ASSERT_TRUE(kin::forward(mm.kinematics, d, {}, p));
  EXPECT_LT((s.p - p).norm(), 1e-15);
  Vec3 p2;
  ASSERT_TRUE(kin::forward(mm.kinematics, d + 1e-6 * dd, {}, p2));
  EXPECT_LT((s.p_dot - (p2 - p) / 1e-6).norm(), 1e-8);
}

// actuator_inertia (docs/effects.md): m_i kg that only actuator i carries.
MachineModel with_actuator_inertia(const Vec3& m, kin::KinematicModel k = kin::KinematicModel::nominal()) {
  MachineModel mm = MachineModel::elkady();
  mm.kinematics = std::move(k);
  for (int i = 0; i < 3; ++i)
    if (m[i] != 0.0) add_effect(mm, "actuator_inertia", i, {m[i]});
  return mm;
}

TEST(ActuatorInertia, OneAxisAcceleratedNeedsExactlyMTimesAMoreOnThatAxis) {
  // Closed form: actuator 2 accelerated alone at a from rest (and at speed: J
  // is constant, so no velocity term), m = 2.5 kg on it: the actuator forces
  // differ by (0, m a, 0), to rounding.
  std::mt19937_64 rng(5);
  const Machine a(with_actuator_inertia(Vec3::Zero(), test::random_calibrated_kinematics(rng, false)));
  const Machine b(with_actuator_inertia(Vec3(0.0, 2.5, 0.0), a.kinematics()));
  ASSERT_TRUE(b.has_constant_jacobian());
  const Mat3& J = b.constant_jacobian();
  const Vec3 p(0.45, 0.40, 0.35);
  for (const Vec3& d_dot : {Vec3(0, 0, 0), Vec3(0.2, -0.1, 0.3)}) {
    const double acc = 3.0;  // m/s^2 on actuator 2
    const Vec3 p_dd = J * Vec3(0.0, acc, 0.0), p_dot = J * d_dot;
    Vec3 fa, fb;
    ASSERT_TRUE(a.inverse_dynamics(p, p_dot, p_dd, fa));
    ASSERT_TRUE(b.inverse_dynamics(p, p_dot, p_dd, fb));
    const Vec3 extra = J.transpose() * (fb - fa);
    EXPECT_NEAR(extra.x(), 0.0, 1e-12);
    EXPECT_NEAR(extra.y(), 2.5 * acc, 1e-12);
    EXPECT_NEAR(extra.z(), 0.0, 1e-12);
  }
  EXPECT_EQ(b.reflected_masses(), Vec3(0.0, 2.5, 0.0));
  EXPECT_EQ(b.effect_forces(Vec3::Constant(0.1), Vec3::Constant(0.2)), Vec3::Zero());  // not an additive force
}

TEST(ActuatorInertia, ForwardThenInverseDynamicsGivesBackTheCommand) {
  // The plant's equation (forward) and the controller's (inverse) agree with
  // the reflected inertias on every axis, drive gain and friction beside them.
  std::mt19937_64 rng(9);
  MachineModel mm = with_actuator_inertia(Vec3(1.2, 40.0, 160.0), test::random_calibrated_kinematics(rng, false));
  add_effect(mm, "force_gain", 0, {0.05});
  add_effect(mm, "viscous_friction", 2, {30.0});
  const Machine m(mm);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  int checked = 0;
  for (int k = 0; k < 50; ++k) {
    const Vec3 p = test::random_platform_point(rng);
    const Vec3 p_dot(0.3 * u(rng), 0.3 * u(rng), 0.3 * u(rng)), cmd(50 * u(rng), 50 * u(rng), 50 * u(rng));
    Vec3 p_dd, F_p, d;
    if (!m.forward_dynamics(p, p_dot, cmd, {}, p_dd)) continue;  // outside the limbs' reach
    ASSERT_TRUE(kin::inverse(m.kinematics(), p, {}, d));
    ASSERT_TRUE(m.inverse_dynamics(p, p_dot, p_dd, F_p));
    const Mat3& J = m.constant_jacobian();
    const Vec3 back = (J.transpose() * F_p + m.effect_forces(d, m.constant_jacobian_inverse() * p_dot))
                          .cwiseQuotient(m.drive_gain());
    EXPECT_LT((back - cmd).norm(), 1e-9 * (1.0 + cmd.norm())) << k;
    ++checked;
  }
  EXPECT_GT(checked, 40);
}

TEST(ActuatorInertia, KineticEnergyGainsHalfMTimesTheActuatorSpeedSquared) {
  std::mt19937_64 rng(13);
  const kin::KinematicModel k = test::random_calibrated_kinematics(rng, false);
  const Vec3 masses(3.0, 0.0, 7.5);
  const Machine a(with_actuator_inertia(Vec3::Zero(), k)), b(with_actuator_inertia(masses, k));
  const Vec3 p(0.42, 0.38, 0.33), p_dot(0.2, -0.3, 0.1);
  double Ta, Tb;
  ASSERT_TRUE(a.kinetic_energy(p, p_dot, Ta));
  ASSERT_TRUE(b.kinetic_energy(p, p_dot, Tb));
  const Vec3 d_dot = b.constant_jacobian_inverse() * p_dot;
  EXPECT_NEAR(Tb - Ta, 0.5 * (masses.array() * d_dot.array().square()).sum(), 1e-12);
}

TEST(ActuatorInertia, RefusesAMassBelowItsBoundOrATotalInertiaThatIsNotPositive) {
  MachineModel mm = MachineModel::elkady();
  try {
    add_effect(mm, "actuator_inertia", 0, {-6.0});
    ADD_FAILURE();
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("actuator_inertia[axis 1]: parameter m"), std::string::npos) << e.what();
  }
  // -4.9 kg is within the bound, but more than the 2A = 3.78 kg the nominal machine puts on axis 1.
  add_effect(mm, "actuator_inertia", 0, {-4.9});
  try {
    const Machine m(mm);
    ADD_FAILURE();
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("negative inertia"), std::string::npos) << e.what();
  }
}

}  // namespace
}  // namespace cpm::ctl
