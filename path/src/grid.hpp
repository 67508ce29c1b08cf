// SPDX-License-Identifier: Apache-2.0
// The planner's grid: points along the path where every limit is a bound
// on u = s_dd given x = s_dot^2 (planner.hpp, step 2), and the passes over it.
#pragma once

#include <array>
#include <vector>

#include "cpm/control/machine.hpp"
#include "cpm/path/geometry.hpp"
#include "cpm/path/limits.hpp"
#include "cpm/path/plan.hpp"

namespace cpm::path::detail {

// lo <= a u + b x + c <= hi, from limit `by` of actuator `axis`.
struct Row {
  double a = 0, b = 0, c = 0, lo = 0, hi = 0;
  Limit by = Limit::none;
  int axis = -1;
};

struct Point {
  double s = 0.0;
  int piece = 0;
  double cap = 0.0;   // x <= cap: feed, speeds, curvature steps, stops (m^2/s^2)
  Limit cap_by = Limit::feed;
  int cap_axis = -1;
  double u_cap = 0.0;  // |u| <= u_cap (m/s^2)
  // |p' u + p'' x| <= A: p'.p', p'.p'', p''.p'', A^2 (A2 <= 0: not applied)
  double q11 = 0, q12 = 0, q22 = 0, A2 = 0;
  std::array<Row, 6> rows{};
  int nrows = 0;
  double scale = 1.0;  // factor on the rows' bounds, lowered by repairs
  double speed = 1.0;  // |p'|: platform speed per unit s_dot
  double feed = 0.0;   // programmed speed here (m/s): the feed, or the velocity ceiling for rapids
  bool rapid = false;
  bool stop = false;
};

struct Grid {
  const Geometry* geometry = nullptr;  // what it was built from
  std::vector<Point> pts;
  std::vector<double> mvc;     // largest feasible x at each point
  std::vector<double> steady;  // largest x at which u = 0 is feasible (<= mvc)
  std::vector<Limit> mvc_by;
  std::vector<int> mvc_axis;
};

// The grid of a blended path (throws Error at a point outside the workspace
// or where the machine cannot hold the platform at rest).
Grid build_grid(const Geometry& g, const ctl::Machine& m, const PlannerOptions& o);

// Which limits set the lower and upper bound on u.
struct Binding {
  Limit lo_by = Limit::tangential;
  int lo_axis = -1;
  Limit hi_by = Limit::tangential;
  int hi_axis = -1;
};
// The bounds on u at x: false when there is none.
bool interval(const Point& p, double x, double& lo, double& hi, Binding* why = nullptr) noexcept;
// Sets the tangential cap on every point; returns it (m/s^2).
double set_tangential_cap(Grid& grid, const PlannerOptions& o);
// Largest feasible x at every point (grid.mvc) and what bounds it.
void max_velocity_curve(Grid& grid);

// x (= s_dot^2) at every point and u over each interval [i, i+1].
struct Profile {
  std::vector<double> x, u;
};
// Caps spread by the filter's reach (planner.hpp, step 4): each point's
// largest x held over the distance the filter's window covers at that speed.
std::vector<double> spread_caps(const Grid& grid, double filter_time);
// Backward and forward passes under the caps: the time-optimal profile.
Profile passes(const Grid& grid, const std::vector<double>& caps);

// s(t) of a profile: u constant between grid points, and holds at stops.
// Entry k starts at t[k] from s[k] at speed v[k] with acceleration u[k];
// q[k] is the integral of s dt from 0 to t[k]. The last entry is the end.
struct TimeProfile {
  std::vector<double> t, s, v, u, q;
};
// holds[i]: s to stay at rest when passing point i.
TimeProfile to_time(const Grid& grid, const Profile& pr, const std::vector<double>& holds);
// The knots, every dt, of s(t) filtered by a moving average of length T.
std::vector<Knot> filtered_knots(const TimeProfile& tp, double T, double dt, const Geometry& g);

// A limit the checked plan broke.
struct Violation {
  double t = 0.0, s = 0.0;  // s, m
  Limit by = Limit::none;   // none: the platform left the workspace
  int axis = -1;
  double value = 0.0, limit = 0.0;
};
// Check the plan (its geometry and knots) with the machine's inverse
// kinematics and dynamics, at every knot while the acceleration along the
// path changes and else every half grid step of path or eighth knot: the
// violations of its mode's limits, and the figures in `sum`.
std::vector<Violation> check(const Geometry& g, const std::vector<Knot>& knots, const ctl::Machine& m,
                             const PlannerOptions& o, PlanSummary& sum);

}  // namespace cpm::path::detail
