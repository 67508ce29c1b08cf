// SPDX-License-Identifier: Apache-2.0
// The plant's actuation delay (docs/effects.md, actuation_delay): the command
// given at t_k acts over [t_k + tau, t_k+1 + tau).
#include <gtest/gtest.h>

#include <cmath>
#include <vector>

#include "cpm/sim/plant.hpp"

namespace cpm::sim {
namespace {

constexpr double kT = 1e-3;  // control period (s)

ctl::MachineModel with_delay(ctl::MachineModel mm, double tau) {
  ctl::add_effect(mm, "actuation_delay", -1, {tau});
  return mm;
}

// A command sequence that moves every axis both ways, around the force
// that holds the platform against gravity (F_z = -E at rest).
std::vector<Vec3> commands(const Machine& m, int n) {
  std::vector<Vec3> u;
  for (int k = 0; k < n; ++k) {
    const double s = k * kT;
    u.emplace_back(20.0 * std::sin(2 * M_PI * 3 * s), -15.0 * std::cos(2 * M_PI * 5 * s),
                   -m.inertia().E + 10.0 * std::sin(2 * M_PI * 7 * s + 0.3));
  }
  return u;
}

TEST(PlantDelay, ZeroDelayIsThePlainZeroOrderHoldBitForBit) {
  // The plant before the delay existed: classical RK4, 10 equal sub-steps,
  // the command held over the period. Written out here from that definition,
  // on the plant's own forward dynamics.
  const Machine truth(ctl::MachineModel::elkady());
  const Machine truth0(with_delay(ctl::MachineModel::elkady(), 0.0));
  Plant plant(truth, PlantOptions{}), plant0(truth0, PlantOptions{});
  const Vec3 start(0.45, 0.4, 0.35);
  ASSERT_TRUE(plant.reset(start));
  ASSERT_TRUE(plant0.reset(start));
  Vec3 p = start, v = Vec3::Zero();
  const auto u = commands(truth, 300);
  for (const Vec3& f : u) {
    const double h = kT / 10;
    for (int i = 0; i < 10; ++i) {
      Vec3 a1, a2, a3, a4;
      ASSERT_TRUE(plant.acceleration(p, v, f, a1));
      const Vec3 v1 = v, v2 = v + 0.5 * h * a1;
      ASSERT_TRUE(plant.acceleration(p + 0.5 * h * v1, v2, f, a2));
      const Vec3 v3 = v + 0.5 * h * a2;
      ASSERT_TRUE(plant.acceleration(p + 0.5 * h * v2, v3, f, a3));
      const Vec3 v4 = v + h * a3;
      ASSERT_TRUE(plant.acceleration(p + h * v3, v4, f, a4));
      p += h / 6.0 * (v1 + 2.0 * v2 + 2.0 * v3 + v4);
      v += h / 6.0 * (a1 + 2.0 * a2 + 2.0 * a3 + a4);
    }
    ASSERT_TRUE(plant.step(f, kT));
    ASSERT_TRUE(plant0.step(f, kT));
    for (int i = 0; i < 3; ++i) {
      ASSERT_EQ(plant.position()[i], p[i]);
      ASSERT_EQ(plant.velocity()[i], v[i]);
      ASSERT_EQ(plant0.position()[i], p[i]);  // an explicit tau = 0 is no delay
      ASSERT_EQ(plant0.velocity()[i], v[i]);
    }
  }
}

TEST(PlantDelay, AnIntegerDelayIsTheCommandSequenceShifted) {
  // n periods of delay = the undelayed plant fed u_{k-n}, with the reset's
  // force before the first command.
  const Machine undelayed(ctl::MachineModel::elkady());
  const auto u = commands(undelayed, 400);
  const Vec3 before(1.0, -2.0, -undelayed.inertia().E);  // holding z against gravity
  for (int n : {1, 2, 5}) {
    const Machine truth(with_delay(ctl::MachineModel::elkady(), n * kT));
    Plant delayed(truth, PlantOptions{}), shifted(undelayed, PlantOptions{});
    const Vec3 start(0.5, 0.4, 0.35);
    ASSERT_TRUE(delayed.reset(start, Vec3::Zero(), before));
    ASSERT_TRUE(shifted.reset(start));
    double worst = 0.0;
    for (int k = 0; k < static_cast<int>(u.size()); ++k) {
      ASSERT_TRUE(delayed.step(u[static_cast<std::size_t>(k)], kT));
      ASSERT_TRUE(shifted.step(k >= n ? u[static_cast<std::size_t>(k - n)] : before, kT));
      worst = std::max(worst, (delayed.position() - shifted.position()).norm() +
                                  kT * (delayed.velocity() - shifted.velocity()).norm());
    }
    EXPECT_LT(worst, 1e-13) << n << " periods";
  }
}

// A machine whose dynamics is m q_dd = F + (0, 0, E): massless limbs
// (B = C = 0), so M = (m3 + m4) I and only the weight E = (m3 + m4) g
// remains. Under piecewise-constant force the motion is piecewise
// quadratic, which RK4 integrates exactly: any mismatch is the switching.
TEST(PlantDelay, AFractionalDelaySwitchesTheForceInsideThePeriodClosedForm) {
  for (double periods : {0.37, 1.5, 2.93}) {
    ctl::MachineModel mm = ctl::MachineModel::elkady();
    mm.masses.m1 = 0.0;
    mm.masses.m2 = 0.0;
    const double mass = mm.masses.m3 + mm.masses.m4;
    const double tau = periods * kT;
    const Machine truth(with_delay(mm, tau));
    Plant plant(truth, PlantOptions{});
    const Vec3 start(0.45, 0.4, 0.35);
    const Vec3 before(0.5, -0.5, 0.0);
    ASSERT_TRUE(plant.reset(start, Vec3::Zero(), before));
    // Force steps on every axis: each command held one period.
    std::vector<Vec3> u;
    for (int k = 0; k < 40; ++k) u.emplace_back(((k / 3) % 2 ? 1.0 : -1.0) * (0.2 + 0.01 * k), 0.3 * ((k % 5) - 2),
                                                -mass * ctl::kGravity + 0.1 * ((k % 4) - 1.5));
    // Closed form: over [t_k, t_k+1) the force is F_{k-n-1} until t_k + a T,
    // then F_{k-n}, with tau = (n + a) T; a piece of length L under F moves
    // the state by v L + F L^2 / 2m, v += F L / m (plus gravity on z).
    const int n = static_cast<int>(std::floor(periods));
    const double a = periods - n;
    auto command = [&](int j) { return j < 0 ? before : u[static_cast<std::size_t>(j)]; };
    const Vec3 g(0, 0, ctl::kGravity);
    Vec3 x = start, v = Vec3::Zero();
    double worst_x = 0.0, worst_v = 0.0;
    for (int k = 0; k < static_cast<int>(u.size()); ++k) {
      for (const auto& [F, L] : {std::pair{command(k - n - 1), a * kT}, std::pair{command(k - n), (1 - a) * kT}}) {
        const Vec3 acc = F / mass + g;
        x += v * L + 0.5 * acc * L * L;
        v += acc * L;
      }
      ASSERT_TRUE(plant.step(u[static_cast<std::size_t>(k)], kT));
      worst_x = std::max(worst_x, (plant.position() - x).norm());
      worst_v = std::max(worst_v, (plant.velocity() - v).norm());
    }
    // The motion is millimetres and mm/s: these are rounding, not modelling.
    EXPECT_LT(worst_x, 1e-14) << periods << " periods";
    EXPECT_LT(worst_v, 1e-12) << periods << " periods";
    // And the delay shows: without it the velocity would differ by far more
    // (the last command alone, held a T sooner, changes it by F a T / m).
    Vec3 v0 = Vec3::Zero();
    for (const Vec3& F : u) v0 += (F / mass + g) * kT;
    EXPECT_GT((plant.velocity() - v0).norm(), 1e-5) << periods << " periods";
  }
}

TEST(PlantDelay, AHistoryTooShortForTheDelayIsAStatusNotACrash) {
  // 0.05 s at 50 kHz is 2500 periods: more than the history keeps.
  const Machine truth(with_delay(ctl::MachineModel::elkady(), 0.05));
  Plant plant(truth, PlantOptions{});
  ASSERT_TRUE(plant.reset(Vec3(0.5, 0.4, 0.35)));
  const Vec3 hold(0, 0, -truth.inertia().E);
  Status s;
  for (int k = 0; k < 3000 && s.ok(); ++k) s = plant.step(hold, 2e-5);
  EXPECT_EQ(s.fault, Fault::history_short) << describe(s);
  EXPECT_THROW(ctl::check_delay_fits(0.05, 50000.0), Error);
  EXPECT_NO_THROW(ctl::check_delay_fits(0.05, 10000.0));
}

}  // namespace
}  // namespace cpm::sim
