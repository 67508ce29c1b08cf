// SPDX-License-Identifier: Apache-2.0
// Sampling a prepared plan in the real-time cycle (plan.hpp).
#include "cpm/path/plan.hpp"

#include <algorithm>
#include <cmath>

#include "internal.hpp"

namespace cpm::path {

Plan::Plan(Geometry geometry, std::vector<Knot> knots, double knot_period, PlanSummary summary)
    : geometry_(std::move(geometry)), knots_(std::move(knots)), dt_(knot_period), summary_(std::move(summary)) {
  if (geometry_.pieces.empty() || knots_.size() < 2 || !(dt_ > 0.0)) throw Error("path: an empty plan");
  duration_ = summary_.duration > 0.0 ? summary_.duration : dt_ * static_cast<double>(knots_.size() - 1);
}

PathSample Plan::sample_path(double t, SampleCost* cost) const noexcept {
  return detail::sample(geometry_, knots_, dt_, t, cost);
}

PathSample detail::sample(const Geometry& g, const std::vector<Knot>& knots, double dt, double t,
                          SampleCost* cost) noexcept {
  double s = knots.back().s, sd = 0.0, sdd = 0.0;
  int lo = knots.back().piece, hi = lo;
  const double x = std::max(t, 0.0) / dt;
  if (x < static_cast<double>(knots.size() - 1)) {
    const auto k = static_cast<std::size_t>(x);
    const Knot &a = knots[k], &b = knots[k + 1];
    detail::quintic_hermite({a.s, a.v, a.a, b.s, b.v, b.a}, dt, x - static_cast<double>(k), s, sd, sdd);
    lo = knots[k].piece;
    hi = knots[k + 1].piece;
  }
  int steps = 0;
  const int j = g.find(s, lo, hi, &steps);
  const Piece& pc = g.pieces[static_cast<std::size_t>(j)];
  const PathPoint pp = pc.at(std::clamp(s - pc.s0, 0.0, pc.length));
  if (cost) {
    cost->search_steps += steps;
    cost->pieces_evaluated += 1;
  }
  PathSample out;
  out.ref.p = pp.p;
  out.ref.v = pp.d1 * sd;
  out.ref.a = pp.d1 * sdd + pp.d2 * (sd * sd);
  out.s = s;
  out.s_dot = sd;
  out.piece = j;
  out.segment = pc.segment;
  return out;
}

}  // namespace cpm::path
