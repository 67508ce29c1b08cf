// SPDX-License-Identifier: Apache-2.0
// Trajectories: geometry, derivatives, limits, and refusal of bad ones.
#include <gtest/gtest.h>

#include <cmath>

#include "cpm/control/trajectory.hpp"

namespace cpm::ctl {
namespace {

void expect_consistent_derivatives(const Trajectory& tr, double tol_v, double tol_a) {
  const double h = 1e-6;
  for (double t = 2e-3; t < tr.duration() - 2e-3; t += tr.duration() / 97.0) {
    const auto s = tr.sample(t), sp = tr.sample(t + h), sm = tr.sample(t - h);
    EXPECT_LT((s.v - (sp.p - sm.p) / (2 * h)).norm(), tol_v) << "t = " << t;
    EXPECT_LT((s.a - (sp.v - sm.v) / (2 * h)).norm(), tol_a) << "t = " << t;
  }
}

TEST(Circle, ElkadysCircleIsTheOneOfThePaper) {
  const CircleTrajectory c(CircleSpec{});
  EXPECT_DOUBLE_EQ(c.duration(), 4.0);
  for (double t : {0.0, 0.3, 1.7, 3.999}) {
    const auto s = c.sample(t);
    // x = 0.425 + 0.175 cos(pi t / 2), y = 0.425 + 0.175 sin(pi t / 2), z = 0.3.
    EXPECT_NEAR(s.p.x(), 0.425 + 0.175 * std::cos(M_PI / 2 * t), 1e-15);
    EXPECT_NEAR(s.p.y(), 0.425 + 0.175 * std::sin(M_PI / 2 * t), 1e-15);
    EXPECT_DOUBLE_EQ(s.p.z(), 0.3);
  }
  // It starts at full speed: 0.175 * pi / 2 = 0.2749 m/s along y.
  EXPECT_NEAR(c.sample(0.0).v.y(), 0.175 * M_PI / 2, 1e-15);
  expect_consistent_derivatives(c, 1e-7, 1e-6);
}

TEST(Circle, RampedCircleStartsAndEndsAtRestWithoutJumps) {
  CircleSpec s;
  s.ramp_time = 0.5;
  s.cruise_time = 2.0;
  s.plane = CirclePlane::zx;
  s.radius = 0.05;
  s.angular_speed = -2.0;  // clockwise
  const CircleTrajectory c(s);
  EXPECT_DOUBLE_EQ(c.duration(), 3.0);
  EXPECT_EQ(c.sample(0.0).v, Vec3::Zero());
  EXPECT_EQ(c.sample(0.0).a, Vec3::Zero());
  EXPECT_LT(c.sample(3.0).v.norm(), 1e-15);
  EXPECT_LT(c.sample(3.0 - 1e-9).a.norm(), 1e-6);
  // Full speed in the cruise, radius everywhere, y untouched.
  EXPECT_NEAR(c.sample(1.5).v.norm(), 0.05 * 2.0, 1e-12);
  for (double t = 0; t <= 3.0; t += 0.01) {
    const auto p = c.sample(t).p;
    EXPECT_NEAR((p - s.centre).norm(), 0.05, 1e-12);
    EXPECT_DOUBLE_EQ(p.y(), s.centre.y());
  }
  expect_consistent_derivatives(c, 1e-7, 1e-5);
  // Continuous acceleration across the ramp boundaries.
  for (double tb : {0.5, 2.5})
    EXPECT_LT((c.sample(tb + 1e-7).a - c.sample(tb - 1e-7).a).norm(), 1e-4);
}

TEST(PointToPoint, RespectsItsLimitsAndArrives) {
  const Vec3 a(0.3, 0.3, 0.3), b(0.5, 0.45, 0.4);
  const MotionLimits lim{0.2, 1.5, 30.0};
  const PointToPoint m(a, b, lim);
  EXPECT_NEAR(m.peak_velocity(), 0.2, 1e-12);  // a long move reaches full speed
  double vmax = 0, amax = 0, jmax = 0;
  const double dt = 1e-4;
  for (double t = 0; t <= m.duration(); t += dt) {
    const auto s = m.sample(t);
    vmax = std::max(vmax, s.v.norm());
    amax = std::max(amax, s.a.norm());
    jmax = std::max(jmax, (m.sample(t + dt).a - s.a).norm() / dt);
    // On the straight line from a to b.
    const Vec3 dir = (b - a).normalized();
    EXPECT_LT(((s.p - a) - dir * dir.dot(s.p - a)).norm(), 1e-12);
  }
  EXPECT_LE(vmax, 0.2 * (1 + 1e-9));
  EXPECT_LE(amax, 1.5 * (1 + 1e-9));
  EXPECT_LE(jmax, 30.0 * (1 + 1e-6));
  EXPECT_LT((m.sample(m.duration()).p - b).norm(), 1e-12);
  EXPECT_EQ(m.sample(m.duration() + 1).v, Vec3::Zero());
  expect_consistent_derivatives(m, 1e-6, 1e-4);
  // Time-optimal for the limits: the time of a trapezoid with jerk ramps,
  // L / V + V / A + A / J when both limits are reached.
  const double L = (b - a).norm();
  EXPECT_NEAR(m.duration(), L / 0.2 + 0.2 / 1.5 + 1.5 / 30.0, 1e-9);
}

TEST(PointToPoint, ShortMovesNeverReachFullSpeed) {
  const MotionLimits lim{0.5, 2.0, 20.0};
  for (double len : {1e-5, 1e-3, 0.02, 0.1}) {
    const PointToPoint m(Vec3(0.3, 0.3, 0.3), Vec3(0.3 + len, 0.3, 0.3), lim);
    EXPECT_LE(m.peak_velocity(), 0.5 + 1e-12);
    EXPECT_LE(m.peak_acceleration(), 2.0 + 1e-12);
    EXPECT_NEAR(m.sample(m.duration()).p.x(), 0.3 + len, 1e-12) << len;
    double vmax = 0;
    for (double t = 0; t < m.duration(); t += m.duration() / 1000) vmax = std::max(vmax, m.sample(t).v.norm());
    EXPECT_NEAR(vmax, m.peak_velocity(), 1e-3 * m.peak_velocity() + 1e-9) << len;
  }
}

TEST(Trajectories, RefuseBadSpecifications) {
  CircleSpec s;
  s.radius = -0.1;
  EXPECT_THROW(CircleTrajectory{s}, Error);
  s = {};
  s.centre.x() = NAN;
  EXPECT_THROW(CircleTrajectory{s}, Error);
  s = {};
  s.angular_speed = 0;
  EXPECT_THROW(CircleTrajectory{s}, Error);
  s = {};
  s.cruise_time = -1;
  EXPECT_THROW(CircleTrajectory{s}, Error);
  EXPECT_THROW(PointToPoint(Vec3(0.3, 0.3, NAN), Vec3(0.4, 0.4, 0.4), MotionLimits{}), Error);
  EXPECT_THROW(PointToPoint(Vec3(0.3, 0.3, 0.3), Vec3(0.4, 0.4, 0.4), MotionLimits{0.0, 1.0, 1.0}), Error);
  EXPECT_THROW(PointToPoint(Vec3(0.3, 0.3, 0.3), Vec3(0.4, 0.4, 0.4), MotionLimits{0.1, INFINITY, 1.0}), Error);
}

TEST(Trajectories, ValidationSaysWhenWhereAndWhichLimit) {
  const Machine m(MachineModel::elkady());
  CircleSpec s;
  s.radius = 0.25;  // x = 0.675 at the start: beyond the x stroke end (0.625)
  try {
    validate_trajectory(CircleTrajectory(s), m, 1e-3);
    ADD_FAILURE() << "accepted a circle outside the workspace";
  } catch (const Error& e) {
    const std::string msg = e.what();
    EXPECT_NE(msg.find("t = 0 s"), std::string::npos) << msg;
    EXPECT_NE(msg.find("actuator 1"), std::string::npos) << msg;
  }
  EXPECT_NO_THROW(validate_trajectory(CircleTrajectory(CircleSpec{}), m, 1e-3));
  const PointToPoint fast(Vec3(0.3, 0.3, 0.3), Vec3(0.5, 0.5, 0.4), MotionLimits{0.5, 2.0, 50.0});
  EXPECT_THROW(validate_trajectory(fast, m, 1e-3, 0.3), Error);
  EXPECT_NO_THROW(validate_trajectory(fast, m, 1e-3, 0.6, 2.5));
}

}  // namespace
}  // namespace cpm::ctl
