// SPDX-License-Identifier: Apache-2.0
#include "cpm/calibration/least_squares.hpp"

#include <algorithm>
#include <cmath>

#include "cpm/kinematics/types.hpp"

namespace cpm::cal {
namespace {

double max_cosine(const MatX& J, const VecX& r) {
  const double rn = r.norm();
  if (rn == 0.0) return 0.0;
  double c = 0.0;
  for (Eigen::Index j = 0; j < J.cols(); ++j) {
    const double cn = J.col(j).norm();
    if (cn > 0.0) c = std::max(c, std::abs(J.col(j).dot(r)) / (cn * rn));
  }
  return c;
}

}  // namespace

LmReport levenberg_marquardt(const ResidualFunction& f, VecX& x, const LmOptions& o) {
  LmReport rep;
  const Eigen::Index n = x.size();
  VecX r;
  MatX J;
  f(x, r, &J);
  rep.evaluations = 1;
  if (!r.allFinite() || !J.allFinite())
    throw Error("least squares: residual or Jacobian not finite at the starting point");
  if (r.size() < n)
    throw Error("least squares: " + std::to_string(r.size()) + " residuals for " +
                std::to_string(n) + " parameters: the problem is under-determined");
  double cost = 0.5 * r.squaredNorm();
  rep.initial_cost = cost;
  // Marquardt's scaling: D_j = the largest column norm seen so far, so that
  // the damping and the step test do not depend on the parameters' units.
  VecX D = J.colwise().norm().transpose();
  for (Eigen::Index j = 0; j < n; ++j)
    if (!(D[j] > 0.0)) D[j] = 1.0;
  double lambda = o.initial_lambda;
  double nu = 2.0;
  VecX g = J.transpose() * r;
  for (int it = 0; it < o.max_iterations; ++it) {
    rep.iterations = it + 1;
    rep.gradient_cosine = max_cosine(J, r);
    if (rep.gradient_cosine <= o.gradient_tolerance) {
      rep.converged = true;
      rep.reason = "gradient: the residual is orthogonal to every Jacobian column";
      break;
    }
    // Solve min |J dx + r|^2 + lambda |D dx|^2 as one stacked least-squares
    // problem (QR): better conditioned than the normal equations.
    MatX A(r.size() + n, n);
    A.topRows(r.size()) = J;
    A.bottomRows(n) = (std::sqrt(lambda) * D).asDiagonal();
    VecX b = VecX::Zero(r.size() + n);
    b.head(r.size()) = -r;
    const VecX dx = A.colPivHouseholderQr().solve(b);
    const double step = (D.cwiseProduct(dx)).norm();
    const double xnorm = (D.cwiseProduct(x)).norm();
    if (step <= o.step_tolerance * (xnorm + o.step_tolerance)) {
      rep.converged = true;
      rep.reason = "step: the scaled step is negligible";
      break;
    }
    const VecX x_new = x + dx;
    VecX r_new;
    MatX J_new;
    f(x_new, r_new, &J_new);
    rep.evaluations++;
    const double cost_new = r_new.allFinite() ? 0.5 * r_new.squaredNorm() : INFINITY;
    const double predicted = -(g.dot(dx) + 0.5 * (J * dx).squaredNorm());
    const double actual = cost - cost_new;
    if (cost_new < cost && J_new.allFinite()) {
      const double rho = predicted > 0.0 ? actual / predicted : 0.0;
      x = x_new;
      r = r_new;
      J = J_new;
      g = J.transpose() * r;
      D = D.cwiseMax(J.colwise().norm().transpose());
      rep.last_step_norm = step;
      const bool small = actual <= o.cost_tolerance * cost && predicted <= o.cost_tolerance * cost;
      cost = cost_new;
      lambda *= std::max(1.0 / 3.0, 1.0 - std::pow(2.0 * rho - 1.0, 3));
      nu = 2.0;
      if (small) {
        rep.converged = true;
        rep.reason = "cost: the relative reduction of the cost is negligible";
        break;
      }
    } else {
      lambda *= nu;
      nu *= 2.0;
      if (!(lambda < 1e30)) {
        rep.reason = "damping grew without bound: no step reduces the cost";
        break;
      }
    }
  }
  if (rep.reason.empty()) rep.reason = "iteration limit reached";
  rep.final_cost = cost;
  rep.gradient_norm = g.cwiseAbs().maxCoeff();
  rep.gradient_cosine = max_cosine(J, r);
  rep.lambda = lambda;
  return rep;
}

}  // namespace cpm::cal
