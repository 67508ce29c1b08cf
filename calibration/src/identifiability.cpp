// SPDX-License-Identifier: Apache-2.0
#include "cpm/calibration/identifiability.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>

#include "cpm/kinematics/types.hpp"

namespace cpm::cal {
namespace {

// Regularised incomplete beta function I_x(a, b), by its continued fraction
// (modified Lentz), for the Student t distribution.
double beta_cf(double a, double b, double x) {
  const double tiny = 1e-300;
  double c = 1.0, d = 1.0 - (a + b) * x / (a + 1.0);
  if (std::abs(d) < tiny) d = tiny;
  d = 1.0 / d;
  double h = d;
  for (int m = 1; m <= 500; ++m) {
    const double m2 = 2.0 * m;
    double aa = m * (b - m) * x / ((a + m2 - 1.0) * (a + m2));
    d = 1.0 + aa * d;
    if (std::abs(d) < tiny) d = tiny;
    c = 1.0 + aa / c;
    if (std::abs(c) < tiny) c = tiny;
    d = 1.0 / d;
    h *= d * c;
    aa = -(a + m) * (a + b + m) * x / ((a + m2) * (a + m2 + 1.0));
    d = 1.0 + aa * d;
    if (std::abs(d) < tiny) d = tiny;
    c = 1.0 + aa / c;
    if (std::abs(c) < tiny) c = tiny;
    d = 1.0 / d;
    const double del = d * c;
    h *= del;
    if (std::abs(del - 1.0) < 1e-15) break;
  }
  return h;
}

double incomplete_beta(double a, double b, double x) {
  if (x <= 0.0) return 0.0;
  if (x >= 1.0) return 1.0;
  const double lbt = std::lgamma(a + b) - std::lgamma(a) - std::lgamma(b) + a * std::log(x) +
                     b * std::log(1.0 - x);
  if (x < (a + 1.0) / (a + b + 2.0)) return std::exp(lbt) * beta_cf(a, b, x) / a;
  return 1.0 - std::exp(lbt) * beta_cf(b, a, 1.0 - x) / b;
}

// P(|T| <= t) for Student's t with nu degrees of freedom.
double t_two_sided(double t, double nu) {
  return 1.0 - incomplete_beta(0.5 * nu, 0.5, nu / (nu + t * t));
}

}  // namespace

double student_t_quantile(double confidence, int dof) {
  if (!(confidence > 0.0 && confidence < 1.0)) throw Error("confidence must be within (0, 1)");
  if (dof < 1) return std::numeric_limits<double>::infinity();
  double lo = 0.0, hi = 1.0;
  while (t_two_sided(hi, dof) < confidence) hi *= 2.0;
  for (int i = 0; i < 200 && hi - lo > 1e-12 * hi; ++i) {
    const double mid = 0.5 * (lo + hi);
    (t_two_sided(mid, dof) < confidence ? lo : hi) = mid;
  }
  return 0.5 * (lo + hi);
}

int Identifiability::index(const std::string& name) const {
  for (std::size_t i = 0; i < names.size(); ++i)
    if (names[i] == name) return static_cast<int>(i);
  return -1;
}

std::string Identifiability::describe_combination(const WeakCombination& w) const {
  std::string s;
  for (const auto& [j, c] : w.terms) {
    char buf[96];
    std::snprintf(buf, sizeof buf, "%s%+.2f %s", s.empty() ? "" : " ", c, names[j].c_str());
    s += buf;
  }
  return s;
}

Identifiability analyse_identifiability(const MatX& J, const VecX& r, const VecX& x,
                                        std::vector<std::string> names,
                                        std::vector<std::string> units,
                                        const IdentifiabilityOptions& o) {
  const Eigen::Index N = J.rows(), P = J.cols();
  if (r.size() != N || x.size() != P || static_cast<Eigen::Index>(names.size()) != P ||
      static_cast<Eigen::Index>(units.size()) != P)
    throw Error("identifiability: sizes of J, r, x and the parameter names disagree");
  Identifiability id;
  id.names = std::move(names);
  id.units = std::move(units);
  id.value = x;
  id.observations = static_cast<int>(N);
  id.dof = static_cast<int>(N - P);
  id.confidence = o.confidence;
  const double ssr = r.squaredNorm();
  id.residual_rms = N > 0 ? std::sqrt(ssr / static_cast<double>(N)) : 0.0;
  id.residual_sigma = id.dof > 0 ? std::sqrt(ssr / id.dof) : std::numeric_limits<double>::quiet_NaN();
  if (id.dof < 1)
    id.warnings.push_back("as many parameters as measurements (" + std::to_string(N) +
                          "): no residual is left to estimate the noise, so no standard error "
                          "can be given; measure more poses");

  // Scale columns to unit length: the singular values then compare directions, not units.
  VecX scale = J.colwise().norm().transpose();
  for (Eigen::Index j = 0; j < P; ++j)
    if (!(scale[j] > 0.0)) scale[j] = 1.0;
  const MatX Js = J * scale.cwiseInverse().asDiagonal();
  Eigen::JacobiSVD<MatX> svd(Js, Eigen::ComputeThinV);
  id.singular_values = svd.singularValues();
  const double smax = id.singular_values.size() ? id.singular_values[0] : 0.0;
  const double smin = id.singular_values.size() ? id.singular_values[P - 1] : 0.0;
  id.condition_number = smin > o.undetermined_threshold * smax ? smax / smin
                                                                : std::numeric_limits<double>::infinity();
  // Covariance by the pseudo-inverse: undetermined directions are left out
  // and the parameters they touch get an infinite standard error.
  const MatX& V = svd.matrixV();
  MatX inv_s = MatX::Zero(P, P);
  std::vector<bool> touched(static_cast<std::size_t>(P), false);
  for (Eigen::Index k = 0; k < P; ++k) {
    const double rel = smax > 0.0 ? id.singular_values[k] / smax : 0.0;
    if (rel > o.undetermined_threshold) {
      inv_s(k, k) = 1.0 / (id.singular_values[k] * id.singular_values[k]);
    }
    if (rel < o.weak_threshold) {
      WeakCombination w;
      w.relative_singular_value = rel;
      w.undetermined = rel <= o.undetermined_threshold;
      VecX v = V.col(k);
      v /= v.cwiseAbs().maxCoeff();
      for (Eigen::Index j = 0; j < P; ++j) {
        if (std::abs(v[j]) >= 0.1) w.terms.emplace_back(static_cast<int>(j), v[j]);
        if (w.undetermined && std::abs(v[j]) >= 1e-3) touched[static_cast<std::size_t>(j)] = true;
      }
      std::sort(w.terms.begin(), w.terms.end(),
                [](const auto& a, const auto& b) { return std::abs(a.second) > std::abs(b.second); });
      id.weak.push_back(std::move(w));
    }
  }
  const double s2 = id.dof > 0 ? ssr / id.dof : std::numeric_limits<double>::quiet_NaN();
  const MatX cov_scaled = V * inv_s * V.transpose();
  id.covariance = s2 * scale.cwiseInverse().asDiagonal() * cov_scaled * scale.cwiseInverse().asDiagonal();
  id.std_error = id.covariance.diagonal().cwiseMax(0.0).cwiseSqrt();
  for (Eigen::Index j = 0; j < P; ++j)
    if (touched[static_cast<std::size_t>(j)]) id.std_error[j] = std::numeric_limits<double>::infinity();
  id.t_quantile = student_t_quantile(o.confidence, id.dof);
  id.ci_low = x - id.t_quantile * id.std_error;
  id.ci_high = x + id.t_quantile * id.std_error;
  id.correlation = MatX::Identity(P, P);
  for (Eigen::Index a = 0; a < P; ++a)
    for (Eigen::Index b = 0; b < P; ++b) {
      const double den = std::sqrt(cov_scaled(a, a) * cov_scaled(b, b));
      if (a != b) id.correlation(a, b) = den > 0.0 ? cov_scaled(a, b) / den : 0.0;
    }
  for (Eigen::Index a = 0; a < P; ++a)
    for (Eigen::Index b = a + 1; b < P; ++b)
      if (std::abs(id.correlation(a, b)) >= o.strong_correlation)
        id.strong_pairs.push_back({static_cast<int>(a), static_cast<int>(b), id.correlation(a, b)});
  std::sort(id.strong_pairs.begin(), id.strong_pairs.end(), [](const auto& p, const auto& q) {
    return std::abs(p.correlation) > std::abs(q.correlation);
  });
  // Multiple correlation of each column with all the others:
  // 1 - R_j^2 = 1 / ((Js^T Js)^-1)_jj for unit columns.
  id.multiple_correlation = VecX::Ones(P);
  for (Eigen::Index j = 0; j < P; ++j) {
    const double cjj = cov_scaled(j, j);
    if (cjj > 0.0 && !touched[static_cast<std::size_t>(j)])
      id.multiple_correlation[j] = std::sqrt(std::max(0.0, 1.0 - 1.0 / cjj));
  }
  for (const WeakCombination& w : id.weak) {
    char buf[160];
    std::snprintf(buf, sizeof buf, " (relative singular value %.2e)", w.relative_singular_value);
    id.warnings.push_back(std::string(w.undetermined ? "cannot be determined from these data: "
                                                     : "poorly determined by these data: ") +
                          "the combination " + id.describe_combination(w) + buf);
  }
  for (Eigen::Index j = 0; j < P; ++j) {
    if (!touched[static_cast<std::size_t>(j)] && id.multiple_correlation[j] >= o.inseparable_correlation) {
      char buf[200];
      std::snprintf(buf, sizeof buf,
                    "%s can hardly be separated from the other parameters (multiple correlation "
                    "%.6f): its standard error is inflated %.0f times",
                    id.names[j].c_str(), id.multiple_correlation[j],
                    std::sqrt(cov_scaled(j, j)));
      id.warnings.push_back(buf);
    }
  }
  return id;
}

}  // namespace cpm::cal
