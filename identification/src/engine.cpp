// SPDX-License-Identifier: Apache-2.0
#include "cpm/identification/engine.hpp"

#include <algorithm>
#include <cmath>

#include "cpm/identification/stats.hpp"
#include "cpm/kinematics/types.hpp"

namespace cpm::ident {
namespace {

// Least squares with column scaling and rank detection; coefficients of
// dependent columns are 0.
Eigen::VectorXd lstsq(const Eigen::MatrixXd& A, const Eigen::VectorXd& b, bool* full_rank) {
  const Eigen::Index n = A.cols();
  Eigen::VectorXd scale(n);
  for (Eigen::Index j = 0; j < n; ++j) {
    const double s = A.col(j).norm();
    scale(j) = s > 0.0 ? 1.0 / s : 0.0;
  }
  const Eigen::MatrixXd As = A * scale.asDiagonal();
  Eigen::ColPivHouseholderQR<Eigen::MatrixXd> qr(As);
  qr.setThreshold(1e-9);
  if (full_rank) *full_rank = qr.rank() == n && (scale.array() > 0.0).all();
  return scale.asDiagonal() * qr.solve(b);
}

}  // namespace

Engine::Engine(LinearProblem problem) : p_(std::move(problem)) {
  const Eigen::Index N = p_.y.size();
  if (p_.B.rows() != N || p_.w.size() != N || static_cast<Eigen::Index>(p_.series.size()) != N)
    throw Error("identification: residual, base columns, weights and series differ in length");
  yw_ = p_.w.cwiseProduct(p_.y);
  Bw_ = p_.w.asDiagonal() * p_.B;
  // Identifiable base columns: greedy by pivoted QR on scaled columns,
  // the nuisance first. A nuisance column is fitted in every test; where it
  // is collinear with a base parameter (a structure's constant on z and the
  // weight) the pivot must keep it, else a fit without the base refit leaves
  // that direction free and an effect beside it takes it (a drive gain or a
  // payload on z took the mean of a force outside the library).
  const Eigen::Index nb = Bw_.cols();
  if (nb > 0) {
    Eigen::VectorXd scale(nb), pivot(nb);
    for (Eigen::Index j = 0; j < nb; ++j) {
      const double s = Bw_.col(j).norm();
      scale(j) = s > 0.0 ? 1.0 / s : 0.0;
      const bool nuisance = static_cast<std::size_t>(j) < p_.nuisance.size() && p_.nuisance[static_cast<std::size_t>(j)];
      pivot(j) = nuisance ? 2.0 * scale(j) : scale(j);
    }
    const Eigen::MatrixXd Bs = Bw_ * scale.asDiagonal();
    Eigen::ColPivHouseholderQR<Eigen::MatrixXd> qr(Bw_ * pivot.asDiagonal());
    qr.setThreshold(1e-7);
    rank_ = static_cast<int>(qr.rank());
    for (Eigen::Index j = 0; j < nb; ++j) {
      const int c = static_cast<int>(qr.colsPermutation().indices()(j));
      (j < rank_ && scale(c) > 0.0 ? ident_ : unident_).push_back(c);
    }
    std::sort(ident_.begin(), ident_.end());
    std::sort(unident_.begin(), unident_.end());
    rank_ = static_cast<int>(ident_.size());
    Eigen::MatrixXd Bi(N, rank_);
    for (int j = 0; j < rank_; ++j) Bi.col(j) = Bs.col(ident_[j]);
    Eigen::HouseholderQR<Eigen::MatrixXd> q2(Bi);
    Q_ = q2.householderQ() * Eigen::MatrixXd::Identity(N, rank_);
    for (int j : ident_)
      if (static_cast<std::size_t>(j) < p_.nuisance.size() && p_.nuisance[j]) ident_n_.push_back(j);
    const int rn = static_cast<int>(ident_n_.size());
    Eigen::MatrixXd Bn(N, rn);
    for (int j = 0; j < rn; ++j) Bn.col(j) = Bs.col(ident_n_[j]);
    Eigen::HouseholderQR<Eigen::MatrixXd> q3(Bn);
    Qn_ = q3.householderQ() * Eigen::MatrixXd::Identity(N, rn);
  } else {
    Q_.resize(N, 0);
    Qn_.resize(N, 0);
  }
  yperp_ = yw_ - Q_ * (Q_.transpose() * yw_);
  yn_ = yw_ - Qn_ * (Qn_.transpose() * yw_);
  rss0_ = yn_.squaredNorm();
  base_ = fit(Eigen::MatrixXd(N, 0), true);
}

Eigen::MatrixXd Engine::project_off_base(const Eigen::MatrixXd& X) const {
  Eigen::MatrixXd Xw = p_.w.asDiagonal() * X;
  if (rank_ > 0) Xw -= Q_ * (Q_.transpose() * Xw);
  return Xw;
}

Eigen::MatrixXd Engine::project_off_nuisance(const Eigen::MatrixXd& X) const {
  Eigen::MatrixXd Xw = p_.w.asDiagonal() * X;
  if (Qn_.cols()) Xw -= Qn_ * (Qn_.transpose() * Xw);
  return Xw;
}

double Engine::rss(const Eigen::MatrixXd& X, bool with_base) const {
  if (X.cols() == 0) return with_base ? base_.rss : rss0_;
  if (with_base) {
    const Eigen::MatrixXd Xp = project_off_base(X);
    const Eigen::VectorXd b = lstsq(Xp, yperp_, nullptr);
    return (yperp_ - Xp * b).squaredNorm();
  }
  const Eigen::MatrixXd Xw = project_off_nuisance(X);
  const Eigen::VectorXd b = lstsq(Xw, yn_, nullptr);
  return (yn_ - Xw * b).squaredNorm();
}

JointFit Engine::fit(const Eigen::MatrixXd& X, bool with_base) const {
  JointFit f;
  const Eigen::Index N = rows();
  const Eigen::Index nb = p_.B.cols();
  f.base_delta = Eigen::VectorXd::Zero(nb);
  Eigen::VectorXd rw;
  if (with_base) {
    const Eigen::MatrixXd Xp = project_off_base(X);
    f.beta = X.cols() ? lstsq(Xp, yperp_, &f.full_rank) : Eigen::VectorXd(0);
    rw = yperp_ - (X.cols() ? Eigen::VectorXd(Xp * f.beta) : Eigen::VectorXd::Zero(N));
    if (rank_ > 0) {
      // Base change: least squares of what is left after the candidate on the identifiable base.
      Eigen::VectorXd target = yw_;
      if (X.cols()) target -= p_.w.asDiagonal() * (X * f.beta);
      Eigen::MatrixXd Bi(N, rank_);
      for (int j = 0; j < rank_; ++j) Bi.col(j) = Bw_.col(ident_[j]);
      const Eigen::VectorXd db = lstsq(Bi, target, nullptr);
      for (int j = 0; j < rank_; ++j) f.base_delta(ident_[j]) = db(j);
    }
  } else {
    Eigen::MatrixXd Xw = p_.w.asDiagonal() * X;
    if (Qn_.cols()) Xw -= Qn_ * (Qn_.transpose() * Xw);
    f.beta = X.cols() ? lstsq(Xw, yn_, &f.full_rank) : Eigen::VectorXd(0);
    rw = yn_ - (X.cols() ? Eigen::VectorXd(Xw * f.beta) : Eigen::VectorXd::Zero(N));
    const int rn = static_cast<int>(ident_n_.size());
    if (rn > 0) {
      Eigen::VectorXd target = yw_;
      if (X.cols()) target -= p_.w.asDiagonal() * (X * f.beta);
      Eigen::MatrixXd Bn(N, rn);
      for (int j = 0; j < rn; ++j) Bn.col(j) = Bw_.col(ident_n_[j]);
      const Eigen::VectorXd db = lstsq(Bn, target, nullptr);
      for (int j = 0; j < rn; ++j) f.base_delta(ident_n_[j]) = db(j);
    }
  }
  f.rss = rw.squaredNorm();
  f.residual = rw.cwiseQuotient(p_.w);
  f.n_eff = effective_rows(rw);
  return f;
}

NestedTest Engine::nested(double rss_parent, double rss, int q, int k_total, double n_eff) const {
  NestedTest t;
  if (q <= 0 || !(rss >= 0.0)) return t;
  const double N = rows(), fr = floor_rss();
  const double ne = std::max(n_eff, static_cast<double>(k_total) + 2.0);
  const double gain = std::max(0.0, rss_parent - rss);
  const double den = (rss + fr) / std::max(1.0, N - k_total);
  t.f_stat = den > 0.0 ? (gain / q) / den * (ne / N) : 0.0;
  t.p_value = f_tail(t.f_stat, q, std::max(1.0, ne - k_total));
  t.delta_bic = rss + fr > 0.0 && rss_parent + fr > 0.0
                    ? ne * std::log((rss + fr) / (rss_parent + fr)) + q * std::log(ne)
                    : 0.0;
  return t;
}

double Engine::effective_rows(const Eigen::VectorXd& rw) const {
  std::vector<std::vector<double>> s(static_cast<std::size_t>(std::max(1, p_.n_series)));
  for (Eigen::Index r = 0; r < rw.size(); ++r) s[static_cast<std::size_t>(p_.series[r])].push_back(rw(r));
  return effective_samples(s);
}

Eigen::VectorXd Engine::base_share(const Eigen::MatrixXd& X) const {
  const Eigen::MatrixXd Xw = p_.w.asDiagonal() * X;
  const Eigen::MatrixXd Xp = project_off_base(X);
  Eigen::VectorXd s(X.cols());
  for (Eigen::Index j = 0; j < X.cols(); ++j) {
    const double n2 = Xw.col(j).squaredNorm();
    s(j) = n2 > 0.0 ? std::clamp(1.0 - Xp.col(j).squaredNorm() / n2, 0.0, 1.0) : 1.0;
  }
  return s;
}

Eigen::MatrixXd Engine::base_cosines(const Eigen::MatrixXd& X) const {
  const Eigen::MatrixXd Xw = p_.w.asDiagonal() * X;
  Eigen::MatrixXd c = Eigen::MatrixXd::Zero(X.cols(), Bw_.cols());
  for (Eigen::Index i = 0; i < X.cols(); ++i)
    for (Eigen::Index j = 0; j < Bw_.cols(); ++j) {
      const double den = Xw.col(i).norm() * Bw_.col(j).norm();
      c(i, j) = den > 0.0 ? Xw.col(i).dot(Bw_.col(j)) / den : 0.0;
    }
  return c;
}

Eigen::MatrixXd Engine::covariance(const Eigen::MatrixXd& Jc, const JointFit& f,
                                   int n_params_total, bool with_base) const {
  const Eigen::Index N = rows();
  const std::vector<int>& cols = with_base ? ident_ : ident_n_;
  const int nb = static_cast<int>(cols.size());
  Eigen::MatrixXd Z(N, nb + Jc.cols());
  for (int j = 0; j < nb; ++j) Z.col(j) = Bw_.col(cols[j]);
  Z.rightCols(Jc.cols()) = p_.w.asDiagonal() * Jc;
  Eigen::VectorXd scale(Z.cols());
  for (Eigen::Index j = 0; j < Z.cols(); ++j) {
    const double s = Z.col(j).norm();
    scale(j) = s > 0.0 ? 1.0 / s : 0.0;
  }
  const Eigen::MatrixXd Zs = Z * scale.asDiagonal();
  const Eigen::MatrixXd G = Zs.transpose() * Zs;
  const Eigen::MatrixXd Ginv = G.completeOrthogonalDecomposition().pseudoInverse();
  const double dof = std::max(1.0, static_cast<double>(N) - n_params_total);
  const double s2 = f.rss / dof;
  const double inflate = f.n_eff > 0.0 ? static_cast<double>(N) / f.n_eff : 1.0;
  const Eigen::MatrixXd full = scale.asDiagonal() * Ginv * scale.asDiagonal() * (s2 * inflate);
  return full.bottomRightCorner(Jc.cols(), Jc.cols());
}

}  // namespace cpm::ident
