// SPDX-License-Identifier: Apache-2.0
// The planner: closed forms on lines and arcs, the limits it is given held
// at every sample (checked here with the model's inverse dynamics), and
// look-ahead that slows before a corner rather than breaking a limit.
#include <gtest/gtest.h>

#include <cmath>
#include <numbers>

#include "path_fixtures.hpp"

namespace cpm::path::test {
namespace {

PlannerOptions cartesian(double A, double J = 1000.0) {
  PlannerOptions o;
  o.mode = PlanMode::cartesian_only;
  o.cartesian.acceleration = A;
  o.cartesian.jerk = J;
  o.knot_period = 1e-4;  // the closed forms to 0.1 ms
  return o;
}

double speed_at(const Plan& p, double t) { return p.sample(t).v.norm(); }

TEST(Planner, StraightLineIsATrapezoidPlusTheJerkFilter) {
  // Cartesian limits: a trapezoid at A to V, then a moving average of
  // T = 2 A / J that lengthens it by exactly T: t = L/V + V/A + T.
  const double L = 0.2, V = 0.15, A = 4.0, J = 1000.0;
  PathQueue q(kCentre - Vec3(L / 2, 0, 0));
  q.line(kCentre + Vec3(L / 2, 0, 0), V);
  const Plan p = plan_path(q, elkady(), cartesian(A, J));
  const double T = 2 * A / J;
  EXPECT_NEAR(p.summary().filter_time, T, 1e-12);
  // Within the grid (the switches fall inside 1 mm intervals) and a knot.
  EXPECT_NEAR(p.duration(), L / V + V / A + T, 2e-3 / V + 1e-4);
  EXPECT_NEAR(speed_at(p, p.duration() / 2), V, 1e-9);
  EXPECT_LE(p.summary().peak_acceleration, A * 1.001);
  EXPECT_LE(p.summary().peak_jerk, J * 1.001);
  EXPECT_GE(p.summary().peak_jerk, 0.45 * J);  // the jerk limit is used, not just kept
  EXPECT_LT((p.sample(p.duration()).p - q.end()).norm(), 1e-12);
  EXPECT_LT(p.sample(p.duration()).v.norm(), 1e-12);
}

TEST(Planner, ShortLineIsATriangle) {
  const double L = 0.002, V = 0.15, A = 4.0, J = 1000.0;
  PathQueue q(kCentre);
  q.line(kCentre + Vec3(0, 0, L), V);
  PlannerOptions o = cartesian(A, J);
  o.grid_step = 1e-4;  // resolve the switch in the middle of 2 mm
  const Plan p = plan_path(q, elkady(), o);
  EXPECT_NEAR(p.duration(), 2 * std::sqrt(L / A) + 2 * A / J, 2e-4);
}

TEST(Planner, ArcAtTheCentripetalLimit) {
  // |a| <= A on a circle of radius r at constant speed: v = sqrt(A r).
  const double r = 0.05, A = 4.0;
  PathQueue q(kCentre + Vec3(r, 0, 0));
  q.arc(kCentre + Vec3(r, 0, 0), kCentre, Vec3::UnitY(), 1, 0.5);
  const Plan p = plan_path(q, elkady(), cartesian(A));
  EXPECT_NEAR(speed_at(p, p.duration() / 2), std::sqrt(A * r), 1e-3 * std::sqrt(A * r));
  EXPECT_LE(p.summary().peak_acceleration, A * 1.01);
}

// The largest steady speed on the circle that keeps every actuator within
// `bound` (N), found here by bisection with the model's inverse dynamics.
double steady_force_limited_speed(const ctl::Machine& m, double r, double bound) {
  double lo = 0.0, hi = 2.0;
  for (int it = 0; it < 60; ++it) {
    const double v = 0.5 * (lo + hi);
    bool ok = true;
    for (int k = 0; k < 360 && ok; ++k) {
      const double th = 2 * std::numbers::pi * k / 360;
      const Vec3 u(std::cos(th), std::sin(th), 0), t(-std::sin(th), std::cos(th), 0);
      Vec3 F;
      EXPECT_TRUE(m.inverse_dynamics(kCentre + r * u, v * t, -v * v / r * u, F).ok());
      ok = F.cwiseAbs().maxCoeff() <= bound;  // J = I on the nominal machine
    }
    (ok ? lo : hi) = v;
  }
  return lo;
}

TEST(Planner, ArcHeldByTheActuatorForces) {
  PlannerOptions o;
  o.actuators.force = Vec3::Constant(60.0);
  o.actuators.force_reserve = 0.2;
  const double r = 0.02;
  PathQueue q(kCentre + Vec3(r, 0, 0));
  q.arc(kCentre + Vec3(r, 0, 0), kCentre, Vec3::UnitZ(), 3, 1.0);
  const Plan p = plan_path(q, elkady(), o);
  // A constant speed round the circle is feasible up to v; the plan goes at
  // least that fast, faster where the inertia the turn meets is lower, and
  // the forces reach the bound without passing it.
  const double v = steady_force_limited_speed(elkady(), r, 48.0);
  double slowest = 1e9;
  for (double t = p.duration() / 3; t < 2 * p.duration() / 3; t += 1e-3) slowest = std::min(slowest, speed_at(p, t));
  EXPECT_GE(slowest, v * 0.98);
  const double peak = peak_forces(p, elkady()).maxCoeff();
  EXPECT_LE(peak, 48.0 * 1.02);
  EXPECT_GE(peak, 48.0 * 0.97);
}

TEST(Planner, PlantedLimitsHoldAtEverySample) {
  // Tight planted limits on a machine with friction and a drive-gain error,
  // and a path with corners, an arc in the ZX plane and a climb against gravity.
  ctl::MachineModel mm = ctl::MachineModel::elkady();
  for (int i = 0; i < 3; ++i) {
    ctl::add_effect(mm, "viscous_friction", i, {8.0});
    ctl::add_effect(mm, "coulomb_friction", i, {3.0});
  }
  ctl::add_effect(mm, "force_gain", 1, {0.1});
  const ctl::Machine m(std::move(mm));
  PlannerOptions o;
  o.actuators.force = Vec3(70.0, 60.0, 80.0);
  o.actuators.velocity = Vec3(0.3, 0.2, 0.3);
  o.actuators.acceleration = Vec3(8.0, 12.0, 8.0);
  PathQueue q(kCentre, 2e-4);
  q.line(kCentre + Vec3(0.1, 0.05, 0), 0.4);
  q.arc(kCentre + Vec3(0.1, 0.05, 0.1), kCentre + Vec3(0.1, 0.05, 0.05), Vec3::UnitY(), -1, 0.4);
  q.line(kCentre + Vec3(-0.1, -0.1, 0.15), 0.4);
  q.line(kCentre, 0.0);  // rapid
  const Plan p = plan_path(q, m, o);
  EXPECT_TRUE(p.summary().actuators_within_limits);
  const Vec3 peak = peak_forces(p, m);
  for (int i = 0; i < 3; ++i) {
    EXPECT_LE(peak[i], 0.8 * o.actuators.force[i] * 1.02) << "actuator " << i + 1;
    EXPECT_LE(p.summary().peak_actuator_speed[i], o.actuators.velocity[i] * 1.01);
    EXPECT_LE(p.summary().peak_actuator_acceleration[i], o.actuators.acceleration[i] * 1.01);
  }
  for (double t = 0; t < p.duration(); t += 1e-3) {
    if (p.sample_path(t).segment < 3) {  // not the rapid
      EXPECT_LE(speed_at(p, t), 0.4 * 1.01 + 1e-9);
    }
  }
}

TEST(Planner, LookAheadSlowsBeforeASharpCorner) {
  // 300 mm straight at 0.5 m/s into a 150 degree turn with 0.05 mm tolerance.
  PathQueue q(kCentre + Vec3(-0.15, 0, 0), 5e-5);
  q.line(kCentre + Vec3(0.15, 0, 0), 0.5);
  q.line(kCentre + Vec3(0.15, 0, 0) + 0.1 * Vec3(-std::cos(0.5236), std::sin(0.5236), 0), 0.5);
  const Plan p = plan_path(q, elkady(), PlannerOptions{});
  // The speed falls monotonically from 0.25 m to the blend (0.3 m less its trim).
  const Piece& corner = p.geometry().pieces[1];
  ASSERT_EQ(corner.kind, PieceKind::blend);
  double t_corner = 0, previous = 1e9;
  for (double t = 0; t < p.duration(); t += 1e-4) {
    const PathSample s = p.sample_path(t);
    if (s.s < 0.25) continue;
    if (s.s >= corner.s0) {
      t_corner = t;
      break;
    }
    EXPECT_LE(s.ref.v.norm(), previous + 1e-6) << "t = " << t;
    previous = s.ref.v.norm();
  }
  EXPECT_LT(previous, 0.1);
  EXPECT_NEAR(speed_at(p, t_corner - 0.4), 0.5, 1e-6) << "at feed well before the corner";
  EXPECT_LE(peak_forces(p, elkady()).maxCoeff(), 96.0 * 1.02);
  bool said_why = false;
  for (const LimitedStretch& l : p.summary().limited) said_why |= l.by == Limit::actuator_force && l.s_end > 0.29;
  EXPECT_TRUE(said_why) << "the corner is held by the actuators' force";
}

TEST(Planner, CartesianPlanMayOverloadTheDrivesTheActuatorPlanDoesNot) {
  // Planted: a Cartesian acceleration the drives cannot give everywhere
  // (climbing against gravity, 37 N of weight, with 4.5 kg of inertia).
  PathQueue q(kCentre + Vec3(0, 0, 0.2), 1e-4);
  q.line(kCentre + Vec3(0, 0, -0.05), 0.5);
  q.line(kCentre + Vec3(0.1, 0, -0.05), 0.5);
  PlannerOptions fast = cartesian(25.0, 5000.0);
  fast.cartesian.velocity = 0.5;
  const Plan c = plan_path(q, elkady(), fast);
  EXPECT_FALSE(c.summary().actuators_within_limits);
  EXPECT_GT(peak_forces(c, elkady()).maxCoeff(), 96.0 * 1.05);
  PlannerOptions safe;
  safe.cartesian.jerk = 5000.0;
  const Plan a = plan_path(q, elkady(), safe);
  EXPECT_TRUE(a.summary().actuators_within_limits);
  EXPECT_LE(peak_forces(a, elkady()).maxCoeff(), 96.0 * 1.02);
  // And with the daemon's 5 m/s^2 the Cartesian plan is safe but slower.
  const Plan slow = plan_path(q, elkady(), cartesian(5.0, 5000.0));
  EXPECT_LT(a.duration(), slow.duration());
}

TEST(Planner, ReferenceIsSmoothAcrossPiecesAndKnots) {
  // v = dp/dt and a = dv/dt everywhere, also where a blend meets a line or
  // an arc and between knots: no step in the speed a controller would chase.
  PathQueue q(kCentre + Vec3(-0.1, -0.05, 0), 5e-5);
  q.line(kCentre + Vec3(0.05, -0.05, 0), 0.2);
  q.arc(kCentre + Vec3(0.05, 0.05, 0), kCentre + Vec3(0.05, 0, 0), Vec3::UnitZ(), 1, 0.2);  // a tangent half circle
  q.line(kCentre + Vec3(-0.1, 0.05, 0.02), 0.2);
  q.line(kCentre + Vec3(-0.1, -0.05, 0), 0.2);  // corners: blends
  const Plan p = plan_path(q, elkady(), PlannerOptions{});
  const double h = 1e-6;
  for (double t = 2e-3; t < p.duration() - 2e-3; t += 1.3e-4) {
    const ctl::TrajectorySample s = p.sample(t), a = p.sample(t + h), b = p.sample(t - h);
    EXPECT_LT((s.v - (a.p - b.p) / (2 * h)).norm(), 1e-6) << "t = " << t;
    EXPECT_LT((s.a - (a.v - b.v) / (2 * h)).norm(), 2e-2) << "t = " << t;
  }
}

TEST(Planner, DwellsAndStopsHoldThePlatformAtRest) {
  PathQueue q(kCentre, 0.0);
  q.line(kCentre + Vec3(0.05, 0, 0), 0.1);
  q.dwell(0.5);
  q.line(kCentre + Vec3(0.05, 0.05, 0), 0.1);  // a corner without tolerance: a stop
  const Plan p = plan_path(q, elkady(), PlannerOptions{});
  double at_rest = 0.0;
  for (double t = 0.01; t < p.duration() - 0.01; t += 1e-4) {
    const ctl::TrajectorySample s = p.sample(t);
    if ((s.p - (kCentre + Vec3(0.05, 0, 0))).norm() < 1e-9 && s.v.norm() < 1e-9) at_rest += 1e-4;
  }
  EXPECT_NEAR(at_rest, 0.5, 2e-3);
}

TEST(Planner, RefusesBadOptionsAndPathsOutsideTheWorkspace) {
  PlannerOptions o;
  o.cartesian.jerk = 0.0;
  EXPECT_THROW(plan_path(square(0.1, 0.1, 0.0), elkady(), o), Error);
  PathQueue out(kCentre);
  out.line(kCentre + Vec3(0.3, 0, 0), 0.1);  // beyond the x stroke
  for (PlanMode mode : {PlanMode::actuator_aware, PlanMode::cartesian_only}) {
    PlannerOptions m;
    m.mode = mode;
    EXPECT_THROW(plan_path(out, elkady(), m), Error);
  }
}

TEST(Planner, SaysWhereTheFeedIsLimited) {
  const Plan p = plan_path(square(0.2, 0.3, 1e-4), elkady(), PlannerOptions{});
  ASSERT_GE(p.summary().limited.size(), 5u);  // the start, three corners, the end
  EXPECT_EQ(p.summary().limited.front().by, Limit::stop);
  EXPECT_EQ(p.summary().limited.back().by, Limit::stop);
  for (std::size_t k = 1; k + 1 < p.summary().limited.size(); ++k) {
    const LimitedStretch& l = p.summary().limited[k];
    EXPECT_EQ(l.by, Limit::actuator_force);
    EXPECT_LT(l.speed, 0.3);
    EXPECT_NEAR(l.feed, 0.3, 1e-12);
  }
}

}  // namespace
}  // namespace cpm::path::test
