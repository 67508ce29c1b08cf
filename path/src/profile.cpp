// SPDX-License-Identifier: Apache-2.0
// From the grid's profile to time, and the jerk filter (planner.hpp, step 4).
#include <algorithm>
#include <cmath>
#include <sstream>

#include "grid.hpp"

namespace cpm::path::detail {
namespace {

void push(TimeProfile& tp, double t, double s, double v, double u) {
  tp.t.push_back(t);
  tp.s.push_back(s);
  tp.v.push_back(v);
  tp.u.push_back(u);
  if (tp.q.empty()) {
    tp.q.push_back(0.0);
    return;
  }
  const std::size_t k = tp.t.size() - 2;
  const double h = t - tp.t[k];
  tp.q.push_back(tp.q[k] + tp.s[k] * h + tp.v[k] * h * h / 2.0 + tp.u[k] * h * h * h / 6.0);
}

// s, s_dot and the integral of s at time t; `cur` only moves forward.
struct At {
  double s, v, q;
};
At at(const TimeProfile& tp, double t, std::size_t& cur) {
  if (t <= 0.0) return At{tp.s.front(), 0.0, tp.s.front() * t};
  const std::size_t last = tp.t.size() - 1;
  if (t >= tp.t[last]) return At{tp.s[last], 0.0, tp.q[last] + tp.s[last] * (t - tp.t[last])};
  while (tp.t[cur + 1] <= t) ++cur;
  const double h = t - tp.t[cur];
  return At{tp.s[cur] + tp.v[cur] * h + tp.u[cur] * h * h / 2.0, tp.v[cur] + tp.u[cur] * h,
            tp.q[cur] + tp.s[cur] * h + tp.v[cur] * h * h / 2.0 + tp.u[cur] * h * h * h / 6.0};
}

}  // namespace

TimeProfile to_time(const Grid& grid, const Profile& pr, const std::vector<double>& holds) {
  TimeProfile tp;
  double t = 0.0;
  const std::size_t n = grid.pts.size();
  for (std::size_t i = 0; i < n; ++i) {
    if (holds[i] > 0.0) {
      push(tp, t, grid.pts[i].s, 0.0, 0.0);
      t += holds[i];
    }
    if (i + 1 == n) break;
    const double ds = grid.pts[i + 1].s - grid.pts[i].s;
    if (ds <= 0.0) continue;
    const double v0 = std::sqrt(pr.x[i]), v1 = std::sqrt(pr.x[i + 1]);
    if (v0 + v1 <= 0.0) {
      std::ostringstream o;
      o << "path: the plan cannot move on at " << grid.pts[i].s * 1e3 << " mm along the path";
      throw Error(o.str());
    }
    const double dt = 2.0 * ds / (v0 + v1);
    push(tp, t, grid.pts[i].s, v0, (v1 - v0) / dt);
    t += dt;
  }
  push(tp, t, grid.pts.back().s, 0.0, 0.0);
  return tp;
}

std::vector<Knot> filtered_knots(const TimeProfile& tp, double T, double dt, const Geometry& g) {
  const double end = tp.t.back() + T;
  const auto count = static_cast<std::size_t>(std::ceil(end / dt)) + 1;
  std::vector<Knot> knots(count);
  std::size_t now = 0, before = 0;
  int piece = 0;
  const int last = static_cast<int>(g.pieces.size()) - 1;
  const double L = g.length();
  for (std::size_t k = 0; k < count; ++k) {
    const double t = static_cast<double>(k) * dt;
    const At a = at(tp, t, now), b = at(tp, t - T, before);
    // Moving average of s over [t - T, t]: its rate and acceleration are
    // the differences of s and s_dot across the window.
    Knot& kn = knots[k];
    kn.s = std::clamp((a.q - b.q) / T, 0.0, L);
    kn.v = (a.s - b.s) / T;
    kn.a = (a.v - b.v) / T;
    while (piece < last && g.pieces[static_cast<std::size_t>(piece + 1)].s0 <= kn.s) ++piece;
    kn.piece = piece;
  }
  return knots;
}

}  // namespace cpm::path::detail
