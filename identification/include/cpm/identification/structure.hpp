// SPDX-License-Identifier: Apache-2.0
// What remains: structure in a residual that the fitted effects do not
// explain, said with where it is. Checks, per axis: a difference between the
// two directions of motion; a periodic pattern against each axis' position
// (wavelengths 2 mm .. 2/3 of the stroke covered) and against time; a trend
// in time; a step or a bump at a position; a friction whose level varies
// along the axis' own travel (position_friction); a smooth force that follows any
// axis' position, velocity or acceleration, or time (the best variable per
// axis, with the others that explain it nearly as well). Significance uses the residual's
// own spread, corrected for autocorrelation and for how many places were
// searched, so noise alone reports nothing.
#pragma once

#include <string>
#include <vector>

#include "cpm/identification/diagnose.hpp"

namespace cpm::ident {

// The smooth search's basis: Legendre polynomials of degree 1..kSmoothDegree.
constexpr int kSmoothDegree = 5;

// Variable `name` of the state at kept row r: "d1".."d3" (m), "v1".."v3"
// (m/s), "a1".."a3" (m/s^2, the long-kernel estimate of the columns), "t" (s).
double state_variable(const MotionProblem& P, int r, const std::string& name);
// P_1..P_kSmoothDegree of x mapped from [lo, hi] to [-1, 1] (clamped): the columns of a smooth finding.
void legendre_row(double x, double lo, double hi, double* out);

// The columns of a smooth force on `axis` following `var` over [lo, hi]:
// P_1..P_kSmoothDegree and a constant, 3R rows (zero off the axis). Of a
// position, velocity or time: the polynomial of each sample's value through
// the rows' own filter, as the library's effect columns are built (a
// polynomial of the row's filtered state differs from it by a term in the
// acceleration, which a spring at its stiffness bound took up); of an
// acceleration: at the row.
Eigen::MatrixXd smooth_columns(const MotionProblem& P, int axis, const std::string& var, double lo, double hi);
// The nodes of a table of a variable with values x: kTableUniformNodes
// evenly over its range and the kTableQuantileNodes' inner quantiles (where
// the log dwells), merged closer than 1 % of the range. Increasing.
constexpr int kTableUniformNodes = 12, kTableQuantileNodes = 8;
std::vector<double> table_nodes(std::vector<double> x);
// A table of `var` on `axis`: piecewise linear between table_nodes of the
// log's rows, as the hats of nodes 2..n and a constant, filtered as
// smooth_columns; no columns when fewer than 3 nodes. It follows a narrow
// hump the polynomial cannot.
Eigen::MatrixXd table_columns(const MotionProblem& P, int axis, const std::string& var);

// The columns of a friction that varies along `axis`' own travel (kind
// "position_friction"): sign(v) and sign(v) P_1..P_kSmoothDegree(d) over
// [lo, hi] of the axis' own position (the finding's nodes and values: the
// level (N, opposing the motion) at positions of d_axis), sign(v) as the library's
// Coulomb friction has it (tanh(v / kSignEpsilon)), filtered as smooth_columns.
Eigen::MatrixXd friction_map_columns(const MotionProblem& P, int axis, double lo, double hi);

// bump_beside_step: also a bump on an axis where a step was found (by
// default not: one of the two describes the axis).
std::vector<StructureFinding> find_motion_structure(const MotionProblem& P,
                                                    const Eigen::VectorXd& residual,
                                                    const Vec3& axis_noise, bool bump_beside_step = false);

// Periodogram of y against coordinate x for wavelengths in [lmin, lmax]:
// the least-squares power of a sine/cosine pair (weighted sum of squares
// removed) at each wavelength. Returns wavelengths and powers.
void periodogram(const std::vector<double>& x, const std::vector<double>& y, double lmin, double lmax,
                 std::vector<double>& wavelength, std::vector<double>& power);

}  // namespace cpm::ident
