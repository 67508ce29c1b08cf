// Sampling a prepared plan in the real-time cycle (plan.hpp).
#include "cpm/path/plan.hpp"

#include <algorithm>
#include <cmath>

#include "internal.hpp"

namespace cpm::path {
namespace {

// Quintic Hermite interpolation of s over one knot interval of length h at
// tau in [0, 1]: matches s, s_dot and s_dd at both knots.
void hermite(const Knot& k0, const Knot& k1, double h, double tau, double& s, double& v, double& a) noexcept {
  const double t2 = tau * tau, t3 = t2 * tau, t4 = t3 * tau, t5 = t4 * tau;
  const double y[6] = {k0.s, h * k0.v, h * h * k0.a, h * h * k1.a, h * k1.v, k1.s};
  const double H[6] = {1 - 10 * t3 + 15 * t4 - 6 * t5, tau - 6 * t3 + 8 * t4 - 3 * t5,
                       0.5 * (t2 - 3 * t3 + 3 * t4 - t5), 0.5 * (t3 - 2 * t4 + t5),
                       -4 * t3 + 7 * t4 - 3 * t5, 10 * t3 - 15 * t4 + 6 * t5};
  const double D[6] = {-30 * t2 + 60 * t3 - 30 * t4, 1 - 18 * t2 + 32 * t3 - 15 * t4,
                       0.5 * (2 * tau - 9 * t2 + 12 * t3 - 5 * t4), 0.5 * (3 * t2 - 8 * t3 + 5 * t4),
                       -12 * t2 + 28 * t3 - 15 * t4, 30 * t2 - 60 * t3 + 30 * t4};
  const double DD[6] = {-60 * tau + 180 * t2 - 120 * t3, -36 * tau + 96 * t2 - 60 * t3,
                        0.5 * (2 - 18 * tau + 36 * t2 - 20 * t3), 0.5 * (6 * tau - 24 * t2 + 20 * t3),
                        -24 * tau + 84 * t2 - 60 * t3, 60 * tau - 180 * t2 + 120 * t3};
  s = v = a = 0.0;
  for (int i = 0; i < 6; ++i) {
    s += H[i] * y[i];
    v += D[i] * y[i];
    a += DD[i] * y[i];
  }
  v /= h;
  a /= h * h;
}

}  // namespace

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
    hermite(knots[k], knots[k + 1], dt, x - static_cast<double>(k), s, sd, sdd);
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
