// SPDX-License-Identifier: Apache-2.0
// The regression machinery every data kind shares: a residual y (one row per
// measured scalar), the columns of the base model's own parameters B, row
// weights, and candidate effects given as more columns. Fitting a candidate
// "jointly with the base" is least squares on [B, X]; by Frisch-Waugh-Lovell
// it is done as X and y projected off the span of B, so the base is
// factorised once. The dynamic side (motion logs) builds its problem in
// motion.hpp; a kinematic side (ball-bar, positions) would build the same
// struct from its own residual and Jacobians.
#pragma once

#include <string>
#include <vector>

#include <Eigen/Dense>

namespace cpm::ident {

struct LinearProblem {
  Eigen::VectorXd y;                 // residual of the model as given (data units)
  Eigen::MatrixXd B;                 // base-parameter columns (data units per parameter unit)
  std::vector<std::string> base_names, base_units;
  std::vector<double> base_values;   // current values of the base parameters
  // Nuisance columns (flag per base column): always fitted, even for "the
  // model as given" (e.g. axis coupling from misaligned planes on motion data).
  std::vector<char> nuisance;
  Eigen::VectorXd w;                 // row weights (1 / noise sigma of the row)
  std::vector<int> series;           // row -> series (e.g. axis); rows of a series are in time order
  int n_series = 1;
  // Resolution of the residual itself, as a variance per row in weighted
  // units: what the model's own approximations leave even on noise-free
  // data. Added to every RSS the statistics compare, so that on data far
  // quieter than that resolution a crumb of approximation error is not
  // called a physical effect. 0: the noise alone decides.
  double floor_variance = 0.0;
};

// A nested model against its parent: q parameters added, k_total fitted in
// all, n_eff effective rows; both RSS with the problem's resolution floor.
struct NestedTest {
  double f_stat = 0.0;
  double p_value = 1.0;
  double delta_bic = 0.0;   // < 0 favours the nested model
};

struct JointFit {
  Eigen::VectorXd beta;        // coefficients of the candidate columns
  Eigen::VectorXd base_delta;  // change of the base parameters (0 when not refitted)
  Eigen::VectorXd residual;    // residual after the fit (data units)
  double rss = 0.0;            // weighted residual sum of squares
  double n_eff = 0.0;          // effective independent rows of this residual
  bool full_rank = true;       // false: the candidate columns are (nearly) in the base span
};

class Engine {
 public:
  explicit Engine(LinearProblem problem);

  [[nodiscard]] const LinearProblem& problem() const noexcept { return p_; }
  [[nodiscard]] int rows() const noexcept { return static_cast<int>(p_.y.size()); }
  [[nodiscard]] double rss_given() const noexcept { return rss0_; }     // only nuisance fitted
  [[nodiscard]] double rss_base() const noexcept { return base_.rss; }  // base refitted
  [[nodiscard]] const JointFit& base_fit() const noexcept { return base_; }
  [[nodiscard]] int base_rank() const noexcept { return rank_; }
  // Identifiable base columns that are not nuisance: what a base refit adds
  // to the model as given (whose fit already holds the nuisance).
  [[nodiscard]] int base_rank_beyond_nuisance() const noexcept { return rank_ - nuisance_rank(); }
  // Identifiable nuisance columns: fitted in every model, the model as given included.
  [[nodiscard]] int nuisance_rank() const noexcept { return static_cast<int>(ident_n_.size()); }
  // Base parameters that the data cannot determine (their column is in the span of the others).
  [[nodiscard]] const std::vector<int>& unidentifiable_base() const noexcept { return unident_; }

  // Least squares of the residual on X (unweighted columns), with the base
  // refitted jointly or kept as given.
  [[nodiscard]] JointFit fit(const Eigen::MatrixXd& X, bool with_base = true) const;
  // Only the weighted RSS (searches call this many times).
  [[nodiscard]] double rss(const Eigen::MatrixXd& X, bool with_base = true) const;
  // X (weighted) with its base-span part removed.
  [[nodiscard]] Eigen::MatrixXd project_off_base(const Eigen::MatrixXd& X) const;
  // X (weighted) with its nuisance-span part removed: the space in which
  // candidates that are base directions (payload, inertia error) are judged.
  [[nodiscard]] Eigen::MatrixXd project_off_nuisance(const Eigen::MatrixXd& X) const;
  // Share of each column of X that lies in the base span (R^2, 0..1), and
  // the cosine with each base column (rows: columns of X).
  [[nodiscard]] Eigen::VectorXd base_share(const Eigen::MatrixXd& X) const;
  [[nodiscard]] Eigen::MatrixXd base_cosines(const Eigen::MatrixXd& X) const;
  // Covariance of (base, theta) for a linearised model with Jacobian columns
  // Jc (unweighted) at the fitted point, scaled by the residual variance and
  // the effective sample size. Returns the covariance of theta only; base
  // columns that are unidentifiable are left out.
  [[nodiscard]] Eigen::MatrixXd covariance(const Eigen::MatrixXd& Jc, const JointFit& f,
                                           int n_params_total, bool with_base = true) const;
  [[nodiscard]] double effective_rows(const Eigen::VectorXd& weighted_residual) const;
  // The RSS a fit cannot go below: rows x floor_variance.
  [[nodiscard]] double floor_rss() const noexcept { return p_.floor_variance * rows(); }
  // F-test and BIC of a model with RSS `rss` against its parent (`rss_parent`).
  [[nodiscard]] NestedTest nested(double rss_parent, double rss, int q, int k_total, double n_eff) const;
  // Weighted RMS -> data units: RMS of an unweighted residual.
  static double rms(const Eigen::VectorXd& r) {
    return r.size() ? std::sqrt(r.squaredNorm() / static_cast<double>(r.size())) : 0.0;
  }

 private:
  LinearProblem p_;
  Eigen::VectorXd yw_, yperp_;
  Eigen::MatrixXd Bw_, Q_, Qn_;  // orthonormal bases of the identifiable base / nuisance spans
  Eigen::VectorXd yn_;           // weighted y off the nuisance span
  std::vector<int> ident_, unident_, ident_n_;
  int rank_ = 0;
  double rss0_ = 0.0;
  JointFit base_;
};

}  // namespace cpm::ident
