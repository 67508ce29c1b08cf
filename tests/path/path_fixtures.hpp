// SPDX-License-Identifier: Apache-2.0
// What the path tests share: the machine, a few paths, and an independent
// check of a plan's actuator forces through the model's inverse dynamics.
#pragma once

#include <gtest/gtest.h>

#include "cpm/path/planner.hpp"

namespace cpm::path::test {

inline const Vec3 kCentre(0.425, 0.425, 0.300);  // middle of the workspace (m)

inline const ctl::Machine& elkady() {
  static const ctl::Machine m(ctl::MachineModel::elkady());
  return m;
}

// A square of side `side` (m) in the XY plane around kCentre, from its
// lower-left corner counter-clockwise, at `feed` (m/s).
inline PathQueue square(double side, double feed, double tolerance) {
  const double h = side / 2;
  PathQueue q(kCentre + Vec3(-h, -h, 0), tolerance);
  q.line(kCentre + Vec3(h, -h, 0), feed);
  q.line(kCentre + Vec3(h, h, 0), feed);
  q.line(kCentre + Vec3(-h, h, 0), feed);
  q.line(kCentre + Vec3(-h, -h, 0), feed);
  return q;
}

// The largest actuator command (N) of a plan over samples every dt, each
// computed here from the model (the planner checks its knots, 1 ms apart,
// to 0.5 %; between them and with the grid's resolution the tests allow 2 %
// over the planned bound, which the force reserve keeps far below the
// drives' limit): F = M a + G v + K (Machine::inverse_dynamics),
// F_d = J^T F + effects(d, d_dot), command = F_d / drive gain.
inline Vec3 peak_forces(const Plan& plan, const ctl::Machine& m, double dt = 2.5e-4) {
  Vec3 peak = Vec3::Zero();
  const kin::KinematicInputs in{};
  for (double t = 0.0; t <= plan.duration(); t += dt) {
    const ctl::TrajectorySample s = plan.sample(t);
    Vec3 d, F;
    Mat3 J_inv;
    EXPECT_TRUE(kin::inverse(m.kinematics(), s.p, in, d, &J_inv).ok());
    EXPECT_TRUE(m.inverse_dynamics(s.p, s.v, s.a, F).ok());
    const Mat3 J = J_inv.inverse();
    const Vec3 cmd = (J.transpose() * F + m.effect_forces(d, J_inv * s.v)).cwiseQuotient(m.drive_gain());
    peak = peak.cwiseMax(cmd.cwiseAbs());
  }
  return peak;
}

}  // namespace cpm::path::test
