// SPDX-License-Identifier: Apache-2.0
// The independent generator checked with its own arithmetic (nothing from
// identification/): on noise-free logs the velocity change over one sample
// period is what the true machine's dynamics give for the force that the
// timing convention says was applied over that period (the mean-force
// identity), the delays shift that force by exactly one or one and a half
// samples, the logged force noise has the stated sigma, and the path stays
// inside the strokes while every axis reverses many times.
#include <gtest/gtest.h>

#include <cmath>
#include <functional>

#include "generator.hpp"

namespace cpm::indep {
namespace {

// The force the machine needed over [t_k, t_k+1) by the midpoint rule on the
// true noise-free state: J^T (M(p_mid) J (v_k+1 - v_k) / T + G p_dot + K) + effects.
// Its error against the period's mean applied force is O(T^2) of the motion.
std::vector<Vec3> needed_force(const GeneratedLog& g, const ctl::Machine& truth) {
  const io::MotionData& L = g.log;
  const Mat3 J = truth.constant_jacobian();
  ctl::TaskState ts0;
  EXPECT_TRUE(truth.task_state(Vec3::Zero(), Vec3::Zero(), {}, ts0));
  std::vector<Vec3> out;
  for (std::size_t k = 0; k + 1 < L.t.size(); ++k) {
    const double T = L.t[k + 1] - L.t[k];
    const Vec3 dm = 0.5 * (L.d[k] + L.d[k + 1]), vm = 0.5 * (L.v[k] + L.v[k + 1]);
    ctl::RigidBodyTerms rb;
    EXPECT_TRUE(truth.rigid_body(ts0.p + J * dm, J * vm, rb));
    const Vec3 acc = J * (L.v[k + 1] - L.v[k]) / T;
    Vec3 f = J.transpose() * (rb.M * acc + rb.Gv + rb.K) + truth.effect_forces(dm, vm);
    out.push_back(f.cwiseQuotient(truth.drive_gain()));
  }
  return out;
}

// Largest |needed - hypothesis_k| over the log after the ramp's first samples.
double worst(const std::vector<Vec3>& needed, const std::function<Vec3(std::size_t)>& hyp, std::size_t from) {
  double w = 0.0;
  for (std::size_t k = from; k < needed.size(); ++k) w = std::max(w, (needed[k] - hyp(k)).cwiseAbs().maxCoeff());
  return w;
}

GeneratorSpec quiet(Timing t, double rate = 1000.0) {
  GeneratorSpec s;
  s.timing = t;
  s.rate = rate;
  s.duration = 6.0;
  s.seed = 7;
  s.disturbance_sigma = s.force_noise_sigma = 0.0;
  s.position_noise = s.velocity_noise = 0.0;
  // Smooth effects so the midpoint rule stays at integration precision.
  s.effects = {{"viscous_friction", 0, {3.0}}, {"spring", 1, {150.0, 0.2}}, {"force_gain", 2, {0.05}}};
  return s;
}

TEST(IndependentGenerator, ZohHeldForceGivesTheVelocityChangeOverEachPeriod) {
  const GeneratorSpec s = quiet(Timing::zoh);
  const GeneratedLog g = generate(s);
  const ctl::Machine truth(true_model(s.effects));
  const auto need = needed_force(g, truth);
  const auto& f = g.log.f;
  const double held = worst(need, [&](std::size_t k) { return f[k]; }, 2);
  const double shifted = worst(need, [&](std::size_t k) { return f[k - 1]; }, 2);
  std::printf("zoh: |needed - f_k| <= %.3g N, |needed - f_k-1| <= %.3g N\n", held, shifted);
  EXPECT_LT(held, 1e-4);         // integration and midpoint-rule precision
  EXPECT_GT(shifted, 50 * held); // and the identity tells a one-sample shift apart
  // The generator's own record of the applied force agrees.
  for (std::size_t k = 0; k < g.applied_mean.size(); ++k)
    ASSERT_LT((g.applied_mean[k] - g.commanded[k]).cwiseAbs().maxCoeff(), 1e-12) << k;
}

TEST(IndependentGenerator, RotorInertiaOfTheGeneratorAgreesWithTheMachines) {
  // The generator adds actuator_inertia as diag(m) in actuator coordinates;
  // ctl::Machine as J^-T diag(m) J^-1 in M. The needed force by the Machine's
  // dynamics must match the held force as closely as without it.
  GeneratorSpec s = quiet(Timing::zoh);
  s.effects.push_back({"actuator_inertia", 1, {4.0}});
  const GeneratedLog g = generate(s);
  const ctl::Machine truth(true_model(s.effects));
  const auto need = needed_force(g, truth);
  const double held = worst(need, [&](std::size_t k) { return g.log.f[k]; }, 2);
  ctl::MachineModel without = true_model(s.effects);
  without.effects.clear();
  for (const auto& e : quiet(Timing::zoh).effects) ctl::add_effect(without, e.name, e.axis, e.values);
  const double ignored = worst(needed_force(g, ctl::Machine(without)), [&](std::size_t k) { return g.log.f[k]; }, 2);
  std::printf("zoh with 4 kg on axis 2: |needed - f_k| <= %.3g N; without the rotor in the Machine %.3g N\n", held,
              ignored);
  EXPECT_LT(held, 1e-4);
  EXPECT_GT(ignored, 50 * held);
}

// The forces beyond the library act as stated: on a noise-free zoh log the
// needed force less the held command is c v_j on the cable-carrier axis, the
// bump's Gaussian on its axis and the cubic on its own, each written out here.
TEST(IndependentGenerator, OutsideForcesAreWhatTheyStateOnTheirAxis) {
  GeneratorSpec s = quiet(Timing::zoh);
  s.effects.clear();
  // Centres within the travel the same path covers without them.
  const GeneratedLog g0 = generate(s);
  const double x0 = 0.5 * (g0.d_min[0] + g0.d_max[0]), xc = 0.5 * (g0.d_min[2] + g0.d_max[2]);
  const double half = 0.5 * (g0.d_max[2] - g0.d_min[2]);
  const double c = 4.0, bump = 2.0, w = 0.004, cube = 1.5;
  s.outside = {{OutsideForce::Kind::cross_velocity, 1, 0, c, 0.0, 1.0},
               {OutsideForce::Kind::bump, 0, -1, bump, x0, w},
               {OutsideForce::Kind::cubic, 2, -1, cube, xc, half}};
  const GeneratedLog g = generate(s);
  const ctl::Machine truth(true_model({}));
  const auto need = needed_force(g, truth);
  const auto& L = g.log;
  double worst_left = 0.0, largest = 0.0;
  for (std::size_t k = 2; k < need.size(); ++k) {
    const Vec3 dm = 0.5 * (L.d[k] + L.d[k + 1]), vm = 0.5 * (L.v[k] + L.v[k + 1]);
    const double u0 = (dm[0] - x0) / w, u2 = (dm[2] - xc) / half;
    const Vec3 outside(bump * std::exp(-0.5 * u0 * u0), c * vm[0], cube * u2 * u2 * u2);
    const Vec3 extra = L.f[k] - need[k];  // what the drive spent beyond the rigid body
    worst_left = std::max(worst_left, (extra - outside).cwiseAbs().maxCoeff());
    largest = std::max(largest, outside.cwiseAbs().maxCoeff());
  }
  std::printf("outside forces: largest %.3g N, |f - needed - outside| <= %.3g N\n", largest, worst_left);
  EXPECT_GT(largest, 0.5);
  EXPECT_LT(worst_left, 2e-3);
}

// The humps of a velocity (own on axis 1, axis 2's on axis 3): size at
// |v| = width, odd in v, from the drive's force less the rigid body's.
TEST(IndependentGenerator, VelocityHumpsAreWhatTheyStateOnTheirAxis) {
  GeneratorSpec s = quiet(Timing::zoh);
  s.effects.clear();
  const double own = 1.5, cross = 2.0, w0 = 0.02, w1 = 0.03;
  s.outside = {{OutsideForce::Kind::velocity_hump, 0, -1, own, 0.0, w0},
               {OutsideForce::Kind::cross_velocity_hump, 2, 1, cross, 0.0, w1}};
  const GeneratedLog g = generate(s);
  const ctl::Machine truth(true_model({}));
  const auto need = needed_force(g, truth);
  const auto& L = g.log;
  double worst_left = 0.0;
  Vec3 largest = Vec3::Zero();
  for (std::size_t k = 2; k < need.size(); ++k) {
    const Vec3 vm = 0.5 * (L.v[k] + L.v[k + 1]);
    const double u0 = vm[0] / w0, u1 = vm[1] / w1;
    const Vec3 outside(own * u0 * std::exp(0.5 - 0.5 * u0 * u0), 0.0, cross * u1 * std::exp(0.5 - 0.5 * u1 * u1));
    const Vec3 extra = L.f[k] - need[k];
    worst_left = std::max(worst_left, (extra - outside).cwiseAbs().maxCoeff());
    largest = largest.cwiseMax(outside.cwiseAbs());
  }
  std::printf("velocity humps: largest %.3g, %.3g N, |f - needed - outside| <= %.3g N\n", largest[0], largest[2],
              worst_left);
  // Both humps are crossed at their peaks (the path reaches well beyond w).
  EXPECT_GT(largest[0], 0.95 * own);
  EXPECT_GT(largest[2], 0.95 * cross);
  EXPECT_EQ(largest[1], 0.0);
  EXPECT_LT(worst_left, 2e-3);
}

// The friction map: size (0.65 + 0.35 u) tanh(v / 2 mm/s) on axis 2, u along
// its travel, checked away from the reversals (there the sign turns within a
// period and the mid-period velocity does not stand for it).
TEST(IndependentGenerator, PositionFrictionIsWhatItStatesOnItsAxis) {
  GeneratorSpec s = quiet(Timing::zoh);
  s.effects.clear();
  const GeneratedLog g0 = generate(s);
  const double size = 1.2, centre = 0.5 * (g0.d_min[1] + g0.d_max[1]), width = 0.5 * (g0.d_max[1] - g0.d_min[1]);
  s.outside = {{OutsideForce::Kind::position_friction, 1, -1, size, centre, width}};
  const GeneratedLog g = generate(s);
  const ctl::Machine truth(true_model({}));
  const auto need = needed_force(g, truth);
  const auto& L = g.log;
  double worst_left = 0.0, lowest = 1e9, highest = -1e9;
  for (std::size_t k = 2; k < need.size(); ++k) {
    const Vec3 vm = 0.5 * (L.v[k] + L.v[k + 1]), dm = 0.5 * (L.d[k] + L.d[k + 1]);
    if (std::fabs(vm[1]) < 0.02) continue;
    const double level = size * (0.65 + 0.35 * (dm[1] - centre) / width);
    const Vec3 outside(0.0, level * std::tanh(vm[1] / 2e-3), 0.0);
    worst_left = std::max(worst_left, (L.f[k] - need[k] - outside).cwiseAbs().maxCoeff());
    lowest = std::min(lowest, level);
    highest = std::max(highest, level);
  }
  std::printf("position friction: level %.3f to %.3f N, |f - needed - outside| <= %.3g N\n", lowest, highest,
              worst_left);
  EXPECT_GT(lowest, 0.0);                   // positive everywhere on the path
  EXPECT_GT(highest - lowest, 0.4 * size);  // and rising along it (0.7 size over the null log's stroke)
  EXPECT_LT(worst_left, 2e-3);
}

TEST(IndependentGenerator, Delay1IsZohWithTheAppliedForceShiftedByOneSample) {
  const GeneratorSpec s = quiet(Timing::delay1);
  const GeneratedLog g = generate(s);
  const ctl::Machine truth(true_model(s.effects));
  const auto need = needed_force(g, truth);
  const auto& f = g.log.f;
  const double shifted = worst(need, [&](std::size_t k) { return f[k - 1]; }, 2);
  const double held = worst(need, [&](std::size_t k) { return f[k]; }, 2);
  std::printf("delay1: |needed - f_k-1| <= %.3g N, |needed - f_k| <= %.3g N\n", shifted, held);
  EXPECT_LT(shifted, 1e-4);
  EXPECT_GT(held, 50 * shifted);
  for (std::size_t k = 1; k < g.applied_mean.size(); ++k)
    ASSERT_LT((g.applied_mean[k] - g.commanded[k - 1]).cwiseAbs().maxCoeff(), 1e-12) << k;
}

TEST(IndependentGenerator, Delay1_5SwitchesHalfWayThroughThePeriod) {
  for (double rate : {250.0, 1000.0}) {
    const GeneratorSpec s = quiet(Timing::delay1_5, rate);
    const GeneratedLog g = generate(s);
    const ctl::Machine truth(true_model(s.effects));
    const auto need = needed_force(g, truth);
    const auto& f = g.log.f;
    const double half = worst(need, [&](std::size_t k) { return Vec3(0.5 * (f[k - 2] + f[k - 1])); }, 3);
    const double one = worst(need, [&](std::size_t k) { return f[k - 1]; }, 3);
    std::printf("delay1_5 at %.0f Hz: |needed - (f_k-2 + f_k-1)/2| <= %.3g N, |needed - f_k-1| <= %.3g N\n", rate,
                half, one);
    EXPECT_LT(half, rate < 500 ? 1e-3 : 1e-4);
    EXPECT_GT(one, 10 * half);
  }
}

TEST(IndependentGenerator, SampledForceIsContinuousAndItsPeriodMeanIsTheTrapezoid) {
  const GeneratorSpec s = quiet(Timing::sampled);
  const GeneratedLog g = generate(s);
  const ctl::Machine truth(true_model(s.effects));
  const auto need = needed_force(g, truth);
  const auto& f = g.log.f;
  const double trap = worst(need, [&](std::size_t k) { return Vec3(0.5 * (f[k] + f[k + 1])); }, 2);
  const double held = worst(need, [&](std::size_t k) { return f[k]; }, 2);
  std::printf("sampled: |needed - (f_k + f_k+1)/2| <= %.3g N, |needed - f_k| <= %.3g N\n", trap, held);
  EXPECT_LT(trap, 1e-3);
  EXPECT_GT(held, 5 * trap);
}

TEST(IndependentGenerator, PlantDisturbanceIsHeldOverEachPeriodAndTheLogHoldsTheCleanCommand) {
  GeneratorSpec s = quiet(Timing::zoh);
  s.disturbance_sigma = 0.3;
  const GeneratedLog g = generate(s);
  const ctl::Machine truth(true_model(s.effects));
  const auto need = needed_force(g, truth);
  // The machine felt gain * f_k + w_k: in the drive's units (need is divided by the gain).
  const double with_w = worst(
      need, [&](std::size_t k) { return Vec3(g.log.f[k] + g.disturbance[k].cwiseQuotient(truth.drive_gain())); }, 2);
  const double without = worst(need, [&](std::size_t k) { return g.log.f[k]; }, 2);
  EXPECT_LT(with_w, 1e-4);
  EXPECT_GT(without, 0.3);
  for (std::size_t k = 0; k < g.commanded.size(); ++k) ASSERT_EQ(g.log.f[k], g.commanded[k]);
  double ss = 0.0;
  for (const Vec3& w : g.disturbance) ss += w.squaredNorm();
  EXPECT_NEAR(std::sqrt(ss / (3.0 * static_cast<double>(g.disturbance.size()))), 0.3, 0.02);
}

TEST(IndependentGenerator, CommandNoiseHasTheStatedSigmaOnTheLoggedForce) {
  GeneratorSpec s;
  s.noise = NoisePlacement::command;
  s.duration = 10.0;
  s.seed = 3;
  const GeneratedLog g = generate(s);
  Vec3 sum = Vec3::Zero(), ss = Vec3::Zero();
  const double n = static_cast<double>(g.commanded.size());
  for (std::size_t k = 0; k < g.commanded.size(); ++k) {
    const Vec3 e = g.log.f[k] - g.commanded[k];
    sum += e;
    ss += e.cwiseProduct(e);
  }
  for (int i = 0; i < 3; ++i) {
    const double mean = sum[i] / n, sd = std::sqrt(ss[i] / n - mean * mean);
    EXPECT_NEAR(sd, 0.3, 0.3 * 4.0 / std::sqrt(2.0 * n)) << "axis " << i + 1;  // 4 sigma of the estimate
    EXPECT_NEAR(mean, 0.0, 4.0 * 0.3 / std::sqrt(n)) << "axis " << i + 1;
  }
  // No disturbance entered the plant, and the encoders carry their noise.
  for (const Vec3& w : g.disturbance) ASSERT_EQ(w, Vec3::Zero());
  double sv = 0.0;
  for (std::size_t k = 0; k < g.v_true.size(); ++k) sv += (g.log.v[k] - g.v_true[k]).squaredNorm();
  EXPECT_NEAR(std::sqrt(sv / (3.0 * n)), 2e-4, 2e-4 * 0.05);
}

// The reference alone, over many seeds (the phases vary with the seed): it
// keeps a 40 mm margin to every stroke end and the force limit is far.
TEST(IndependentGenerator, TheExcitationStaysInsideTheStrokesForEverySeed) {
  const Vec3 d0(0.2250, 0.2250, 0.2268), lo(0.04, 0.04, 0.04), hi(0.36, 0.36, 0.26);
  for (std::uint64_t seed = 0; seed < 200; ++seed) {
    const Excitation path(seed);
    Vec3 amax = Vec3::Zero();
    for (int k = 0; k <= 30000; ++k) {
      const Reference r = path(k * 1e-3);
      const Vec3 d = r.p - d0;
      for (int i = 0; i < 3; ++i) {
        ASSERT_GT(d[i], lo[i]) << "seed " << seed << " axis " << i + 1 << " t " << k * 1e-3;
        ASSERT_LT(d[i], hi[i]) << "seed " << seed << " axis " << i + 1 << " t " << k * 1e-3;
      }
      amax = amax.cwiseMax(r.a.cwiseAbs());
    }
    ASSERT_LT(amax.maxCoeff(), 3.0) << "seed " << seed;  // m/s^2: a few kg need well under 120 N
  }
}

TEST(IndependentGenerator, EveryConventionStaysInTheWorkspaceAndReversesEveryAxisOften) {
  for (Timing t : {Timing::sampled, Timing::zoh, Timing::delay1, Timing::delay1_5}) {
    GeneratorSpec s;
    s.timing = t;
    s.rate = 250.0;
    s.seed = 11;
    s.effects = {{"coulomb_friction", 2, {3.0}}, {"payload_mass", -1, {0.5}}};
    const GeneratedLog g = generate(s);
    SCOPED_TRACE(timing_name(t));
    EXPECT_LE(g.max_abs_force, 120.0);
    for (int i = 0; i < 3; ++i) {
      EXPECT_GT(g.d_min[i], 0.03) << "axis " << i + 1;
      EXPECT_LT(g.d_max[i], (i < 2 ? 0.4 : 0.3) - 0.03) << "axis " << i + 1;
      // Reversals with a hysteresis of 5 mm/s, and the speeds they happen between.
      int reversals = 0, sign = 0;
      double vmax = 0.0;
      for (const Vec3& v : g.v_true) {
        vmax = std::max(vmax, std::fabs(v[i]));
        const int sg = v[i] > 5e-3 ? 1 : v[i] < -5e-3 ? -1 : 0;
        if (sg != 0 && sg != sign) {
          if (sign != 0) ++reversals;
          sign = sg;
        }
      }
      EXPECT_GE(reversals, 15) << "axis " << i + 1;
      EXPECT_GT(vmax, 0.15) << "axis " << i + 1;
    }
  }
  // And the excitation starts at rest.
  const Reference r = excitation(0.0, 11);
  EXPECT_EQ(r.v, Vec3::Zero());
  EXPECT_EQ(r.a, Vec3::Zero());
}

}  // namespace
}  // namespace cpm::indep
