// SPDX-License-Identifier: Apache-2.0
// Pieces of a candidate effect's evaluation that do not depend on the kind of
// data (not a public header): the searches of a nonlinear parameter (a
// wavelength, a time constant, a speed) and the base parameters a candidate's
// columns are confounded with. Both sides use them: the kinematic effects and
// the motion side's cogging wavelength and Stribeck speed (candidate_*.cpp).
#pragma once

#include <algorithm>
#include <functional>
#include <string>
#include <vector>

#include <Eigen/Dense>

#include "internal.hpp"

namespace cpm::ident::detail {

// Indices of the local minima of v (each no higher than its neighbours), the
// lowest first, at most n of them.
inline std::vector<int> lowest_local_minima(const std::vector<double>& v, std::size_t n) {
  const int K = static_cast<int>(v.size());
  std::vector<int> m;
  for (int q = 0; q < K; ++q) {
    const auto u = static_cast<std::size_t>(q);
    if ((q == 0 || v[u] <= v[u - 1]) && (q == K - 1 || v[u] <= v[u + 1])) m.push_back(q);
  }
  std::sort(m.begin(), m.end(), [&](int a, int b) { return v[static_cast<std::size_t>(a)] < v[static_cast<std::size_t>(b)]; });
  if (m.size() > n) m.resize(n);
  return m;
}

// Golden-section refinement (iters steps) of cost on one grid step either
// side of each grid point x0 + q * step for q in `at`, kept within [lo, hi]:
// the best point found. When grid_cost (the cost at every grid point) is
// given, the grid points themselves compete. `none`: the answer when no
// cost is below 1e300.
template <class F>
double refine_grid_minima(F&& cost, const std::vector<int>& at, const std::vector<double>& grid_cost, double x0,
                          double step, double lo, double hi, int iters, double none) {
  double best = 1e300, bx = none;
  for (int q : at) {
    const double xq = x0 + q * step;
    double fb = 0.0;
    const double xr = golden(cost, std::max(lo, xq - step), std::min(hi, xq + step), iters, fb);
    if (fb < best) { best = fb; bx = xr; }
    if (!grid_cost.empty() && grid_cost[static_cast<std::size_t>(q)] < best) {
      best = grid_cost[static_cast<std::size_t>(q)];
      bx = xq;
    }
  }
  return bx;
}

// Minimum of cost on n equally spaced points of [lo, hi], refined by golden
// section (iters steps) one grid step either side of the best (within
// [lo, hi]). `none`: the answer when no grid cost is below 1e300. For a
// parameter known to a factor (a time constant, a speed), pass its log.
template <class F>
double grid_then_golden(F&& cost, double lo, double hi, int n, int iters, double none) {
  double best = 1e300, bx = none;
  const double step = (hi - lo) / (n - 1);
  for (int g = 0; g < n; ++g) {
    const double x = lo + g * step;
    const double v = cost(x);
    if (v < best) { best = v; bx = x; }
  }
  double fb = 0.0;
  const double xr = golden(cost, std::max(lo, bx - step), std::min(hi, bx + step), iters, fb);
  if (fb < best) bx = xr;
  return bx;
}

// The base parameter whose column is most alike column j of a candidate
// (cosines: rows are the candidate's columns, Engine::base_cosines), or
// empty when the base has no columns.
inline std::string most_alike_base(const Eigen::MatrixXd& cosines, Eigen::Index j,
                                   const std::vector<std::string>& base_names) {
  if (cosines.cols() == 0) return {};
  Eigen::Index bi = 0;
  cosines.row(j).cwiseAbs().maxCoeff(&bi);
  return base_names[static_cast<std::size_t>(bi)];
}

// The base parameters a candidate's columns are confounded with: for each
// column with at least 81 % of it in the base span (share, Engine::base_share;
// |cos| >= 0.9), the base parameter most alike it, each once, with the
// measurement that would separate them (separate_by(base parameter name)).
inline std::vector<Confounder> base_confounders(const Eigen::VectorXd& share, const Eigen::MatrixXd& cosines,
                                                const std::vector<std::string>& base_names,
                                                const std::function<std::string(const std::string&)>& separate_by) {
  std::vector<Confounder> out;
  for (Eigen::Index j = 0; j < cosines.rows() && cosines.cols() > 0; ++j) {
    if (share(j) < 0.81) continue;
    const std::string name = most_alike_base(cosines, j, base_names);
    bool dup = false;
    for (const auto& o : out) dup |= o.with == name;
    if (!dup) out.push_back({name, "", -1, std::sqrt(share(j)), separate_by(name)});
  }
  return out;
}

}  // namespace cpm::ident::detail
