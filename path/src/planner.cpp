// SPDX-License-Identifier: Apache-2.0
// The planner's steps in order (planner.hpp), the repairs, and what the plan reports.
#include "cpm/path/planner.hpp"

#include <algorithm>
#include <cmath>
#include <sstream>

#include "grid.hpp"

namespace cpm::path {
namespace {

using detail::Grid;
using detail::Profile;
using detail::Violation;

// Time held at each grid point: dwells, and the filter's window at every
// stop inside the path, so that the filtered plan is at rest there too.
std::vector<double> hold_times(const Grid& grid, const Geometry& g, double T) {
  std::vector<double> holds(grid.pts.size(), 0.0);
  std::size_t i = 0;
  for (const Stop& st : g.stops) {
    while (i < grid.pts.size() && grid.pts[i].s < st.s - 1e-12) ++i;
    if (i == grid.pts.size()) break;
    const bool inside = st.s > 0.0 && st.s < g.length();
    holds[i] += st.dwell + (inside ? T : 0.0);
  }
  return holds;
}

std::size_t point_at(const Grid& grid, double s) {
  const auto it = std::upper_bound(grid.pts.begin(), grid.pts.end(), s,
                                   [](double v, const detail::Point& p) { return v < p.s; });
  return it == grid.pts.begin() ? 0 : static_cast<std::size_t>(it - grid.pts.begin() - 1);
}

// The repair's factors. The profile's variable is the squared speed x = v^2.
// A speed limit (feed, velocity, actuator velocity) passed by value/limit is
// met by scaling x by (limit/value)^2, less a 2 % margin for what the filter
// and the grid's interpolation add back (kSpeedMargin), and by at least
// kLeastSpeedCut so that a limit passed by a hair still costs a round its
// worth; a force or acceleration limit depends on the path's curvature
// too, not on the speed alone: x is cut by a fixed kOtherCut and the rows'
// bounds tightened by kBoundTighten per round, never below kLeastBoundScale
// of the original (a limit that needs more is a path the machine cannot
// follow: refused after limits.max_repairs rounds).
constexpr double kSpeedMargin = 0.98;
constexpr double kLeastSpeedCut = 0.9;
constexpr double kOtherCut = 0.85;
constexpr double kBoundTighten = 0.97;
constexpr double kLeastBoundScale = 0.5;

// Lower the speed (and for force and acceleration limits the bounds too)
// around every violation, over the distance the filter reaches.
void repair(Grid& grid, std::vector<double>& caps, const Profile& pr, const std::vector<Violation>& vs, double T,
            double step) {
  std::vector<char> tighten(grid.pts.size(), 0);
  for (const Violation& v : vs) {
    const std::size_t i = point_at(grid, v.s);
    const double reach = T * std::sqrt(pr.x[i]) + 2.0 * step;
    const bool speed = v.by == Limit::feed || v.by == Limit::velocity || v.by == Limit::actuator_velocity;
    const double f =
        speed ? std::min(kLeastSpeedCut, kSpeedMargin * (v.limit / v.value) * (v.limit / v.value)) : kOtherCut;
    for (std::size_t j = point_at(grid, v.s - reach); j < grid.pts.size() && grid.pts[j].s <= v.s + reach; ++j) {
      caps[j] = std::min(caps[j], f * pr.x[j]);
      if (!speed) tighten[j] = 1;
    }
  }
  for (std::size_t j = 0; j < grid.pts.size(); ++j)
    if (tighten[j]) grid.pts[j].scale = std::max(kLeastBoundScale, grid.pts[j].scale * kBoundTighten);
}

[[noreturn]] void refuse(const Geometry& g, const Violation& v) {
  std::ostringstream o;
  o << "path: no plan within the limits was found: at " << g.where(v.s) << " (t = " << v.t << " s) ";
  if (v.by == Limit::none) o << "the planned path leaves the workspace";
  else {
    o << limit_name(v.by);
    if (v.axis >= 0) o << " of actuator " << v.axis + 1;
    o << " " << v.value << " exceeds " << v.limit;
  }
  throw Error(o.str());
}

// Below this share of the programmed feed a stretch is reported as limited
// (a smaller dip is the filter's rounding, not a limit).
constexpr double kLimitedBelowFeed = 0.98;

// Stretches where the plan runs below the programmed feed, and what holds it there.
constexpr double kShortStretch = 1e-3;  // m

std::vector<LimitedStretch> limited(const Grid& grid, const Profile& pr, const Geometry& g, int& short_count) {
  std::vector<LimitedStretch> out;
  const std::size_t n = grid.pts.size();
  for (std::size_t i = 0; i < n;) {
    const auto slow = [&](std::size_t k) {
      return std::sqrt(pr.x[k]) * grid.pts[k].speed < kLimitedBelowFeed * grid.pts[k].feed;
    };
    if (!slow(i)) {
      ++i;
      continue;
    }
    LimitedStretch st;
    st.s_begin = grid.pts[i].s;
    std::size_t tight = i;
    st.speed = 1e300;
    for (; i < n && slow(i); ++i) {
      const detail::Point& p = grid.pts[i];
      st.speed = std::min(st.speed, std::sqrt(pr.x[i]) * p.speed);
      const auto room = [&](std::size_t k) { return grid.mvc[k] * grid.pts[k].speed * grid.pts[k].speed / (grid.pts[k].feed * grid.pts[k].feed); };
      if (room(i) < room(tight)) tight = i;
      st.s_end = p.s;
    }
    st.by = grid.mvc_by[tight];
    st.axis = grid.mvc_axis[tight];
    st.feed = grid.pts[tight].feed;
    st.segment = g.pieces[static_cast<std::size_t>(grid.pts[tight].piece)].segment;
    // A dip broken by a grid point or two is one stretch: join it to the
    // last when they are this close and held by the same.
    if (!out.empty() && out.back().by == st.by && st.s_begin - out.back().s_end < kShortStretch) {
      LimitedStretch& last = out.back();
      if (st.speed < last.speed) {
        last.speed = st.speed;
        last.segment = st.segment;
        last.feed = st.feed;
        last.axis = st.axis;
      }
      last.s_end = st.s_end;
      continue;
    }
    out.push_back(st);
  }
  // Left out: stretches shorter than kShortStretch but stops (the blend of a
  // corner dips a few % below the feed for a few tenths of a mm: no news).
  // The count is kept.
  short_count = static_cast<int>(std::erase_if(out, [](const LimitedStretch& l) {
    return l.by != Limit::stop && l.s_end - l.s_begin < kShortStretch;
  }));
  return out;
}

}  // namespace

Plan plan_path(const PathQueue& q, const ctl::Machine& m, const PlannerOptions& o) {
  o.validate();
  Geometry g = blend(q);
  Grid grid = detail::build_grid(g, m, o);
  const double a_t = detail::set_tangential_cap(grid, o);
  detail::max_velocity_curve(grid);
  const double T = 2.0 * a_t / o.cartesian.jerk;
  std::vector<double> caps = detail::spread_caps(grid, T);
  const std::vector<double> holds = hold_times(grid, g, T);
  PlanSummary sum;
  std::vector<Knot> knots;
  Profile pr;
  std::vector<Violation> bad;
  for (int round = 0;; ++round) {
    pr = detail::passes(grid, caps);

    const detail::TimeProfile tp = detail::to_time(grid, pr, holds);
    knots = detail::filtered_knots(tp, T, o.knot_period, g);
    sum = PlanSummary{};
    sum.mode = o.mode;
    // To the knot after the filtered end: from there every knot is at rest.
    sum.duration = static_cast<double>(knots.size() - 1) * o.knot_period;
    sum.repairs = round;
    bad = detail::check(g, knots, m, o, sum);
    if (bad.empty() || round >= o.max_repairs) break;
    repair(grid, caps, pr, bad, T, o.grid_step);
  }
  if (!bad.empty()) refuse(g, bad.front());
  sum.length = g.length();
  sum.filter_time = T;
  sum.tangential_acceleration = a_t;
  sum.limited = limited(grid, pr, g, sum.short_limited);
  return Plan(std::move(g), std::move(knots), o.knot_period, std::move(sum));
}

}  // namespace cpm::path
