// SPDX-License-Identifier: Apache-2.0
// The gain check: which laws and gains hold the machine at the loop's rate.
// Its figures are checked against the closed form of a sampled double
// integrator under PD, against a direct simulation of the sampled loop (and
// the eigenvalues of that simulation's step, the augmented-state matrix), and
// against the simulator's plant under the controller.
#include <gtest/gtest.h>

#include <Eigen/Eigenvalues>
#include <array>
#include <cmath>
#include <functional>

#include "cpm/control/gain_check.hpp"
#include "cpm/sim/plant.hpp"

namespace cpm::ctl {
namespace {

constexpr double kRate = 1000.0, kT = 1.0 / kRate;
constexpr double kFollowingError = 0.005;  // m, cpmd's default limits.following_error

MachineModel with_delay(MachineModel mm, double tau) {
  // As config/machine-canopen.yaml adds the bus's period: one machine-wide effect.
  if (tau > 0.0) add_effect(mm, "actuation_delay", -1, {tau});
  return mm;
}

// A machine whose links weigh nothing: the platform is a point mass m3 + m4
// on every actuator, everywhere (M = 2A I, 2A = m3 + m4; J = I), held against
// its weight (m3 + m4) g by the z actuator alone.
MachineModel point_mass() {
  MachineModel mm = MachineModel::elkady();
  mm.masses = {0.0, 0.0, 0.2, 0.3};
  return mm;
}
constexpr double kPointMass = 0.5;  // kg

// One mass under PD sampled at T with a zero-order hold, the command given at
// t_j acting from t_j + tau, stepped directly: between switching instants the
// force is constant and the motion is exact. State: x, v, the previous
// sample of x, then the commands given 1 ... N periods ago. Written apart
// from loop_polynomial, from the description of the loop only.
struct DirectLoop {
  double m, T, tau, kp, kd;
  bool difference;

  [[nodiscard]] int past() const { return static_cast<int>(std::ceil(tau / T - 1e-9)) + 1; }
  [[nodiscard]] int size() const { return 3 + past(); }
  [[nodiscard]] Eigen::VectorXd step(const Eigen::VectorXd& s) const {
    const double x = s[0], v = s[1], x_prev = s[2];
    const double u = -kp * x - kd * (difference ? (x - x_prev) / T : v);
    const auto command = [&](int j) { return j == 0 ? u : s[2 + j]; };  // given j periods ago
    double xs = x, vs = v, t = 0.0;
    while (t < T) {
      int j = 0;  // the newest command already acting at t
      while (-j * T + tau > t + 1e-9 * T) ++j;
      const double end = j == 0 ? T : std::min(T, -(j - 1) * T + tau);
      const double dt = end - t, a = command(j) / m;
      xs += vs * dt + 0.5 * a * dt * dt;
      vs += a * dt;
      t = end;
    }
    Eigen::VectorXd next(size());
    next << xs, vs, x, u, s.segment(3, past() - 1);
    return next;
  }
  // The augmented-state matrix: the step is linear, its columns are the
  // steps of the unit states, here in units that make its entries of one
  // size (v in m per period, the commands in m per period^2): in N and m/s
  // they span ten decades and cost the eigenvalues five digits.
  [[nodiscard]] double spectral_radius() const {
    Eigen::VectorXd unit = Eigen::VectorXd::Constant(size(), m / (T * T));
    unit.head(3) << 1.0, 1.0 / T, 1.0;
    Eigen::MatrixXd A(size(), size());
    for (int i = 0; i < size(); ++i) A.col(i) = step(unit[i] * Eigen::VectorXd::Unit(size(), i)).cwiseQuotient(unit);
    return Eigen::EigenSolver<Eigen::MatrixXd>(A, false).eigenvalues().cwiseAbs().maxCoeff();
  }
  // |x| at the end of 2000 steps from x = 1 mm at rest, over the start.
  [[nodiscard]] double growth_over_2000_steps() const {
    Eigen::VectorXd s = Eigen::VectorXd::Zero(size());
    s[0] = s[2] = 1e-3;
    double late = 0.0;
    for (int k = 0; k < 2000; ++k) {
      s = step(s);
      if (k >= 1900) late = std::max(late, std::abs(s[0]));
    }
    return late / 1e-3;
  }
};

// The closed form: a mass m, exact velocity, no delay. With a = kp T^2 / m and
// b = kd T / m the loop's polynomial is z^2 - (2 - a/2 - b) z + (1 - b + a/2);
// both roots lie within |z| < r when (Jury, on the polynomial in z / r)
//   b > 1 - r^2 + a/2,                      (the product of the roots)
//   b < 1 + r^2 + a/2,
//   b < (1 + r) + (a/2)(1 - r)/(1 + r),     (a root at z = -r)
//   b < (1 - r) + (a/2)(1 + r)/(1 - r),     (a root at z = +r)
// which at r = 1 is the known 0 < kp T < 2 kd, kd T / m < 2.
struct ClosedForm {
  double kd_min, kd_max, kp_min, kp_max;
};
ClosedForm closed_form(double m, double kp, double kd, double r) {
  const double a = kp * kT * kT / m, b = kd * kT / m;
  const double b_max = std::min({1 + r * r + a / 2, (1 + r) + (a / 2) * (1 - r) / (1 + r),
                                 (1 - r) + (a / 2) * (1 + r) / (1 - r)});
  const double a_min = std::max({0.0, 2 * (b - 1 - r * r), 2 * (1 + r) * (b - (1 + r)) / (1 - r),
                                 2 * (1 - r) * (b - (1 - r)) / (1 + r)});
  const double s = m / (kT * kT);
  return {(1 - r * r + a / 2) * m / kT, b_max * m / kT, a_min * s, 2 * (b - 1 + r * r) * s};
}

TEST(GainCheck, Table3GainsHoldTheMachineAt1kHzWithAndWithoutTheBusDelay) {
  for (const double tau : {0.0, kT}) {
    const Machine m(with_delay(MachineModel::elkady(), tau));
    for (ControlLaw law : {ControlLaw::pd, ControlLaw::pd_gravity, ControlLaw::pd_feedforward,
                           ControlLaw::computed_torque})
      for (VelocityMeasurement vel : {VelocityMeasurement::difference, VelocityMeasurement::exact}) {
        SCOPED_TRACE(std::string(law_name(law)) + " tau " + std::to_string(tau) +
                     (vel == VelocityMeasurement::exact ? " exact" : " difference"));
        const Gains g = table3_gains(law);
        const GainVerdict v = check_gains(m, law, g, kRate, kFollowingError, vel);
        EXPECT_TRUE(v.ok) << v.reason;
        EXPECT_EQ(v.reason, "");
        EXPECT_EQ(v.axis, -1);
        EXPECT_LT(v.spectral_radius, max_spectral_radius(kRate));
        EXPECT_TRUE((g.kd.array() < v.kd_max.array()).all() && (g.kd.array() > v.kd_min.array()).all());
        EXPECT_TRUE((g.kp.array() < v.kp_max.array()).all() && (g.kp.array() > v.kp_min.array()).all());
        // pd holds the weight by 12691 N/m: 43.9 N at worst, 3.5 mm.
        if (law == ControlLaw::pd) {
          EXPECT_GT(v.sag, m.inertia().E / g.kp.z());
          EXPECT_LT(v.sag, kFollowingError);
        } else {
          EXPECT_EQ(v.sag, 0.0);
        }
      }
  }
}

TEST(GainCheck, EffectiveMassesAreTheModelsInertiaSeenByEachActuator) {
  // Planted: a point mass everywhere, and a payload adds to it on every actuator.
  MachineModel mm = point_mass();
  const GainVerdict v = check_gains(Machine(mm), ControlLaw::pd_gravity, table3_gains(ControlLaw::pd_gravity), kRate,
                                    kFollowingError);
  EXPECT_LT((v.mass_min - Vec3::Constant(kPointMass)).norm(), 1e-12);
  EXPECT_LT((v.mass_max - Vec3::Constant(kPointMass)).norm(), 1e-12);
  add_effect(mm, "payload_mass", -1, {2.0});
  const GainVerdict p = check_gains(Machine(mm), ControlLaw::pd_gravity, table3_gains(ControlLaw::pd_gravity),
                                    kRate, kFollowingError);
  EXPECT_LT((p.mass_min - Vec3::Constant(kPointMass + 2.0)).norm(), 1e-12);
  // Elkady's machine: never lighter than the platform and links moving with it,
  // 2A = m1 + 2 m2 + m3 + m4, which the z actuator alone reaches (docs/model.md);
  // the links' rotation adds up to twice as much again.
  const Machine e(MachineModel::elkady());
  const GainVerdict ve = check_gains(e, ControlLaw::pd_gravity, table3_gains(ControlLaw::pd_gravity), kRate,
                                     kFollowingError);
  EXPECT_TRUE((ve.mass_min.array() >= 2 * e.inertia().A - 1e-12).all());
  EXPECT_NEAR(ve.mass_min.z(), 2 * e.inertia().A, 1e-4);
  EXPECT_TRUE((ve.mass_max.array() > 1.5 * ve.mass_min.array()).all());
  // Computed torque normalises by M: one unit mass.
  const GainVerdict ct = check_gains(e, ControlLaw::computed_torque, table3_gains(ControlLaw::computed_torque),
                                     kRate, kFollowingError);
  EXPECT_EQ(ct.mass_min, Vec3::Ones());
  EXPECT_EQ(ct.mass_max, Vec3::Ones());
}

TEST(GainCheck, BoundsWithoutDelayAreTheClosedFormOfTheSampledDoubleIntegrator) {
  const Machine m(point_mass());
  const double r = max_spectral_radius(kRate);
  EXPECT_NEAR(r, std::exp(-1e-3), 1e-15);
  for (const auto& [kp, kd] : {std::pair{12691.0, 436.0}, std::pair{8507.0, 100.0}, std::pair{2000.0, 600.0}}) {
    const Gains g{Vec3::Constant(kp), Vec3::Constant(kd)};
    const GainVerdict v = check_gains(m, ControlLaw::pd_gravity, g, kRate, kFollowingError, VelocityMeasurement::exact);
    const ClosedForm c = closed_form(kPointMass, kp, kd, r);
    for (int i = 0; i < 3; ++i) {
      EXPECT_NEAR(v.kd_max[i], c.kd_max, 1e-4 * c.kd_max);
      EXPECT_NEAR(v.kd_min[i], c.kd_min, 1e-4 * c.kd_min);
      EXPECT_NEAR(v.kp_max[i], c.kp_max, 1e-4 * c.kp_max);
      EXPECT_NEAR(v.kp_min[i], c.kp_min, 1e-4 * c.kp_min);
    }
    // At r = 1 the known boundary kd T / m = 2, kp T = 2 kd: the spectral radius crosses 1 there.
    const AxisLoop l{kPointMass, kT, 0.0, VelocityMeasurement::exact};
    const double kd_edge = 2 * kPointMass / kT, kp_edge = 2 * kd / kT;
    EXPECT_LT(loop_spectral_radius(l, kp, 0.995 * kd_edge), 1.0);
    EXPECT_GT(loop_spectral_radius(l, kp, 1.005 * kd_edge), 1.0);
    EXPECT_LT(loop_spectral_radius(l, 0.995 * kp_edge, kd), 1.0);
    EXPECT_GT(loop_spectral_radius(l, 1.005 * kp_edge, kd), 1.0);
  }
  // Computed torque is the same loop on a unit mass, gains in 1/s^2 and 1/s.
  const GainVerdict ct = check_gains(m, ControlLaw::computed_torque, table3_gains(ControlLaw::computed_torque), kRate,
                                     kFollowingError, VelocityMeasurement::exact);
  const ClosedForm c = closed_form(1.0, 2550.25, 101.0, r);
  EXPECT_NEAR(ct.kd_max.x(), c.kd_max, 1e-4 * c.kd_max);
  EXPECT_NEAR(ct.kp_max.x(), c.kp_max, 1e-4 * c.kp_max);
}

TEST(GainCheck, BoundsWithDifferencedVelocityAreItsClosedForm) {
  // v = (x_k - x_k-1) / T, no delay: (one root at 0 and) the cubic
  //   z^3 + (-2 + (a + b)/2) z^2 + (1 + a/2) z - b/2.
  // Its roots lie within |z| < r when Jury's conditions hold for the cubic
  // in w = z / r, w^3 + c2 w^2 + c1 w + c0:
  //   1 + c2 + c1 + c0 > 0, 1 - c2 + c1 - c0 > 0, |c0| < 1, |c0 c2 - c1| < 1 - c0^2,
  // each linear in a at a given b: kp_max is where the first fails. At r = 1
  // they reduce to 0 < b < 2 and a < 2b (2 - b) / (2 + b).
  const Machine m(point_mass());
  const double r = max_spectral_radius(kRate);
  for (const double kd : {200.0, 436.0, 800.0}) {
    const Gains g{Vec3::Constant(12691.0), Vec3::Constant(kd)};
    const GainVerdict v = check_gains(m, ControlLaw::pd_gravity, g, kRate, kFollowingError);
    const double b = kd * kT / kPointMass;
    const auto coefficients = [&](double a) {
      return std::array<double, 3>{(-2 + (a + b) / 2) / r, (1 + a / 2) / (r * r), -b / 2 / (r * r * r)};
    };
    const std::function<double(double)> conditions[] = {
        [&](double a) { const auto c = coefficients(a); return 1 + c[0] + c[1] + c[2]; },
        [&](double a) { const auto c = coefficients(a); return 1 - c[0] + c[1] - c[2]; },
        [&](double a) { const auto c = coefficients(a); return 1 - c[2] * c[2] - (c[2] * c[0] - c[1]); },
        [&](double a) { const auto c = coefficients(a); return 1 - c[2] * c[2] + (c[2] * c[0] - c[1]); },
    };
    double a_max = INFINITY;
    for (const auto& f : conditions) {
      const double at0 = f(0.0), slope = f(1.0) - f(0.0);
      if (slope < 0) a_max = std::min(a_max, -at0 / slope);
    }
    EXPECT_NEAR(v.kp_max.x(), a_max * kPointMass / (kT * kT), 1e-4 * v.kp_max.x()) << kd;
    // r = 1
    const AxisLoop l{kPointMass, kT, 0.0, VelocityMeasurement::difference};
    const double kp_edge = 2 * b * (2 - b) / (2 + b) * kPointMass / (kT * kT);
    EXPECT_LT(loop_spectral_radius(l, 0.995 * kp_edge, kd), 1.0);
    EXPECT_GT(loop_spectral_radius(l, 1.005 * kp_edge, kd), 1.0);
  }
  // b < 2 where a is small enough not to bind first (a < 0.01 near b = 2).
  const AxisLoop l{kPointMass, kT, 0.0, VelocityMeasurement::difference};
  EXPECT_LT(loop_spectral_radius(l, 1000.0, 0.995 * 2 * kPointMass / kT), 1.0);
  EXPECT_GT(loop_spectral_radius(l, 1000.0, 1.005 * 2 * kPointMass / kT), 1.0);
}

TEST(GainCheck, TheLoopsPolynomialHasTheEigenvaluesOfTheAugmentedStateMatrix) {
  // Integer and fractional delays, both velocities, loops that hold and loops that do not.
  for (const double periods : {0.0, 0.3, 1.0, 1.5, 2.0, 3.7})
    for (const bool difference : {false, true})
      for (const auto& [kp, kd] : {std::pair{12691.0, 436.0}, std::pair{2e5, 3000.0}, std::pair{500.0, 20.0}}) {
        const DirectLoop d{3.0, kT, periods * kT, kp, kd, difference};
        const AxisLoop l{3.0, kT, periods * kT,
                         difference ? VelocityMeasurement::difference : VelocityMeasurement::exact};
        EXPECT_NEAR(loop_spectral_radius(l, kp, kd), d.spectral_radius(), 1e-8)
            << periods << " periods, difference " << difference << ", kp " << kp << ", kd " << kd;
      }
}

TEST(GainCheck, AKdAboveTheBoundIsRefusedWithTheFigure) {
  const Machine m(MachineModel::elkady());
  const GainVerdict ok = check_gains(m, ControlLaw::pd_gravity, table3_gains(ControlLaw::pd_gravity), kRate,
                                     kFollowingError);
  ASSERT_TRUE(ok.ok);
  // Equal gains on all three: the z actuator, the lightest, bounds kd.
  EXPECT_LT(ok.kd_max.z(), ok.kd_max.x());
  EXPECT_LT(ok.kd_max.z(), ok.kd_max.y());
  Gains g = table3_gains(ControlLaw::pd_gravity);
  g.kd.setConstant(5000.0);
  const GainVerdict v = check_gains(m, ControlLaw::pd_gravity, g, kRate, kFollowingError);
  // kd T / m = 5 / 3.784 = 1.32 against 2: stable without a delay...
  EXPECT_TRUE(v.ok) << v.reason;
  // ...but not with the bus's period.
  const Machine md(with_delay(MachineModel::elkady(), kT));
  const GainVerdict d = check_gains(md, ControlLaw::pd_gravity, g, kRate, kFollowingError);
  ASSERT_FALSE(d.ok);
  EXPECT_EQ(d.axis, 2);
  const DirectLoop z{d.mass_min.z(), kT, kT, 8507.0, 5000.0, true};
  EXPECT_NEAR(d.spectral_radius, z.spectral_radius(), 1e-8);
  EXPECT_GT(d.spectral_radius, 1.0);
  char pole[32];
  std::snprintf(pole, sizeof pole, "|z| = %.4f", d.spectral_radius);
  char most[32];
  std::snprintf(most, sizeof most, "at most %.0f N s/m", std::floor(d.kd_max.z()));
  for (const std::string& part : {std::string("pd_gravity: "), std::string("kd_z = 5000 N s/m"),
                                 std::string("lightest effective mass 3.78 kg"), std::string("at 1000 Hz"),
                                 std::string(pole), std::string(most)})
    EXPECT_NE(d.reason.find(part), std::string::npos) << part << " in: " << d.reason;
  // The bound itself: just above it the loop diverges, just below it decays.
  EXPECT_GT((DirectLoop{d.mass_min.z(), kT, kT, 8507.0, 1.02 * d.kd_max.z(), true}).growth_over_2000_steps(), 10.0);
  EXPECT_LT((DirectLoop{d.mass_min.z(), kT, kT, 8507.0, 0.98 * d.kd_max.z(), true}).growth_over_2000_steps(), 0.01);
}

TEST(GainCheck, ADelayOfOnePeriodLowersTheLargestStableKd) {
  // As kp -> 0 the velocity loop alone: exact velocity v_k+1 = v_k - b v_k-1
  // (z^2 - z + b) holds for b < 1, against b < 2 without the delay: half. With
  // the differenced velocity, (z - 1)(z^2 + (b/2 - 1) z + b/2) and the delay
  // give b < 2 (sqrt 2 - 1) = 0.828.
  const AxisLoop exact{1.0, kT, kT, VelocityMeasurement::exact};
  // (A kp of 1 on a unit mass keeps the position's root just inside z = 1.)
  EXPECT_LT(loop_spectral_radius(exact, 1.0, 0.99 / kT), 1.0);
  EXPECT_GT(loop_spectral_radius(exact, 1.0, 1.01 / kT), 1.0);
  const AxisLoop diff{1.0, kT, kT, VelocityMeasurement::difference};
  const double b = 2 * (std::sqrt(2.0) - 1);
  EXPECT_LT(loop_spectral_radius(diff, 1.0, 0.99 * b / kT), 1.0);
  EXPECT_GT(loop_spectral_radius(diff, 1.0, 1.01 * b / kT), 1.0);

  // On the machine, with Table 3's kp, for both velocities and whole and half periods.
  const Gains g = table3_gains(ControlLaw::pd_gravity);
  for (const bool difference : {false, true}) {
    const auto vel = difference ? VelocityMeasurement::difference : VelocityMeasurement::exact;
    const Machine m(point_mass());
    const GainVerdict none = check_gains(m, ControlLaw::pd_gravity, g, kRate, kFollowingError, vel);
    double before = none.kd_max.x();
    for (const double periods : {0.5, 1.0, 1.5}) {
      SCOPED_TRACE(std::to_string(periods) + " periods, difference " + std::to_string(difference));
      const Machine md(with_delay(point_mass(), periods * kT));
      const GainVerdict v = check_gains(md, ControlLaw::pd_gravity, g, kRate, kFollowingError, vel);
      EXPECT_LT(v.kd_max.x(), before);
      before = v.kd_max.x();
      // A direct simulation of that loop diverges just above the bound and decays just below.
      const auto loop = [&](double kd) { return DirectLoop{kPointMass, kT, periods * kT, g.kp.x(), kd, difference}; };
      EXPECT_GT(loop(1.02 * v.kd_max.x()).growth_over_2000_steps(), 10.0);
      EXPECT_LT(loop(0.98 * v.kd_max.x()).growth_over_2000_steps(), 0.01);
    }
    // One period: about half the undelayed bound (0.5 and 0.41 as kp -> 0).
    const Machine m1(with_delay(point_mass(), kT));
    const double ratio =
        check_gains(m1, ControlLaw::pd_gravity, g, kRate, kFollowingError, vel).kd_max.x() / none.kd_max.x();
    EXPECT_NEAR(ratio, difference ? 0.414 : 0.5, 0.01);
  }
}

TEST(GainCheck, PdWithKp100IsRefusedForTheSag) {
  // The point mass: 0.5 kg g = 4.905 N on z alone, 49.05 mm at 100 N/m.
  Gains g = table3_gains(ControlLaw::pd);
  g.kp.setConstant(100.0);
  const GainVerdict p = check_gains(Machine(point_mass()), ControlLaw::pd, g, kRate, kFollowingError);
  ASSERT_FALSE(p.ok);
  EXPECT_EQ(p.axis, 2);
  EXPECT_NEAR(p.sag, kPointMass * kGravity / 100.0, 1e-12);
  EXPECT_NE(p.reason.find("pd: kp_z = 100 N/m would let z sag 49.1 mm under the weight it holds (4.91 N), more than "
                          "the 5.000 mm the following-error limit allows: at least 981 N/m"),
            std::string::npos)
      << p.reason;
  // Elkady's machine: the platform's weight E = 37.1 N and the links' moment
  // on z; a payload of 2 kg adds its weight to the worst pose's, exactly.
  MachineModel mm = MachineModel::elkady();
  const Machine e(mm);
  const GainVerdict v = check_gains(e, ControlLaw::pd, g, kRate, kFollowingError);
  ASSERT_FALSE(v.ok);
  EXPECT_EQ(v.axis, 2);
  EXPECT_GT(v.sag, e.inertia().E / 100.0);
  EXPECT_LT(v.sag, 1.25 * e.inertia().E / 100.0);
  add_effect(mm, "payload_mass", -1, {2.0});
  const GainVerdict heavy = check_gains(Machine(mm), ControlLaw::pd, g, kRate, kFollowingError);
  EXPECT_NEAR(heavy.sag - v.sag, 2.0 * kGravity / 100.0, 1e-9);
  // With the model's gravity there is no sag; kd 436 N s/m over kp 100 N/m
  // is then a 4.4 s pole, too slow to hold anything either.
  const GainVerdict grav = check_gains(e, ControlLaw::pd_gravity, g, kRate, kFollowingError);
  EXPECT_EQ(grav.sag, 0.0);
  ASSERT_FALSE(grav.ok);
  EXPECT_GT(grav.spectral_radius, max_spectral_radius(kRate));
  EXPECT_LT(grav.spectral_radius, 1.0);
  EXPECT_NE(grav.reason.find("time constant of 4.4 s"), std::string::npos) << grav.reason;
}

TEST(GainCheck, EveryMassBetweenTheLightestAndTheHeaviestHolds) {
  // The check tries the two ends of each actuator's mass range: the masses
  // between them hold too, near the bounds on both sides.
  const Machine m(with_delay(MachineModel::elkady(), kT));
  const double r = max_spectral_radius(kRate);
  const GainVerdict base = check_gains(m, ControlLaw::pd_gravity, table3_gains(ControlLaw::pd_gravity), kRate,
                                       kFollowingError);
  for (const Vec3& kd : {Vec3(0.999 * base.kd_max), Vec3(1.001 * base.kd_min)}) {
    Gains g = table3_gains(ControlLaw::pd_gravity);
    g.kd = kd;
    const GainVerdict v = check_gains(m, ControlLaw::pd_gravity, g, kRate, kFollowingError);
    ASSERT_TRUE(v.ok) << v.reason;
    for (int i = 0; i < 3; ++i)
      for (int k = 0; k <= 50; ++k) {
        const double mass = v.mass_min[i] + (v.mass_max[i] - v.mass_min[i]) * k / 50.0;
        EXPECT_LT(loop_spectral_radius({mass, kT, kT, VelocityMeasurement::difference}, g.kp[i], kd[i]), r)
            << "actuator " << i << ", " << mass << " kg, kd " << kd[i];
      }
  }
}

TEST(GainCheck, BadGainsAreRefusedByKeyAndBadSettingsThrow) {
  const Machine m(MachineModel::elkady());
  const struct {
    ControlLaw law;
    int axis;
    bool kp;
    double value;
    const char* says;
  } cases[] = {
      {ControlLaw::pd, 1, false, 0.0, "pd: kd_y = 0 N s/m: a gain must be finite and > 0."},
      {ControlLaw::pd_gravity, 0, true, -5.0, "pd_gravity: kp_x = -5 N/m: a gain must be finite and > 0."},
      {ControlLaw::computed_torque, 2, true, NAN, "computed_torque: kp_z = nan 1/s^2: a gain must be finite and > 0."},
      {ControlLaw::computed_torque, 2, false, INFINITY, "computed_torque: kd_z = inf 1/s: a gain must be finite and > 0."},
  };
  for (const auto& c : cases) {
    Gains g = table3_gains(c.law);
    (c.kp ? g.kp : g.kd)[c.axis] = c.value;
    const GainVerdict v = check_gains(m, c.law, g, kRate, kFollowingError);
    EXPECT_FALSE(v.ok);
    EXPECT_EQ(v.axis, c.axis);
    EXPECT_EQ(v.reason, c.says);
  }
  const Gains g = table3_gains(ControlLaw::pd);
  EXPECT_THROW(check_gains(m, ControlLaw::pd, g, 0.0, kFollowingError), Error);
  EXPECT_THROW(check_gains(m, ControlLaw::pd, g, NAN, kFollowingError), Error);
  EXPECT_THROW(check_gains(m, ControlLaw::pd, g, kRate, -1.0), Error);
  // Computed torque: the advice is in its own units and names no mass.
  Gains ct = table3_gains(ControlLaw::computed_torque);
  ct.kd.setConstant(2500.0);
  const GainVerdict v = check_gains(m, ControlLaw::computed_torque, ct, kRate, kFollowingError);
  ASSERT_FALSE(v.ok);
  EXPECT_NE(v.reason.find("1/s keeps every pole"), std::string::npos) << v.reason;
  EXPECT_EQ(v.reason.find("kg"), std::string::npos) << v.reason;
}

// The simulator's plant under the controller, at the pose where the z
// actuator is lightest (there its limbs do not couple it to x and y).
struct PlantRun {
  double growth = 0.0;  // |z error| at the end over the start, or inf when the loop broke
};
// A stiffer kp than Table 3's makes the slow pole (about kp / kd) fast enough
// that 2000 periods tell decay from growth near the kd bound.
Gains plant_gains() { return {Vec3::Constant(50000.0), Vec3::Constant(436.0)}; }
PlantRun run_plant(const Machine& truth, const Machine& model, double kd_z) {
  // The lightest pose: the z actuator's mass is 2A where Gamma's z column vanishes.
  const kin::Strokes& s = truth.model().strokes;
  Vec3 best_p = Vec3::Zero();
  double best = INFINITY;
  for (int i = 0; i <= 8; ++i)
    for (int j = 0; j <= 8; ++j)
      for (int k = 0; k <= 8; ++k) {
        const Vec3 d = s.min + (s.max - s.min).cwiseProduct(Vec3(i, j, k) / 8.0);
        Vec3 p;
        RigidBodyTerms t;
        if (kin::forward(truth.kinematics(), d, {}, p) && truth.rigid_body(p, Vec3::Zero(), t) && t.M(2, 2) < best) {
          best = t.M(2, 2);
          best_p = p;
        }
      }
  Gains g = plant_gains();
  g.kd.z() = kd_z;
  const Controller c(model, ControlLaw::pd_gravity, g);
  sim::Plant plant(truth, sim::PlantOptions{});
  Vec3 hold;
  EXPECT_TRUE(truth.holding_command(best_p, {}, hold));
  // Far below what saturates the drives (an oscillation at the kd bound
  // reaches the 120 N limit from about 10 um and stays there).
  const double start = 1e-9;
  EXPECT_TRUE(plant.reset(best_p + Vec3(0, 0, start), Vec3::Zero(), hold));
  ControllerState state;
  state.reset(hold);
  ControlInput in;
  in.ref.p = best_p;
  ControlOutput out;
  double late = 0.0;
  for (int k = 0; k < 2000; ++k) {
    const sim::EncoderReading enc = plant.read();
    in.d = enc.d;
    in.d_dot = enc.d_dot;
    in.kin.t = k * kT;
    if (!c.step(in, state, out) || !plant.step(out.force, kT)) return {INFINITY};
    const double e = std::abs(plant.position().z() - best_p.z());
    if (e > 1e-3) return {INFINITY};  // far outside anything linear: diverged
    if (k >= 1900) late = std::max(late, e);
  }
  return {late / start};
}

TEST(GainCheck, TheSimulatorsPlantAgreesWithTheBound) {
  // The plant's encoders give the velocity itself: the exact measurement.
  const Machine nominal(MachineModel::elkady());
  const GainVerdict v =
      check_gains(nominal, ControlLaw::pd_gravity, plant_gains(), kRate, kFollowingError, VelocityMeasurement::exact);
  ASSERT_TRUE(v.ok) << v.reason;
  EXPECT_GT(run_plant(nominal, nominal, 1.02 * v.kd_max.z()).growth, 10.0);
  EXPECT_LT(run_plant(nominal, nominal, 0.98 * v.kd_max.z()).growth, 0.01);
  // A truth with the bus's period and a controller that does not know it: the delayed bound.
  const Machine delayed(with_delay(MachineModel::elkady(), kT));
  const GainVerdict d =
      check_gains(delayed, ControlLaw::pd_gravity, plant_gains(), kRate, kFollowingError, VelocityMeasurement::exact);
  ASSERT_TRUE(d.ok) << d.reason;
  EXPECT_GT(run_plant(delayed, nominal, 1.02 * d.kd_max.z()).growth, 10.0);
  EXPECT_LT(run_plant(delayed, nominal, 0.98 * d.kd_max.z()).growth, 0.01);
  // A controller that knows it predicts across it, and with an exact model
  // holds above the delayed bound: the check gives that prediction no credit.
  EXPECT_LT(run_plant(delayed, delayed, 1.5 * d.kd_max.z()).growth, 0.01);
}

}  // namespace
}  // namespace cpm::ctl
