// SPDX-License-Identifier: Apache-2.0
// The plan as the cycle will sample it, checked at every knot against the
// limits with the machine's own inverse kinematics and inverse dynamics.
#include <algorithm>
#include <cmath>

#include "grid.hpp"
#include "internal.hpp"

namespace cpm::path::detail {
namespace {

constexpr double kSlack = 0.005;  // the grid bounds the limits between its points only to about this
constexpr std::size_t kKeep = 4096;  // violations kept (all are counted in the figures)

struct Checker {
  const ctl::Machine& m;
  const PlannerOptions& o;
  PlanSummary& sum;
  std::vector<Violation>& out;
  double t = 0.0, s = 0.0;

  void over(Limit by, int axis, double value, double limit, bool counts = true) {
    if (std::abs(value) <= limit * (1.0 + kSlack) + 1e-12) return;
    if (by == Limit::actuator_force || by == Limit::actuator_velocity || by == Limit::actuator_acceleration)
      sum.actuators_within_limits = false;
    if (counts && out.size() < kKeep) out.push_back(Violation{t, s, by, axis, value, limit});
  }

  void actuators(const PathSample& ps) {
    const kin::KinematicInputs in{};
    Vec3 d, F;
    Mat3 J_inv, J;
    // The limbs' reach and singularity come with the dynamics, the strokes with d.
    if (!kin::inverse(m.kinematics(), ps.ref.p, in, d, &J_inv) || !kin::check_strokes(m.model().strokes, d) ||
        !m.jacobian(d, ps.ref.p, in, J) || !m.inverse_dynamics(ps.ref.p, ps.ref.v, ps.ref.a, F)) {
      if (out.size() < kKeep) out.push_back(Violation{t, s, Limit::none, -1, 0.0, 0.0});
      return;
    }
    const Vec3 d_dot = J_inv * ps.ref.v, d_dd = J_inv * ps.ref.a;  // the dJ^-1/dt term is left out
    const Vec3 cmd = (J.transpose() * F + m.effect_forces(d, d_dot)).cwiseQuotient(m.drive_gain());
    sum.peak_actuator_speed = sum.peak_actuator_speed.cwiseMax(d_dot.cwiseAbs());
    sum.peak_actuator_acceleration = sum.peak_actuator_acceleration.cwiseMax(d_dd.cwiseAbs());
    sum.peak_actuator_force = sum.peak_actuator_force.cwiseMax(cmd.cwiseAbs());
    const bool counts = o.mode == PlanMode::actuator_aware;
    const ActuatorLimits& L = o.actuators;
    for (int i = 0; i < 3; ++i) {
      over(Limit::actuator_velocity, i, d_dot[i], L.velocity[i], counts);
      over(Limit::actuator_acceleration, i, d_dd[i], L.acceleration[i], counts);
      over(Limit::actuator_force, i, cmd[i], (1.0 - L.force_reserve) * L.force[i], counts);
    }
  }

  void at(const Geometry& g, const std::vector<Knot>& knots, double time) {
    t = time;
    const PathSample ps = detail::sample(g, knots, o.knot_period, t, nullptr);
    s = ps.s;
    const double speed = ps.ref.v.norm(), acc = ps.ref.a.norm();
    sum.peak_speed = std::max(sum.peak_speed, speed);
    sum.peak_acceleration = std::max(sum.peak_acceleration, acc);
    const Piece& pc = g.pieces[static_cast<std::size_t>(ps.piece)];
    over(Limit::velocity, -1, speed, o.cartesian.velocity);
    if (pc.feed > 0.0) over(Limit::feed, -1, speed, pc.feed);
    if (o.mode == PlanMode::cartesian_only) over(Limit::acceleration, -1, acc, o.cartesian.acceleration);
    actuators(ps);
  }
};

}  // namespace

std::vector<Violation> check(const Geometry& g, const std::vector<Knot>& knots, const ctl::Machine& m,
                             const PlannerOptions& o, PlanSummary& sum) {
  std::vector<Violation> out;
  Checker c{m, o, sum, out};
  const double dt = o.knot_period;
  std::size_t last = 0;
  for (std::size_t k = 0; k < knots.size(); ++k) {
    // Every knot while the acceleration changes, else every half grid step
    // of path or every eighth knot (cruise, where only the pose changes).
    const bool changing = std::abs(knots[k].a - knots[last].a) > 0.05 || std::abs(knots[k].v - knots[last].v) > 1e-3;
    if (k == 0 || k + 1 == knots.size() || changing || k - last >= 8 || knots[k].s - knots[last].s >= 0.5 * o.grid_step) {
      c.at(g, knots, static_cast<double>(k) * dt);
      last = k;
    }
    if (k + 1 < knots.size()) sum.peak_jerk = std::max(sum.peak_jerk, std::abs(knots[k + 1].a - knots[k].a) / dt);
  }
  return out;
}

}  // namespace cpm::path::detail
