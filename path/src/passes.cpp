// SPDX-License-Identifier: Apache-2.0
// Reachability over the grid (planner.hpp, steps 3 and 4).
#include <algorithm>
#include <cmath>
#include <limits>

#include "grid.hpp"

namespace cpm::path::detail {
namespace {

constexpr int kBisections = 48;

// Largest x in [0, hi] with ok(x), ok monotone (true up to some x), ok(0) assumed.
template <class Ok>
double largest(double hi, Ok ok) {
  if (ok(hi)) return hi;
  double lo = 0.0;
  for (int it = 0; it < kBisections && hi - lo > 1e-12 * hi; ++it) {
    const double mid = 0.5 * (lo + hi);
    (ok(mid) ? lo : hi) = mid;
  }
  return lo;
}

// The limit that closes the interval just above x: of the two bounds that
// cross, the one that is not the tangential cap.
void binding(const Point& p, double x, Limit& by, int& axis) {
  double lo, hi;
  Binding w;
  (void)interval(p, x * (1.0 + 1e-6) + 1e-12, lo, hi, &w);
  const bool low = w.lo_by != Limit::tangential;
  by = low ? w.lo_by : w.hi_by;
  axis = low ? w.lo_axis : w.hi_axis;
}

// The largest u in [lo, u] that the interval's end also allows at the
// speed it reaches, x + 2 ds u: accelerating into a tighter bound (a curve
// taken faster) must not end the interval beyond it.
double held_at_end(const Point& end, double x, double ds, double lo, double u) {
  const auto ok = [&](double v) {
    double l, h;
    return interval(end, x + 2.0 * ds * v, l, h) && v >= l - 1e-12 && v <= h + 1e-12;
  };
  if (ok(u) || !ok(lo)) return u;
  double a = lo, b = u;
  for (int it = 0; it < 30; ++it) {
    const double mid = 0.5 * (a + b);
    (ok(mid) ? a : b) = mid;
  }
  return a;
}

}  // namespace

double set_tangential_cap(Grid& grid, const PlannerOptions& o) {
  double available = 0.0, v_feed = 0.0, v_any = 0.0;
  for (Point& p : grid.pts) {
    p.u_cap = std::numeric_limits<double>::infinity();
    double lo = 0.0, hi = 0.0;
    if (o.mode == PlanMode::cartesian_only) available = o.cartesian.acceleration;
    else if (interval(p, 0.0, lo, hi)) available = std::max(available, std::max(hi, -lo));
    v_any = std::max(v_any, p.feed);
    if (!p.rapid) v_feed = std::max(v_feed, p.feed);
  }
  // Slowing for a corner from v and back costs about 2 v / a_t of braking
  // and accelerating plus 3 T = 6 a_t / j of filter (the window, and the
  // cap spread over T on either side): least at a_t = sqrt(v j / 3), v the
  // fastest programmed feed (rapids only when there is nothing else).
  const double v = v_feed > 0.0 ? v_feed : v_any;
  const double a_t = std::min(available, std::sqrt(o.cartesian.jerk * v / 3.0));
  for (Point& p : grid.pts) p.u_cap = a_t;
  return a_t;
}

void max_velocity_curve(Grid& grid) {
  const std::size_t n = grid.pts.size();
  grid.mvc.assign(n, 0.0);
  grid.steady.assign(n, 0.0);
  grid.mvc_by.assign(n, Limit::none);
  grid.mvc_axis.assign(n, -1);
  for (std::size_t i = 0; i < n; ++i) {
    const Point& p = grid.pts[i];
    double lo, hi;
    if (!interval(p, 0.0, lo, hi))
      throw Error("path: at " + grid.geometry->where(p.s) + ": the actuators cannot hold the platform at rest there");
    grid.mvc[i] = largest(p.cap, [&](double x) { return interval(p, x, lo, hi); });
    grid.steady[i] = largest(grid.mvc[i], [&](double x) { return interval(p, x, lo, hi) && lo <= 0.0 && hi >= 0.0; });
    grid.mvc_by[i] = p.cap_by;
    grid.mvc_axis[i] = p.cap_axis;
    if (grid.mvc[i] < p.cap * (1.0 - 1e-9)) binding(p, grid.mvc[i], grid.mvc_by[i], grid.mvc_axis[i]);
  }
}

Profile passes(const Grid& grid, const std::vector<double>& caps) {
  const std::size_t n = grid.pts.size();
  std::vector<double> k(n);
  k[n - 1] = caps[n - 1];
  for (std::size_t i = n - 1; i-- > 0;) {
    const Point& p = grid.pts[i];
    const double ds = grid.pts[i + 1].s - p.s;
    if (ds <= 0.0) {
      k[i] = std::min(caps[i], k[i + 1]);
      continue;
    }
    // Largest x from which the most braking u still lands at or below k[i + 1].
    k[i] = largest(caps[i], [&](double x) {
      double lo, hi;
      return interval(p, x, lo, hi) && x + 2.0 * ds * lo <= k[i + 1] * (1.0 + 1e-12);
    });
  }
  Profile pr;
  pr.x.assign(n, 0.0);
  pr.u.assign(n, 0.0);
  pr.x[0] = std::min(caps[0], k[0]);
  for (std::size_t i = 0; i + 1 < n; ++i) {
    const double ds = grid.pts[i + 1].s - grid.pts[i].s;
    if (ds <= 0.0) {
      pr.x[i + 1] = std::min(pr.x[i], k[i + 1]);
      continue;
    }
    double lo = 0.0, hi = 0.0;
    if (!interval(grid.pts[i], pr.x[i], lo, hi)) lo = hi = 0.0;
    double u = std::max(std::min(hi, (k[i + 1] - pr.x[i]) / (2.0 * ds)), lo);
    u = held_at_end(grid.pts[i + 1], pr.x[i], ds, lo, u);
    pr.x[i + 1] = std::max(0.0, std::min(pr.x[i] + 2.0 * ds * u, k[i + 1]));
    pr.u[i] = (pr.x[i + 1] - pr.x[i]) / (2.0 * ds);
  }
  return pr;
}

std::vector<double> spread_caps(const Grid& grid, double T) {
  // If s_dot <= c on [s_j - T c, s_j + T c], the platform spends at least
  // T on either half, so the filter's window around s_j (T long) lies in it
  // and averages speeds <= c: the filtered speed at s_j keeps the cap c.
  // The cap spread is the steady one: where the filter flattens the speed
  // to c, u is near 0, which the largest feasible x may not allow.
  const std::size_t n = grid.pts.size();
  std::vector<double> caps = grid.mvc;
  for (std::size_t j = 0; j < n; ++j) {
    if (grid.pts[j].stop) continue;  // stops are held for T instead
    const double x = grid.steady[j], reach = T * std::sqrt(x), s = grid.pts[j].s;
    for (std::size_t i = j + 1; i < n && grid.pts[i].s - s <= reach; ++i) caps[i] = std::min(caps[i], x);
    for (std::size_t i = j; i-- > 0 && s - grid.pts[i].s <= reach;) caps[i] = std::min(caps[i], x);
  }
  return caps;
}

}  // namespace cpm::path::detail
