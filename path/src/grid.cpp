// SPDX-License-Identifier: Apache-2.0
// The planner's grid: each limit at each point as a bound on u given x.
#include "grid.hpp"

#include <algorithm>
#include <cmath>
#include <numbers>

namespace cpm::path::detail {
namespace {

constexpr double kSlope = 1e-5;  // m: step of the finite difference of J^-1 along s

int intervals_of(const Piece& pc, double step) {
  int n = std::max(1, static_cast<int>(std::ceil(pc.length / step - 1e-9)));
  if (pc.kind == PieceKind::arc)  // at least every 5 degrees: the Jacobian and M turn with the arc
    n = std::max(n, static_cast<int>(std::ceil(std::abs(pc.angle1 - pc.angle0) / (std::numbers::pi / 36))));
  if (pc.kind == PieceKind::blend) n = std::max(n, 6);  // its curvature rises and falls within it
  return n;
}

[[noreturn]] void refuse(const Geometry& g, const Point& pt, const std::string& why) {
  throw Error("path: at " + g.where(pt.s) + ": " + why);
}

// Bound on |effects(d, d_dot)| per actuator for speeds up to v_max along
// the path: friction grows with speed (viscous) or peaks just above rest
// (Coulomb, Stribeck); cogging and springs do not depend on it.
Vec3 effects_bound(const ctl::Machine& m, const Vec3& d, const Vec3& d1, double v_max) {
  if (!m.has_additive_effects()) return Vec3::Zero();
  Vec3 e = m.effect_forces(d, Vec3::Zero()).cwiseAbs();
  for (double v : {1e-4, 1e-2 * v_max, 0.1 * v_max, v_max})
    for (double sign : {-1.0, 1.0}) e = e.cwiseMax(m.effect_forces(d, sign * v * d1).cwiseAbs());
  return e;
}

// d and J^-1 at p (throws outside the strokes; the limbs' reach and
// singularity are checked with the dynamics).
Mat3 inverse_jacobian_at(const ctl::Machine& m, const Vec3& p, Vec3& d, const Geometry& g, const Point& pt) {
  const kin::KinematicInputs in{};
  Mat3 J_inv;
  if (Status s = kin::inverse(m.kinematics(), p, in, d, &J_inv); !s) refuse(g, pt, describe(s));
  if (Status s = kin::check_strokes(m.model().strokes, d); !s) refuse(g, pt, describe(s));
  return J_inv;
}

void actuator_rows(Point& pt, const PathPoint& pp, const Geometry& g, const ctl::Machine& m,
                   const ActuatorLimits& lim) {
  const Piece& pc = g.pieces[static_cast<std::size_t>(pt.piece)];
  const double sl = pt.s - pc.s0;
  Vec3 d, dn;
  const Mat3 J_inv = inverse_jacobian_at(m, pp.p, d, g, pt);
  Vec3 d2 = J_inv * pp.d2;
  if (!m.has_constant_jacobian()) {  // d'' = J^-1 p'' + (dJ^-1/ds) p'
    const Mat3 Jp = inverse_jacobian_at(m, pc.at(sl + kSlope).p, dn, g, pt);
    const Mat3 Jm = inverse_jacobian_at(m, pc.at(sl - kSlope).p, dn, g, pt);
    d2 += (Jp - Jm) / (2.0 * kSlope) * pp.d1;
  }
  const Vec3 d1 = J_inv * pp.d1;
  for (int i = 0; i < 3; ++i)
    if (std::abs(d1[i]) > 1e-12 && (lim.velocity[i] * lim.velocity[i]) / (d1[i] * d1[i]) < pt.cap) {
      pt.cap = (lim.velocity[i] * lim.velocity[i]) / (d1[i] * d1[i]);
      pt.cap_by = Limit::actuator_velocity;
      pt.cap_axis = i;
    }
  ctl::RigidBodyTerms t;
  if (Status s = m.rigid_body(pp.p, pp.d1, t); !s) refuse(g, pt, describe(s));
  Mat3 J;
  if (Status s = m.jacobian(d, pp.p, kin::KinematicInputs{}, J); !s) refuse(g, pt, describe(s));
  const Vec3 a = J.transpose() * (t.M * pp.d1), b = J.transpose() * (t.M * pp.d2 + t.Gv), c = J.transpose() * t.K;
  const Vec3 e = effects_bound(m, d, d1, std::sqrt(pt.cap));
  for (int i = 0; i < 3; ++i) {
    const double g_i = m.drive_gain()[i], bound = (1.0 - lim.force_reserve) * lim.force[i] * g_i - e[i];
    pt.rows[static_cast<std::size_t>(i)] = Row{a[i], b[i], c[i], -bound, bound, Limit::actuator_force, i};
    pt.rows[static_cast<std::size_t>(3 + i)] =
        Row{d1[i], d2[i], 0.0, -lim.acceleration[i], lim.acceleration[i], Limit::actuator_acceleration, i};
  }
  pt.nrows = 6;
}

Point make_point(const Geometry& g, int piece, double sl, const ctl::Machine& m, const PlannerOptions& o) {
  const Piece& pc = g.pieces[static_cast<std::size_t>(piece)];
  Point pt;
  pt.piece = piece;
  pt.s = pc.s0 + sl;
  const PathPoint pp = pc.at(sl);
  const double n1 = pp.d1.squaredNorm();
  const double V = o.cartesian.velocity;
  const bool fed = pc.feed > 0.0 && pc.feed < V;
  pt.speed = std::sqrt(n1);
  pt.feed = fed ? pc.feed : V;
  pt.rapid = pc.feed <= 0.0;
  pt.cap = pt.feed * pt.feed / n1;
  pt.cap_by = fed ? Limit::feed : Limit::velocity;
  if (o.mode == PlanMode::cartesian_only) {
    pt.q11 = n1;
    pt.q12 = pp.d1.dot(pp.d2);
    pt.q22 = pp.d2.squaredNorm();
    pt.A2 = o.cartesian.acceleration * o.cartesian.acceleration;
    const kin::KinematicInputs in{};
    if (Status s = kin::check_pose(m.kinematics(), m.model().strokes, pp.p, in); !s) refuse(g, pt, describe(s));
  } else {
    actuator_rows(pt, pp, g, m, o.actuators);
  }
  return pt;
}

// Curvature vector (1/m) of a piece at s.
Vec3 curvature(const Piece& pc, double s) {
  const PathPoint pp = pc.at(s);
  const double n2 = pp.d1.squaredNorm();
  const Vec3 t = pp.d1 / std::sqrt(n2);
  return (pp.d2 - pp.d2.dot(t) * t) / n2;
}

// Stops at rest, and the speed cap where the curvature jumps between pieces.
void junction_caps(Grid& grid, const Geometry& g, const PlannerOptions& o) {
  std::size_t stop = 0;
  for (std::size_t i = 0; i < grid.pts.size(); ++i) {
    Point& pt = grid.pts[i];
    while (stop < g.stops.size() && g.stops[stop].s < pt.s - 1e-12) ++stop;
    if (stop < g.stops.size() && std::abs(g.stops[stop].s - pt.s) <= 1e-12) {
      pt.stop = true;
      pt.cap = 0.0;
      pt.cap_by = Limit::stop;
      continue;
    }
    if (i + 1 < grid.pts.size() && grid.pts[i + 1].piece != pt.piece && grid.pts[i + 1].s == pt.s) {
      const Piece &a = g.pieces[static_cast<std::size_t>(pt.piece)], &b = g.pieces[static_cast<std::size_t>(pt.piece + 1)];
      const double dk = (curvature(a, a.length) - curvature(b, 0.0)).norm();
      const double cap = dk > 1e-9 ? o.cartesian.acceleration_step / dk : 1e300;
      for (Point* q : {&pt, &grid.pts[i + 1]})
        if (cap < q->cap) q->cap = cap, q->cap_by = Limit::curvature_step;
    }
  }
}

}  // namespace

Grid build_grid(const Geometry& g, const ctl::Machine& m, const PlannerOptions& o) {
  Grid grid;
  grid.geometry = &g;
  std::size_t count = 0;
  for (const Piece& pc : g.pieces) count += static_cast<std::size_t>(intervals_of(pc, o.grid_step)) + 1;
  grid.pts.reserve(count);
  for (std::size_t k = 0; k < g.pieces.size(); ++k) {
    const Piece& pc = g.pieces[k];
    const int n = intervals_of(pc, o.grid_step);
    for (int j = 0; j <= n; ++j)
      grid.pts.push_back(make_point(g, static_cast<int>(k), pc.length * j / n, m, o));
  }
  junction_caps(grid, g, o);
  return grid;
}

bool interval(const Point& p, double x, double& lo, double& hi, Binding* why) noexcept {
  lo = -p.u_cap;
  hi = p.u_cap;
  Binding w;
  for (int k = 0; k < p.nrows; ++k) {
    const Row& r = p.rows[static_cast<std::size_t>(k)];
    // Repairs shrink the bounds toward c, the force at rest, which stays inside.
    const double rlo = r.c + (r.lo - r.c) * p.scale, rhi = r.c + (r.hi - r.c) * p.scale;
    const double v = r.b * x + r.c;
    if (std::abs(r.a) < 1e-12) {
      if (v >= rlo && v <= rhi) continue;
      if (why) *why = Binding{r.by, r.axis, r.by, r.axis};
      return false;
    }
    double ul = (rlo - v) / r.a, uh = (rhi - v) / r.a;
    if (r.a < 0.0) std::swap(ul, uh);
    if (ul > lo) lo = ul, w.lo_by = r.by, w.lo_axis = r.axis;
    if (uh < hi) hi = uh, w.hi_by = r.by, w.hi_axis = r.axis;
  }
  if (p.A2 > 0.0) {  // q11 u^2 + 2 q12 x u + q22 x^2 <= A^2
    const double A2 = p.A2 * p.scale * p.scale;
    const double disc = p.q12 * p.q12 * x * x - p.q11 * (p.q22 * x * x - A2);
    if (disc < 0.0) {
      if (why) *why = Binding{Limit::acceleration, -1, Limit::acceleration, -1};
      return false;
    }
    const double r = std::sqrt(disc);
    if ((-p.q12 * x - r) / p.q11 > lo) lo = (-p.q12 * x - r) / p.q11, w.lo_by = Limit::acceleration, w.lo_axis = -1;
    if ((-p.q12 * x + r) / p.q11 < hi) hi = (-p.q12 * x + r) / p.q11, w.hi_by = Limit::acceleration, w.hi_axis = -1;
  }
  if (why) *why = w;
  return lo <= hi;
}

}  // namespace cpm::path::detail
