// SPDX-License-Identifier: Apache-2.0
// The plant: its dynamics against the model's inverse dynamics, energy
// conservation, the closed-form error of computed torque, Table 3.
#include <gtest/gtest.h>

#include <cmath>
#include <fstream>
#include <random>

#include "cpm/sim/closed_loop.hpp"
#include "cpm/sim/table3.hpp"
#include "support/random_models.hpp"

namespace cpm::sim {
namespace {

TEST(Table3, ReproducesTheIndependentFiguresWithinThreePercentInThePapersOrder) {
  const auto rows = reproduce_table3();
  const char* names[] = {"pd", "pd_gravity", "pd_feedforward", "computed_torque"};
  // docs/model.md's independent re-implementation under the same conditions.
  const double independent[] = {2.886e-3, 3.980e-4, 3.101e-4, 1.973e-4};
  for (int i = 0; i < 4; ++i) {
    EXPECT_STREQ(ctl::law_name(rows[i].law), names[i]);
    EXPECT_TRUE(rows[i].fault.ok()) << describe(rows[i].fault);
    EXPECT_EQ(rows[i].metrics.samples, 4000);
    EXPECT_NEAR(rows[i].metrics.position_rmse / independent[i], 1.0, 0.03) << names[i];
    if (i > 0) {
      EXPECT_LT(rows[i].metrics.position_rmse, rows[i - 1].metrics.position_rmse);
    }
  }
}

TEST(Plant, AccelerationInvertsTheModelsInverseDynamics) {
  ctl::MachineModel mm = ctl::MachineModel::elkady();
  std::mt19937_64 rng(41);
  mm.kinematics = test::random_calibrated_kinematics(rng, false);
  ctl::add_effect(mm, "coulomb_friction", 0, {3.0});
  ctl::add_effect(mm, "spring", 2, {150.0, 0.1});
  ctl::add_effect(mm, "force_gain", 1, {-0.05});
  ctl::add_effect(mm, "payload_mass", -1, {0.4});
  const ctl::Machine m(mm);
  Plant plant(m, PlantOptions{});
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  for (int k = 0; k < 50; ++k) {
    const Vec3 p = test::random_platform_point(rng);
    const Vec3 v(0.2 * u(rng), 0.2 * u(rng), 0.2 * u(rng)), a(3 * u(rng), 3 * u(rng), 3 * u(rng));
    // The actuator forces a perfect controller would command for (p, v, a).
    Vec3 fp, d, d_dot;
    Mat3 J;
    ASSERT_TRUE(m.inverse_dynamics(p, v, a, fp));
    ASSERT_TRUE(kin::inverse(m.kinematics(), p, {}, d));
    ASSERT_TRUE(kin::jacobian(m.kinematics(), d, p, {}, J));
    d_dot = J.inverse() * v;
    const Vec3 f_cmd = (J.transpose() * fp + m.effect_forces(d, d_dot)).cwiseQuotient(m.drive_gain());
    Vec3 a_plant;
    ASSERT_TRUE(plant.acceleration(p, v, f_cmd, a_plant));
    EXPECT_LT((a_plant - a).norm(), 1e-9 * (1 + a.norm())) << k;
  }
}

// Free fall from rest for 0.1 s with no actuator force: the worst drift of
// T + V (J) and the kinetic energy at the end.
void free_fall(const ctl::Machine& m, double& worst, double& T_end) {
  PlantOptions opt;
  opt.substeps = 10;
  Plant plant(m, opt);
  const Vec3 start(0.42, 0.40, 0.26);
  ASSERT_TRUE(plant.reset(start));
  double T0, V0;
  ASSERT_TRUE(m.kinetic_energy(plant.position(), plant.velocity(), T0));
  ASSERT_TRUE(m.potential_energy(plant.position(), V0));
  worst = 0.0;
  for (int k = 0; k < 100; ++k) {  // 0.1 s with no actuator force
    ASSERT_TRUE(plant.step(Vec3::Zero(), 1e-3));
    double T, V;
    ASSERT_TRUE(m.kinetic_energy(plant.position(), plant.velocity(), T));
    ASSERT_TRUE(m.potential_energy(plant.position(), V));
    worst = std::max(worst, std::abs(T + V - T0 - V0));
  }
  ASSERT_TRUE(m.kinetic_energy(plant.position(), plant.velocity(), T_end));
  EXPECT_GT(plant.position().z() - start.z(), 0.01);  // it really fell (over 10 mm)
}

TEST(Plant, AFreeFallConservesKineticPlusPotentialEnergy) {
  double worst = 0.0, T_end = 0.0;
  free_fall(ctl::Machine(ctl::MachineModel::elkady()), worst, T_end);
  EXPECT_GT(T_end, 0.5);
  EXPECT_LT(worst, 1e-9 * T_end);        // RK4 with h = 0.1 ms: energy drift far below 1e-9 of T
}

TEST(Plant, AFreeFallWithActuatorInertiaConservesEnergyCountingTheRotors) {
  // The rotors of axes 1 and 3 (2 and 6 kg reflected) fall with the platform:
  // their 1/2 m d_dot^2 is in T, and the fall is slower than without them.
  ctl::MachineModel mm = ctl::MachineModel::elkady();
  ctl::add_effect(mm, "actuator_inertia", 0, {2.0});
  ctl::add_effect(mm, "actuator_inertia", 2, {6.0});
  double worst = 0.0, T_end = 0.0, worst0 = 0.0, T0_end = 0.0;
  free_fall(ctl::Machine(mm), worst, T_end);
  free_fall(ctl::Machine(ctl::MachineModel::elkady()), worst0, T0_end);
  EXPECT_GT(T_end, 0.1);
  EXPECT_LT(worst, 1e-9 * T_end);
  // The same weight over a larger inertia: the same time gives less fall, hence less energy.
  EXPECT_LT(T_end, 0.9 * T0_end);
}

// Computed torque with an exact model and no saturation makes the error obey
// e_dd + Kd e_d + Kp e = 0 (Elkady eq. 19). Start at rest at P1 on the
// paper's circle: e(0) = 0, e_d(0) = (0, e0, 0).
void check_error_dynamics(double kp, double kd, double rate) {
  ctl::MachineModel mm = ctl::MachineModel::elkady();
  mm.force_limit = 1e6;  // no saturation
  const ctl::Machine m(mm);
  const ctl::Controller c(m, ctl::ControlLaw::computed_torque, {Vec3::Constant(kp), Vec3::Constant(kd)});
  Plant plant(m, PlantOptions{});
  const ctl::CircleTrajectory circle(ctl::CircleSpec{});
  LoopOptions lo;
  lo.rate_hz = rate;
  lo.duration = 0.3;
  const RunResult r = run_closed_loop(c, plant, circle, lo);
  ASSERT_TRUE(r.ok()) << describe(r.fault);
  EXPECT_EQ(r.metrics.saturated_samples, 0);
  const double e0 = 0.175 * M_PI / 2;
  const double wn = std::sqrt(kp), zeta = kd / (2 * wn);
  auto closed_form = [&](double t) {
    if (std::abs(zeta - 1.0) < 1e-9) return e0 * t * std::exp(-wn * t);  // Elkady eq. 24
    const double wd = wn * std::sqrt(1 - zeta * zeta);
    return e0 / wd * std::exp(-zeta * wn * t) * std::sin(wd * t);
  };
  double peak = 0.0, worst = 0.0, worst_xz = 0.0;
  for (const LogRow& row : r.log) {
    const Vec3 e = row.p_ref - row.p;
    const double expect = closed_form(row.t);
    peak = std::max(peak, std::abs(expect));
    worst = std::max(worst, std::abs(e.y() - expect));
    worst_xz = std::max({worst_xz, std::abs(e.x()), std::abs(e.z())});
  }
  // The zero-order hold delays the force by half a period: the deviation
  // from the continuous-time solution is O(dt) relative to the peak.
  EXPECT_LT(worst, 0.02 * peak) << "kp " << kp << " kd " << kd;
  EXPECT_LT(worst_xz, 0.02 * peak);
}

TEST(ComputedTorque, ErrorFollowsTheClosedFormCriticallyDamped) { check_error_dynamics(2550.25, 101.0, 10000.0); }
TEST(ComputedTorque, ErrorFollowsTheClosedFormUnderdamped) { check_error_dynamics(2500.0, 40.0, 10000.0); }

TEST(Plant, EncoderQuantisesAndAddsNoise) {
  const ctl::Machine m(ctl::MachineModel::elkady());
  PlantOptions opt;
  opt.encoder.resolution = 1e-6;
  Plant plant(m, opt);
  ASSERT_TRUE(plant.reset(Vec3(0.4123456789, 0.4, 0.35)));
  const EncoderReading r = plant.read();
  for (int i = 0; i < 3; ++i) EXPECT_NEAR(std::remainder(r.d[i], 1e-6), 0.0, 1e-15);
  EXPECT_NEAR(r.d.x(), 0.4123456789 - 0.225, 0.5e-6 + 1e-15);
  opt.encoder = {};
  opt.encoder.position_noise = 1e-6;
  Plant noisy(m, opt);
  ASSERT_TRUE(noisy.reset(Vec3(0.4, 0.4, 0.35)));
  double sum2 = 0;
  const int n = 4000;
  for (int k = 0; k < n; ++k) sum2 += std::pow(noisy.read().d.x() - 0.175, 2);
  EXPECT_NEAR(std::sqrt(sum2 / n), 1e-6, 0.1e-6);
}

TEST(Plant, BacklashShowsInTheEncoderWhenAnAxisReverses) {
  ctl::MachineModel mm = ctl::MachineModel::elkady();
  ctl::add_effect(mm, "backlash", 0, {50e-6});
  const ctl::Machine truth(mm);
  Plant plant(truth, PlantOptions{});
  const Vec3 p(0.4, 0.4, 0.35);
  ASSERT_TRUE(plant.reset(p, Vec3(0.01, 0, 0)));
  ASSERT_TRUE(plant.step(Vec3(0, 0, -truth.inertia().E), 1e-4));  // moving +x
  const double d_plus = plant.read().d.x() - (plant.position().x() - 0.225);
  ASSERT_TRUE(plant.reset(p, Vec3(-0.01, 0, 0)));
  ASSERT_TRUE(plant.step(Vec3(0, 0, -truth.inertia().E), 1e-4));  // moving -x
  const double d_minus = plant.read().d.x() - (plant.position().x() - 0.225);
  // d~ = d - (b/2) dir: the encoder reads b/2 ahead of the carriage in each direction.
  EXPECT_NEAR(d_plus, 25e-6, 1e-12);
  EXPECT_NEAR(d_minus, -25e-6, 1e-12);
}

TEST(Plant, RefusesBadInputAndKeepsItsState) {
  const ctl::Machine m(ctl::MachineModel::elkady());
  Plant plant(m, PlantOptions{});
  EXPECT_EQ(plant.reset(Vec3(0.1, 0.4, 0.35)).fault, Fault::stroke_low);
  EXPECT_EQ(plant.reset(Vec3(NAN, 0.4, 0.35)).fault, Fault::not_finite);
  ASSERT_TRUE(plant.reset(Vec3(0.4, 0.4, 0.35)));
  EXPECT_EQ(plant.step(Vec3(NAN, 0, 0), 1e-3).fault, Fault::not_finite);
  EXPECT_EQ(plant.step(Vec3::Zero(), -1e-3).fault, Fault::not_finite);
  EXPECT_EQ(plant.position(), Vec3(0.4, 0.4, 0.35));
  // Driven hard into the x stroke end: the step fails and the state stays inside.
  Status s;
  for (int k = 0; k < 2000 && s.ok(); ++k) s = plant.step(Vec3(120, 0, -m.inertia().E), 1e-3);
  EXPECT_EQ(s.fault, Fault::stroke_high);
  EXPECT_EQ(s.index, 0);
  EXPECT_LE(plant.position().x(), 0.625);
  PlantOptions bad;
  bad.substeps = 0;
  EXPECT_THROW(Plant(m, bad), Error);
}

TEST(ClosedLoop, WritesAMotionLogInThePublishedLayout) {
  const ctl::Machine m(ctl::MachineModel::elkady());
  const ctl::Controller c(m, ctl::ControlLaw::computed_torque, ctl::table3_gains(ctl::ControlLaw::computed_torque));
  Plant plant(m, PlantOptions{});
  LoopOptions lo;
  lo.duration = 0.05;
  const RunResult r = run_closed_loop(c, plant, ctl::CircleTrajectory(ctl::CircleSpec{}), lo);
  ASSERT_TRUE(r.ok());
  const std::string path = ::testing::TempDir() + "/cpm_motion_log.csv";
  write_motion_log(path, r.log, 1000.0);
  std::ifstream f(path);
  std::string line;
  int comments = 0, rows = 0;
  std::string header;
  while (std::getline(f, line)) {
    if (line.rfind("#", 0) == 0) {
      ++comments;
      continue;
    }
    if (header.empty()) {
      header = line;
      continue;
    }
    ++rows;
  }
  EXPECT_EQ(header, "t,d1,d2,d3,v1,v2,v3,f1,f2,f3");
  EXPECT_EQ(rows, 50);
  EXPECT_GE(comments, 1);
}

}  // namespace
}  // namespace cpm::sim
