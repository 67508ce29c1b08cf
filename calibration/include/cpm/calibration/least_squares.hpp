// SPDX-License-Identifier: Apache-2.0
// Levenberg-Marquardt for the calibration problems: small dense problems
// (up to a few dozen parameters, thousands of residuals) with an analytic
// Jacobian. Not for the control cycle: it allocates and may throw.
#pragma once

#include <Eigen/Dense>

#include <functional>
#include <string>

namespace cpm::cal {

using VecX = Eigen::VectorXd;
using MatX = Eigen::MatrixXd;

struct LmOptions {
  int max_iterations = 200;
  // Stop when the cosine between the residual and every (scaled) Jacobian
  // column is below this: the residual is orthogonal to what the parameters
  // can change (MINPACK's gtol).
  double gradient_tolerance = 1e-10;
  // Stop when the scaled step is this small relative to the scaled parameters.
  double step_tolerance = 1e-12;
  // Stop when actual and predicted relative reductions of the cost are below this.
  double cost_tolerance = 1e-14;
  double initial_lambda = 1e-3;  // damping, relative to the scaled J^T J
};

// How the iteration went (for the convergence report).
struct LmReport {
  int iterations = 0;            // accepted and rejected steps
  int evaluations = 0;           // residual evaluations
  double initial_cost = 0.0;     // 1/2 |r|^2 at the start (units of r squared)
  double final_cost = 0.0;       // 1/2 |r|^2 at the end
  double gradient_norm = 0.0;    // max |(J^T r)_j| at the end
  double gradient_cosine = 0.0;  // max cosine between r and a column of J at the end
  double last_step_norm = 0.0;   // |D dx| of the last accepted step (scaled)
  double lambda = 0.0;           // damping at the end
  bool converged = false;
  std::string reason;            // which criterion stopped it
};

// r(x) and, when J is not null, J = dr/dx. Throws Error when x is unusable.
using ResidualFunction = std::function<void(const VecX& x, VecX& r, MatX* J)>;

// Minimise 1/2 |r(x)|^2 from the start x (overwritten with the solution).
LmReport levenberg_marquardt(const ResidualFunction& f, VecX& x, const LmOptions& options = {});

}  // namespace cpm::cal
