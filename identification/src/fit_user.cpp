// SPDX-License-Identifier: Apache-2.0
#include "cpm/identification/fit_user.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <sstream>

#include "cpm/identification/align.hpp"
#include "cpm/identification/diagnose.hpp"
#include "cpm/identification/fit.hpp"

namespace cpm::ident {
namespace {

using Eigen::MatrixXd;
using Eigen::VectorXd;

// The regression a user effect is fitted on: the residual of the model
// without it, aligned as `cpm fit` aligns, the nuisance columns beside it,
// rows weighted by 1 / (noise of their axis).
struct Regression {
  MotionProblem P;
  VectorXd y;   // weighted residual
  MatrixXd B;   // weighted nuisance columns
  VectorXd w;   // row weights
};

Regression regression(const io::MotionData& data, const ctl::MachineModel& without, const MotionOptions& o) {
  const ctl::Machine m(without);
  Regression R{prepare_motion(data, m, o), {}, {}, {}};
  R.P.set_delay(align_motion(data, m, o).reference);
  const LinearProblem L = nuisance_only(motion_linear_problem(R.P));
  R.w = L.w;
  R.y = L.y.cwiseProduct(L.w);
  R.B = L.w.asDiagonal() * L.B;
  return R;
}

// Values of `input` ('d' or 'v' of input_axis) over the log.
std::pair<double, double> data_range(const io::MotionData& data, char input, int axis) {
  const std::vector<Vec3>& x = input == 'd' ? data.d : data.v;
  double lo = std::numeric_limits<double>::infinity(), hi = -lo;
  for (const Vec3& s : x) {
    lo = std::min(lo, s[axis]);
    hi = std::max(hi, s[axis]);
  }
  return {lo, hi};
}

UserFit fit_table(const io::MotionData& data, const ctl::MachineModel& model, int index, const MotionOptions& o) {
  const ctl::UserEffect& e = model.user_effects[static_cast<std::size_t>(index)];
  ctl::MachineModel without = model;
  without.user_effects.erase(without.user_effects.begin() + index);
  Regression R = regression(data, without, o);
  const int n = static_cast<int>(e.nodes.size());
  // Column k: the force of a table with 1 N at node k and 0 elsewhere (the
  // hat function of linear interpolation held beyond the ends).
  const int nb = static_cast<int>(R.B.cols());
  MatrixXd Z(R.y.size(), nb + n);
  Z.leftCols(nb) = R.B;
  std::vector<double> unit(static_cast<std::size_t>(n), 0.0);
  for (int k = 0; k < n; ++k) {
    ctl::UserEffect hat = e;
    hat.values.assign(static_cast<std::size_t>(n), 0.0);
    hat.values[static_cast<std::size_t>(k)] = 1.0;
    Z.col(nb + k) = R.w.cwiseProduct(R.P.user_force_column({hat}));
  }
  // Nodes the data never come near: their columns are (almost) zero.
  const double col_scale = Z.rightCols(n).colwise().norm().maxCoeff();
  if (!(col_scale > 0.0))
    throw Error("user_effects[" + std::to_string(index) + "]: the log never moves " + e.input_name() +
                " over the table's nodes: nothing to fit");
  // Second differences of the values, divided by the node spacing (a
  // curvature per unit of the input, so unequal spacing is not penalised
  // where the nodes crowd).
  MatrixXd D = MatrixXd::Zero(std::max(n - 2, 0), nb + n);
  for (int k = 1; k + 1 < n; ++k) {
    const double h0 = e.nodes[k] - e.nodes[k - 1], h1 = e.nodes[k + 1] - e.nodes[k];
    const double h = 0.5 * (h0 + h1);
    D(k - 1, nb + k - 1) = 1.0 / (h0 * h);
    D(k - 1, nb + k) = -(1.0 / h0 + 1.0 / h1) / h;
    D(k - 1, nb + k + 1) = 1.0 / (h1 * h);
  }
  const MatrixXd ZtZ = Z.transpose() * Z;
  const VectorXd Zty = Z.transpose() * R.y;
  MatrixXd Pen = D.transpose() * D;
  const double rows = static_cast<double>(R.y.size());
  // A whisker of ridge keeps nodes the data do not reach determined by the
  // penalty alone; the scale ties lambda's grid to the data.
  const double scale = ZtZ.bottomRightCorner(n, n).trace() / std::max(Pen.trace(), 1e-300);
  const MatrixXd ridge = 1e-12 * ZtZ.trace() / (nb + n) * MatrixXd::Identity(nb + n, nb + n);
  struct Solution {
    double gcv = std::numeric_limits<double>::infinity(), lambda = 0, tr = 0, rss = 0;
    VectorXd c;
    MatrixXd Ainv;
  } best;
  for (double lg = -10.0; lg <= 4.0 + 1e-9; lg += 0.25) {
    const double lambda = scale * std::pow(10.0, lg);
    const MatrixXd A = ZtZ + lambda * Pen + ridge;
    const Eigen::LDLT<MatrixXd> ldlt(A);
    if (ldlt.info() != Eigen::Success) continue;
    const VectorXd c = ldlt.solve(Zty);
    const MatrixXd Ainv = ldlt.solve(MatrixXd::Identity(nb + n, nb + n));
    const double tr = (Ainv * ZtZ).trace();
    const double rss = (R.y - Z * c).squaredNorm();
    if (!(rows - tr > 1.0)) continue;
    const double gcv = rows * rss / ((rows - tr) * (rows - tr));
    if (gcv < best.gcv) best = {gcv, lambda, tr, rss, c, Ainv};
  }
  if (!std::isfinite(best.gcv)) throw Error("user_effects[" + std::to_string(index) + "]: the table fit is singular");
  UserFit F;
  F.index = index;
  F.lambda = best.lambda;
  F.effective_parameters = best.tr;
  // Covariance of a penalised estimate: sigma^2 A^-1 Z^T Z A^-1.
  const double sigma2 = best.rss / (rows - best.tr);
  const MatrixXd cov = sigma2 * best.Ainv * ZtZ * best.Ainv;
  ctl::UserEffect fitted = e;
  for (int k = 0; k < n; ++k) {
    fitted.values[static_cast<std::size_t>(k)] = best.c(nb + k);
    F.names.push_back("values[" + std::to_string(k) + "]");
    F.value.push_back(best.c(nb + k));
    F.std_error.push_back(std::sqrt(std::max(cov(nb + k, nb + k), 0.0)));
  }
  // Nodes beyond the data's reach are set by the penalty, not by data.
  const auto [lo, hi] = data_range(data, e.input, e.input_axis);
  int outside = 0;
  for (double x : e.nodes) outside += (x < lo || x > hi) ? 1 : 0;
  if (outside > 0) {
    std::ostringstream os;
    os << outside << " of " << n << " nodes lie outside the range the log covers on " << e.input_name() << " ["
       << lo << ", " << hi << "]: their values are the smoothness penalty's extrapolation, not measured";
    F.notes.push_back(os.str());
  }
  F.model = model;
  F.model.user_effects[static_cast<std::size_t>(index)] = fitted;
  return F;
}

UserFit fit_expression(const io::MotionData& data, const ctl::MachineModel& model, int index,
                       const MotionOptions& o) {
  const ctl::UserEffect& e = model.user_effects[static_cast<std::size_t>(index)];
  const int p = static_cast<int>(e.params.size());
  if (p == 0) throw Error("user_effects[" + std::to_string(index) + "]: the expression has no parameter to fit");
  ctl::MachineModel without = model;
  without.user_effects.erase(without.user_effects.begin() + index);
  Regression R = regression(data, without, o);
  // The nuisance projected out once: every residual below lies in its complement.
  const Eigen::ColPivHouseholderQR<MatrixXd> qr(R.B);
  const MatrixXd Q = qr.householderQ() * MatrixXd::Identity(R.B.rows(), qr.rank());
  auto project = [&](const VectorXd& x) -> VectorXd { return x - Q * (Q.transpose() * x); };
  auto residual = [&](const VectorXd& theta) -> VectorXd {
    ctl::UserEffect t = e;
    for (int j = 0; j < p; ++j) t.params[static_cast<std::size_t>(j)].value = theta(j);
    return project(R.y - R.w.cwiseProduct(R.P.user_force_column({t})));
  };
  VectorXd lower(p), upper(p), theta(p);
  for (int j = 0; j < p; ++j) {
    const auto& q = e.params[static_cast<std::size_t>(j)];
    lower(j) = q.lower;
    upper(j) = q.upper;
    theta(j) = q.value;
  }
  auto jacobian = [&](const VectorXd& th) {
    MatrixXd J(R.y.size(), p);
    for (int j = 0; j < p; ++j) {
      const double h = 1e-6 * std::max(std::abs(th(j)), 1e-3);
      VectorXd a = th, b = th;
      a(j) = std::min(th(j) + h, upper(j));
      b(j) = std::max(th(j) - h, lower(j));
      J.col(j) = (residual(a) - residual(b)) / (a(j) - b(j));
    }
    return J;
  };
  VectorXd r = residual(theta);
  double cost = r.squaredNorm(), mu = 1e-3;
  UserFit F;
  MatrixXd J = jacobian(theta);
  for (int it = 0; it < 100; ++it) {
    F.iterations = it + 1;
    const MatrixXd JtJ = J.transpose() * J;
    const VectorXd g = J.transpose() * r;
    bool improved = false;
    for (int tries = 0; tries < 30 && !improved; ++tries) {
      MatrixXd A = JtJ;
      A.diagonal() += mu * JtJ.diagonal().cwiseMax(1e-30);
      const VectorXd step = -A.ldlt().solve(g);
      const VectorXd next = (theta + step).cwiseMax(lower).cwiseMin(upper);
      const VectorXd rn = residual(next);
      if (rn.allFinite() && rn.squaredNorm() < cost) {
        const double gain = cost - rn.squaredNorm();
        theta = next;
        r = rn;
        cost = rn.squaredNorm();
        mu = std::max(mu / 3.0, 1e-12);
        improved = true;
        if (gain < 1e-12 * cost) it = 1000;  // converged
      } else {
        mu *= 4.0;
      }
    }
    if (!improved || it >= 1000) break;
    J = jacobian(theta);
  }
  J = jacobian(theta);
  const MatrixXd JtJ = J.transpose() * J;
  const Eigen::FullPivLU<MatrixXd> lu(JtJ);
  if (lu.rank() < p)
    throw Error("user_effects[" + std::to_string(index) + "]: the log does not determine the parameters of '" +
                e.formula + "' (they change the force in the same way, or not at all)");
  const double dof = static_cast<double>(R.y.size()) - p - static_cast<double>(qr.rank());
  const MatrixXd cov = cost / dof * lu.inverse();
  ctl::UserEffect fitted = e;
  for (int j = 0; j < p; ++j) {
    auto& q = fitted.params[static_cast<std::size_t>(j)];
    q.value = theta(j);
    F.names.push_back(q.name);
    F.value.push_back(theta(j));
    F.std_error.push_back(std::sqrt(std::max(cov(j, j), 0.0)));
    if (theta(j) == lower(j) || theta(j) == upper(j))
      F.notes.push_back(q.name + " stopped at its bound (" + std::to_string(theta(j)) + " " + q.unit +
                        "): the data want it further; its standard error does not hold");
  }
  F.index = index;
  F.model = model;
  F.model.user_effects[static_cast<std::size_t>(index)] = fitted;
  return F;
}

}  // namespace

ctl::UserEffect table_over_data(const io::MotionData& data, int axis, const std::string& input, int nodes) {
  if (input.size() != 2 || (input[0] != 'd' && input[0] != 'v') || input[1] < '1' || input[1] > '3')
    throw Error("table input '" + input + "': must be d1..d3 or v1..v3");
  if (nodes < 2 || nodes > ctl::kUserTableCapacity)
    throw Error("a table needs 2 to " + std::to_string(ctl::kUserTableCapacity) + " nodes");
  ctl::UserEffect e;
  e.kind = ctl::UserEffectKind::table;
  e.axis = axis;
  e.input = input[0];
  e.input_axis = input[1] - '1';
  const auto [lo, hi] = data_range(data, e.input, e.input_axis);
  if (!(hi > lo)) throw Error("the log never moves " + input + ": a table against it cannot be fitted");
  for (int k = 0; k < nodes; ++k) e.nodes.push_back(lo + (hi - lo) * k / (nodes - 1));
  e.values.assign(static_cast<std::size_t>(nodes), 0.0);
  return e;
}

UserFit fit_user_effect(const io::MotionData& data, const ctl::MachineModel& model, int index,
                        const MotionOptions& options) {
  if (index < 0 || index >= static_cast<int>(model.user_effects.size()))
    throw Error("no user effect " + std::to_string(index) + " in the model");
  UserFit F = model.user_effects[static_cast<std::size_t>(index)].kind == ctl::UserEffectKind::table
                  ? fit_table(data, model, index, options)
                  : fit_expression(data, model, index, options);
  ctl::MachineModel without = model;
  without.user_effects.erase(without.user_effects.begin() + index);
  F.rms_before = motion_rms(data, without, options);
  F.rms_after = motion_rms(data, F.model, options);
  return F;
}

}  // namespace cpm::ident
