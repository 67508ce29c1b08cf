// SPDX-License-Identifier: Apache-2.0
// The velocity ramp behind jogs, homing moves and the actuator space:
// checked against the closed forms of constant-acceleration motion.
#include <gtest/gtest.h>

#include <cmath>

#include "cpm/daemon/ramp.hpp"

namespace cpm::daemon {
namespace {

constexpr double kDt = 1e-3;

TEST(Ramp, ReachesItsSpeedInVOverATravellingVSquaredOverTwoA) {
  Ramp r;
  r.reset(Vec3::Zero());
  const double v = 0.05, a = 0.5;  // 0.1 s, 2.5 mm
  int n = 0;
  while (r.v.x() < v && n < 10000) {
    r.step(Vec3(v, 0, 0), a, Ramp::unbounded_low(), Ramp::unbounded_high(), kDt);
    ++n;
  }
  EXPECT_EQ(n, 100);
  EXPECT_NEAR(r.p.x(), v * v / (2 * a), 1e-12);
  EXPECT_NEAR(r.a.x(), a, 1e-9);
  EXPECT_EQ(r.p.y(), 0.0);
}

TEST(Ramp, ADiagonalJogKeepsItsDirectionWhileItAccelerates) {
  Ramp r;
  r.reset(Vec3(0.4, 0.4, 0.3));
  const Vec3 target = Vec3(0.03, -0.04, 0.0);  // 50 mm/s
  for (int i = 0; i < 30; ++i) {
    r.step(target, 0.5, Ramp::unbounded_low(), Ramp::unbounded_high(), kDt);
    EXPECT_NEAR(r.v.normalized().dot(target.normalized()), 1.0, 1e-12);
    EXPECT_NEAR(r.a.norm(), 0.5, 1e-9);  // the acceleration bound is on the vector
  }
}

TEST(Ramp, BrakesInTimeForTheBoxAndStopsOnItsEdgeNeverBeyond) {
  Ramp r;
  r.reset(Vec3(0.0, 0.0, 0.0));
  const Vec3 lo = Vec3::Constant(-1.0), hi(0.010, 1.0, 1.0);
  double highest = 0.0, fastest = 0.0;
  for (int i = 0; i < 2000; ++i) {
    r.step(Vec3(0.05, 0, 0), 0.5, lo, hi, kDt);
    highest = std::max(highest, r.p.x());
    fastest = std::max(fastest, r.v.x());
  }
  EXPECT_LE(highest, 0.010);
  EXPECT_NEAR(r.p.x(), 0.010, 1e-5);  // it arrives (within what one period at the last speed covers)
  EXPECT_TRUE(r.at_rest());
  EXPECT_NEAR(fastest, 0.05, 1e-12);  // 10 mm leaves room for the full speed (2.5 mm to stop)
}

TEST(Ramp, StoppingFromSpeedTakesTheClosedFormDistance) {
  Ramp r;
  r.reset(Vec3::Zero());
  for (int i = 0; i < 200; ++i) r.step(Vec3(0, 0.05, 0), 0.5, Ramp::unbounded_low(), Ramp::unbounded_high(), kDt);
  const double from = r.p.y();
  EXPECT_NEAR(r.stopping_distance(2.0), 0.05 * 0.05 / 4.0, 1e-15);
  int n = 0;
  while (!r.at_rest()) {
    r.step(Vec3::Zero(), 2.0, Ramp::unbounded_low(), Ramp::unbounded_high(), kDt);
    ++n;
  }
  EXPECT_EQ(n, 25);                                      // 0.05 / 2 = 25 ms
  EXPECT_NEAR(r.p.y() - from, 0.05 * 0.05 / 4.0, 1e-12);  // v^2 / 2a = 0.625 mm (trapezoidal integration is exact)
}

TEST(Ramp, AMoveToAPlaceArrivesAtRestWithoutOvershoot) {
  for (const double dist : {1e-6, 3e-4, 0.002, 0.037, -0.021}) {
    Ramp r;
    r.reset(Vec3(0.1, 0.2, 0.3));
    const Vec3 target = Vec3(0.1 + dist, 0.2, 0.3);
    double extreme = 0.0;
    int n = 0;
    while (!(r.at_rest() && r.p == target) && n < 100000) {
      r.step_to(target, 0.02, 0.2, kDt);
      extreme = std::max(extreme, (r.p.x() - 0.1) / dist);
      EXPECT_LE(std::abs(r.v.x()), 0.02 + 1e-12);
      ++n;
    }
    EXPECT_EQ(r.p, target) << dist;
    EXPECT_LE(extreme, 1.0 + 1e-9) << "overshoot for " << dist;
    // Within a few periods of the time-optimal trapezoid.
    const double d = std::abs(dist), vmax = 0.02, a = 0.2;
    const double t_opt = d > vmax * vmax / a ? d / vmax + vmax / a : 2.0 * std::sqrt(d / a);
    EXPECT_LE(n * kDt, t_opt + 0.003) << dist;
  }
}

}  // namespace
}  // namespace cpm::daemon
