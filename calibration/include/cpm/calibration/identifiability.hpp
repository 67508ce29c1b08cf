// SPDX-License-Identifier: Apache-2.0
// How well do the data determine each parameter? From the Jacobian J of the
// residuals at the solution and the residuals r:
//  * singular values of J with its columns scaled to unit length (so that the
//    units of the parameters do not matter) and their condition number;
//  * the residual variance s^2 = |r|^2 / (N - P) and the covariance
//    s^2 (J^T J)^-1, hence each parameter's standard error and its confidence
//    interval (Student t with N - P degrees of freedom);
//  * the correlation matrix, with the strongly correlated pairs named;
//  * the combinations the data cannot determine (near-null right singular
//    vectors of the scaled J), named by their largest components.
// Domain layers (position, ball-bar) add advice on which measurement fixes a
// weakness.
#pragma once

#include <string>
#include <vector>

#include "cpm/calibration/least_squares.hpp"

namespace cpm::cal {

struct CorrelatedPair {
  int a = 0, b = 0;         // parameter indices
  double correlation = 0.0;
};

// A direction in parameter space the data barely see: sum_j weight_j * x_j / scale_j.
struct WeakCombination {
  double relative_singular_value = 0.0;   // s_k / s_max of the scaled Jacobian
  std::vector<std::pair<int, double>> terms;  // (parameter, weight), |weight| >= 0.1, largest first
  bool undetermined = false;               // numerically zero: the data cannot fix it at all
};

struct Identifiability {
  std::vector<std::string> names;
  std::vector<std::string> units;
  VecX value;               // fitted values
  VecX std_error;           // +inf for a parameter in an undetermined combination
  VecX ci_low, ci_high;     // confidence interval at `confidence`
  double confidence = 0.95;
  double t_quantile = 0.0;  // the Student t factor used for the interval
  MatX covariance;
  MatX correlation;
  VecX singular_values;     // of the column-scaled Jacobian, descending
  double condition_number = 0.0;  // s_max / s_min of the column-scaled Jacobian (inf when rank deficient)
  int observations = 0;     // N
  int dof = 0;              // N - P
  double residual_rms = 0.0;    // sqrt(|r|^2 / N), units of r
  double residual_sigma = 0.0;  // sqrt(|r|^2 / (N - P)): the estimate of the measurement noise
  VecX multiple_correlation;    // R_j: how well the other parameters' columns imitate column j (1 = not separable)
  std::vector<CorrelatedPair> strong_pairs;  // |rho| >= strong_correlation, largest first
  std::vector<WeakCombination> weak;         // relative singular value below weak_threshold
  std::vector<std::string> warnings;

  [[nodiscard]] int index(const std::string& name) const;  // -1 when absent
  // "c1 = 1.000012 ± 0.000003 (1)" style lines, for people.
  [[nodiscard]] std::string describe_combination(const WeakCombination& w) const;
};

struct IdentifiabilityOptions {
  double confidence = 0.95;
  double strong_correlation = 0.9;
  double weak_threshold = 1e-4;          // relative singular value: warn
  double undetermined_threshold = 1e-9;  // relative singular value: cannot be determined
  double inseparable_correlation = 0.9999;  // multiple correlation above which a parameter is named not separable
};

Identifiability analyse_identifiability(const MatX& J, const VecX& r, const VecX& x,
                                        std::vector<std::string> names,
                                        std::vector<std::string> units,
                                        const IdentifiabilityOptions& options = {});

// Two-sided Student t quantile: P(|T| <= t) = confidence with `dof` degrees of freedom.
double student_t_quantile(double confidence, int dof);

}  // namespace cpm::cal
