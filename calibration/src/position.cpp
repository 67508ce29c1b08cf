// SPDX-License-Identifier: Apache-2.0
#include "cpm/calibration/position.hpp"

#include <cmath>
#include <cstdio>

namespace cpm::cal {
namespace {

std::string mm(double v) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.3f mm", v * 1e3);
  return buf;
}

std::string direction(const Vec3& v) {
  char buf[64];
  // Sign-normalised so that the largest component is positive.
  Eigen::Index k;
  v.cwiseAbs().maxCoeff(&k);
  Vec3 u = v[k] < 0.0 ? Vec3(-v) : v;
  u = u.unaryExpr([](double x) { return std::abs(x) < 5e-3 ? 0.0 : x; });  // no "-0.00"
  std::snprintf(buf, sizeof buf, "(%.2f, %.2f, %.2f)", u.x(), u.y(), u.z());
  return buf;
}

// Parameters <-> planes.
std::array<kin::LimbPlane, 3> planes_from(const VecX& x) {
  std::array<kin::LimbPlane, 3> pl;
  for (int i = 0; i < 3; ++i) {
    pl[i].normal = normal_from_tilts(i, x[4 * i], x[4 * i + 1]);
    pl[i].scale = x[4 * i + 2];
    pl[i].offset = x[4 * i + 3];
  }
  return pl;
}

VecX params_from(const std::array<kin::LimbPlane, 3>& pl) {
  VecX x(12);
  for (int i = 0; i < 3; ++i) {
    tilts_from_normal(i, pl[i].normal, x[4 * i], x[4 * i + 1]);
    x[4 * i + 2] = pl[i].scale;
    x[4 * i + 3] = pl[i].offset;
  }
  return x;
}

}  // namespace

std::array<int, 2> other_axes(int limb) {
  return {limb == 0 ? 1 : 0, limb == 2 ? 1 : 2};
}

Vec3 normal_from_tilts(int limb, double t_a, double t_b, Eigen::Matrix<double, 3, 2>* d_dt) {
  const auto [a, b] = other_axes(limb);
  Vec3 v = Vec3::Unit(limb);
  v[a] = std::tan(t_a);
  v[b] = std::tan(t_b);
  const double n = v.norm();
  const Vec3 u = v / n;
  if (d_dt) {
    const Mat3 P = (Mat3::Identity() - u * u.transpose()) / n;
    const double ca = std::cos(t_a), cb = std::cos(t_b);
    d_dt->col(0) = P.col(a) / (ca * ca);
    d_dt->col(1) = P.col(b) / (cb * cb);
  }
  return u;
}

void tilts_from_normal(int limb, const Vec3& u, double& t_a, double& t_b) {
  const auto [a, b] = other_axes(limb);
  t_a = std::atan2(u[a], u[limb]);
  t_b = std::atan2(u[b], u[limb]);
}

PoseSpread pose_spread(const std::vector<Vec3>& p) {
  PoseSpread s;
  if (p.empty()) return s;
  Vec3 mean = Vec3::Zero();
  for (const Vec3& q : p) mean += q;
  mean /= static_cast<double>(p.size());
  Mat3 C = Mat3::Zero();
  for (const Vec3& q : p) C += (q - mean) * (q - mean).transpose();
  C /= static_cast<double>(p.size());
  Eigen::SelfAdjointEigenSolver<Mat3> es(C);
  for (int k = 0; k < 3; ++k) {  // eigenvalues ascending -> descending
    s.extent[k] = std::sqrt(std::max(0.0, es.eigenvalues()[2 - k]));
    s.directions.col(k) = es.eigenvectors().col(2 - k);
  }
  return s;
}

AnalyticSolution solve_positions_analytic(const std::vector<Vec3>& d, const std::vector<Vec3>& p,
                                          const Vec3& d0, const PositionOptions& o) {
  const std::size_t N = p.size();
  if (d.size() != N) throw Error("full-position calibration: as many actuator readings as positions needed");
  if (N < 4)
    throw DegeneratePoses("full-position calibration needs at least 4 poses (Kim eq. 13: three "
                          "differences per limb), got " + std::to_string(N) +
                          "; add poses that span all three axes");
  const PoseSpread spread = pose_spread(p);
  auto degenerate_advice = [&]() {
    std::string why;
    if (spread.extent[1] < spread.extent[0] / o.refuse_condition)
      why = "the poses lie (nearly) on a line along " + direction(spread.directions.col(0)) +
            " (spread " + mm(spread.extent[0]) + " along it, " + mm(spread.extent[1]) +
            " across); add poses displaced from that line along " +
            direction(spread.directions.col(1)) + " and " + direction(spread.directions.col(2)) +
            " by at least " + mm(spread.extent[0] / o.warn_condition) + " each";
    else
      why = "the poses lie (nearly) in one plane: their RMS spread along " +
            direction(spread.directions.col(2)) + " is " + mm(spread.extent[2]) + " against " +
            mm(spread.extent[0]) + " along " + direction(spread.directions.col(0)) +
            "; add poses displaced along " + direction(spread.directions.col(2)) +
            " by at least " + mm(spread.extent[0] / o.warn_condition) + " on both sides";
    return why;
  };
  AnalyticSolution sol;
  Vec3 pm = Vec3::Zero(), dm = Vec3::Zero();
  for (std::size_t j = 0; j < N; ++j) {
    pm += p[j];
    dm += d[j];
  }
  pm /= static_cast<double>(N);
  dm /= static_cast<double>(N);
  for (int i = 0; i < 3; ++i) {
    const auto [a, b] = other_axes(i);
    // Kim eq. 12 divided by u_i's own component (the large one) and written
    // for every pose's difference from the mean (eq. 13 with n the mean):
    //   [dp_a, dp_b, -dd_i] (u_a/u_i, u_b/u_i, c_i/u_i)^T = -dp_i
    MatX A(N, 3);
    VecX rhs(N);
    for (std::size_t j = 0; j < N; ++j) {
      const Vec3 dp = p[j] - pm;
      A(static_cast<Eigen::Index>(j), 0) = dp[a];
      A(static_cast<Eigen::Index>(j), 1) = dp[b];
      A(static_cast<Eigen::Index>(j), 2) = -(d[j][i] - dm[i]);
      rhs[static_cast<Eigen::Index>(j)] = -dp[i];
    }
    Eigen::JacobiSVD<MatX> svd(A, Eigen::ComputeThinU | Eigen::ComputeThinV);
    const auto& s = svd.singularValues();
    const double cond = s[2] > 0.0 ? s[0] / s[2] : INFINITY;
    sol.condition[i] = cond;
    if (!(cond <= o.refuse_condition)) {
      char buf[96];
      std::snprintf(buf, sizeof buf, "the matrix of Kim's eq. 13 for limb %d is %s (condition %.3g)",
                    i + 1, std::isfinite(cond) ? "badly conditioned" : "singular", cond);
      throw DegeneratePoses(std::string("full-position calibration refused: ") + buf + ": " +
                            degenerate_advice());
    }
    if (cond > o.warn_condition) {
      char buf[128];
      std::snprintf(buf, sizeof buf, "limb %d: the poses determine the plane poorly (condition %.1f of Kim's eq. 13): ",
                    i + 1, cond);
      sol.warnings.push_back(buf + degenerate_advice());
    }
    const Vec3 k = svd.solve(rhs);
    Vec3 v = Vec3::Unit(i);
    v[a] = k[0];
    v[b] = k[1];
    const double un = v.norm();
    kin::LimbPlane& pl = sol.planes[i];
    pl.normal = v / un;         // u_i
    pl.scale = k[2] / un;       // c_i = (c_i/u_i) u_i
    // n_i from eq. 10 averaged over the poses.
    pl.offset = pl.normal.dot(pm) - (dm[i] + d0[i]) * pl.scale;
  }
  return sol;
}

std::vector<std::string> position_parameter_names() {
  // Built with snprintf: GCC 12 warns falsely (-Wrestrict) on short string concatenations.
  std::vector<std::string> n;
  const char* ax = "xyz";
  char buf[32];
  for (int i = 0; i < 3; ++i) {
    const auto [a, b] = other_axes(i);
    std::snprintf(buf, sizeof buf, "limb%d.tilt_%c", i + 1, ax[a]);
    n.emplace_back(buf);
    std::snprintf(buf, sizeof buf, "limb%d.tilt_%c", i + 1, ax[b]);
    n.emplace_back(buf);
    std::snprintf(buf, sizeof buf, "c%d", i + 1);
    n.emplace_back(buf);
    std::snprintf(buf, sizeof buf, "n%d", i + 1);
    n.emplace_back(buf);
  }
  return n;
}

std::vector<std::string> position_parameter_units() {
  std::vector<std::string> u;
  for (int i = 0; i < 3; ++i) u.insert(u.end(), {"rad", "rad", "1", "m"});
  return u;
}

void position_residuals(const std::array<kin::LimbPlane, 3>& planes, const Vec3& d0,
                        const std::vector<Vec3>& d, const std::vector<Vec3>& p, VecX& r, MatX* J) {
  const Eigen::Index N = static_cast<Eigen::Index>(p.size());
  r.resize(3 * N);
  if (J) J->setZero(3 * N, 12);
  Mat3 U;
  std::array<Eigen::Matrix<double, 3, 2>, 3> du{};
  for (int i = 0; i < 3; ++i) {
    double ta, tb;
    tilts_from_normal(i, planes[i].normal, ta, tb);
    U.row(i) = normal_from_tilts(i, ta, tb, &du[i]).transpose();
  }
  const double det = U.determinant();
  if (!(std::abs(det) > 1e-6)) throw Error("full-position calibration: the limb planes became parallel");
  const Mat3 W = U.inverse();
  for (Eigen::Index j = 0; j < N; ++j) {
    const Vec3& dj = d[static_cast<std::size_t>(j)];
    Vec3 b;
    for (int i = 0; i < 3; ++i) b[i] = (dj[i] + d0[i]) * planes[i].scale + planes[i].offset;
    const Vec3 pc = W * b;
    r.segment<3>(3 * j) = pc - p[static_cast<std::size_t>(j)];
    if (!J) continue;
    // p = U^-1 b:  dp = U^-1 (db - dU p), row i of U and entry i of b per limb.
    for (int i = 0; i < 3; ++i) {
      const Vec3 w = W.col(i);
      J->block<3, 1>(3 * j, 4 * i) = -w * du[i].col(0).dot(pc);
      J->block<3, 1>(3 * j, 4 * i + 1) = -w * du[i].col(1).dot(pc);
      J->block<3, 1>(3 * j, 4 * i + 2) = w * (dj[i] + d0[i]);
      J->block<3, 1>(3 * j, 4 * i + 3) = w;
    }
  }
}

PositionFit fit_positions(const kin::KinematicModel& start, const std::vector<Vec3>& d,
                          const std::vector<Vec3>& p, const PositionOptions& o) {
  for (std::size_t j = 0; j < p.size(); ++j)
    if (!p[j].allFinite() || j >= d.size() || !d[j].allFinite())
      throw Error("full-position calibration: pose " + std::to_string(j + 1) + " is not finite");
  PositionFit fit;
  fit.analytic = solve_positions_analytic(d, p, start.d0, o);
  fit.warnings = fit.analytic.warnings;
  VecX x = params_from(fit.analytic.planes);
  const Vec3 d0 = start.d0;
  const ResidualFunction f = [&](const VecX& xv, VecX& r, MatX* J) {
    position_residuals(planes_from(xv), d0, d, p, r, J);
  };
  fit.lm = levenberg_marquardt(f, x, o.lm);
  if (!fit.lm.converged)
    fit.warnings.push_back("the nonlinear least squares did not converge: " + fit.lm.reason);
  VecX r;
  MatX J;
  f(x, r, &J);
  fit.identifiability = analyse_identifiability(J, r, x, position_parameter_names(),
                                                position_parameter_units(), o.identifiability);
  const Identifiability& id = fit.identifiability;
  fit.warnings.insert(fit.warnings.end(), id.warnings.begin(), id.warnings.end());
  if (o.sigma > 0.0 && id.dof > 0 && id.residual_sigma > 3.0 * o.sigma) {
    char buf[320];
    std::snprintf(buf, sizeof buf,
                  "the residuals (%.2f µm per coordinate) are %.1f times the instrument's sigma "
                  "(%.2f µm): the plane model does not explain these data; look for a kinematic "
                  "effect (backlash, guide errors) or a bad measurement",
                  id.residual_sigma * 1e6, id.residual_sigma / o.sigma, o.sigma * 1e6);
    fit.warnings.push_back(buf);
  }
  fit.model = start;
  const auto planes = planes_from(x);
  for (int i = 0; i < 3; ++i) {
    fit.model.planes[i] = planes[i];
    Eigen::Matrix<double, 3, 2> du;
    normal_from_tilts(i, x[4 * i], x[4 * i + 1], &du);
    const Eigen::Matrix2d C = id.covariance.block<2, 2>(4 * i, 4 * i);
    fit.normal_std_error[i] = (du * C * du.transpose()).diagonal().cwiseMax(0.0).cwiseSqrt();
    if (!std::isfinite(id.std_error[4 * i]) || !std::isfinite(id.std_error[4 * i + 1]))
      fit.normal_std_error[i].setConstant(INFINITY);
  }
  fit.model.validate();
  return fit;
}

}  // namespace cpm::cal
