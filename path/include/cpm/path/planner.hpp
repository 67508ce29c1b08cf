// SPDX-License-Identifier: Apache-2.0
// The path planner: the speed along a blended path, with look-ahead over
// the whole queue, within the machine's limits. Runs outside the real-time
// cycle (it allocates and may throw); its result, a Plan, is what the cycle
// samples.
//
// How (docs/path.md has the reasoning and the figures):
//  1. The path is blended within the queue's tolerance (geometry.hpp) and
//     cut into points at most grid_step apart (more on arcs and blends).
//  2. At each point every limit becomes a bound on the path acceleration
//     u = s_dd given x = s_dot^2, linear in both (TOPP's form): with
//     p' = dp/ds, p'' = d2p/ds2, d' = J^-1 p', d'' = d(d')/ds,
//       platform force   F = M(p) (p' u + p'' x) + G(p, p') p' x + K(p),
//       actuator command F_d = (J^T F + effects(d, d_dot)) / drive gain,
//       actuator accel.  d_dd = d' u + d'' x,   actuator speed d' s_dot,
//     with M, G, K, J the model's (ctl::Machine, the controller's model).
//     The Cartesian-only mode keeps feed, |v|, |a| only.
//  3. Reachability on the grid (as TOPP-RA, with one control the sets are
//     intervals): the largest x each point allows; a backward pass from
//     the end at rest gives the largest x from which the rest of the path
//     can still be stopped in time (look-ahead over the whole queue); a
//     forward pass from rest takes the largest u that stays inside. This
//     is time-optimal for bounded acceleration.
//  4. Jerk: s(t) is filtered by a moving average of length T = 2 a_t / j,
//     which bounds d3s/dt3 by j when |u| <= a_t (FIR interpolation of
//     the feed, as in Tajima and Sencer). The filter keeps the path (it
//     acts on s, not on the axes). So that it never raises the speed where
//     a limit holds it, the speed caps are first spread along the path by
//     the distance the filter reaches, and every stop is held for T.
//  5. The filtered plan is checked at every knot with the machine's inverse
//     kinematics and inverse dynamics; where a limit is broken the speed
//     and the bounds are lowered there and the plan is made again. A plan
//     that still breaks one is refused (Error naming the program line).
#pragma once

#include "cpm/control/machine.hpp"
#include "cpm/path/plan.hpp"

namespace cpm::path {

// Plan the queue from rest to rest. Throws Error when the options are bad,
// the path leaves the workspace, the machine cannot hold the platform at
// rest somewhere on it, or no plan within the limits was found.
Plan plan_path(const PathQueue& queue, const ctl::Machine& machine, const PlannerOptions& options);

}  // namespace cpm::path
