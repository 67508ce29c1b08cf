// SPDX-License-Identifier: Apache-2.0
#include "cpm/identification/stats.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

namespace cpm::ident {
namespace {

// Continued fraction of the incomplete beta (modified Lentz).
double beta_cf(double a, double b, double x) {
  constexpr double tiny = 1e-300, eps = 1e-15;
  const double qab = a + b, qap = a + 1.0, qam = a - 1.0;
  double c = 1.0, d = 1.0 - qab * x / qap;
  if (std::fabs(d) < tiny) d = tiny;
  d = 1.0 / d;
  double h = d;
  for (int m = 1; m <= 500; ++m) {
    const int m2 = 2 * m;
    double aa = m * (b - m) * x / ((qam + m2) * (a + m2));
    d = 1.0 + aa * d;
    if (std::fabs(d) < tiny) d = tiny;
    c = 1.0 + aa / c;
    if (std::fabs(c) < tiny) c = tiny;
    d = 1.0 / d;
    h *= d * c;
    aa = -(a + m) * (qab + m) * x / ((a + m2) * (qap + m2));
    d = 1.0 + aa * d;
    if (std::fabs(d) < tiny) d = tiny;
    c = 1.0 + aa / c;
    if (std::fabs(c) < tiny) c = tiny;
    d = 1.0 / d;
    const double del = d * c;
    h *= del;
    if (std::fabs(del - 1.0) < eps) break;
  }
  return h;
}

}  // namespace

double incomplete_beta(double a, double b, double x) {
  if (x <= 0.0) return 0.0;
  if (x >= 1.0) return 1.0;
  const double lbt = std::lgamma(a + b) - std::lgamma(a) - std::lgamma(b) + a * std::log(x) +
                     b * std::log1p(-x);
  if (x < (a + 1.0) / (a + b + 2.0)) return std::exp(lbt) * beta_cf(a, b, x) / a;
  return 1.0 - std::exp(lbt) * beta_cf(b, a, 1.0 - x) / b;
}

double f_tail(double f, double d1, double d2) {
  if (!(f > 0.0)) return 1.0;
  if (!std::isfinite(f)) return 0.0;
  return incomplete_beta(0.5 * d2, 0.5 * d1, d2 / (d2 + d1 * f));
}

double normal_tail(double z) { return 0.5 * std::erfc(z / std::sqrt(2.0)); }

double effective_samples(const std::vector<std::vector<double>>& series) {
  double num = 0.0, den = 0.0;
  std::size_t n = 0;
  for (const auto& s : series) {
    if (s.size() < 3) continue;
    double mean = 0.0;
    for (double x : s) mean += x;
    mean /= static_cast<double>(s.size());
    for (std::size_t k = 0; k < s.size(); ++k) {
      den += (s[k] - mean) * (s[k] - mean);
      if (k > 0) num += (s[k] - mean) * (s[k - 1] - mean);
    }
    n += s.size();
  }
  if (n == 0) return 0.0;
  const double rho = den > 0.0 ? std::clamp(num / den, 0.0, 0.98) : 0.0;
  const double ne = static_cast<double>(n) * (1.0 - rho) / (1.0 + rho);
  return std::clamp(ne, static_cast<double>(n) / 50.0, static_cast<double>(n));
}

double median(std::vector<double> x) {
  if (x.empty()) return std::numeric_limits<double>::quiet_NaN();
  const auto mid = x.begin() + static_cast<long>(x.size() / 2);
  std::nth_element(x.begin(), mid, x.end());
  return *mid;
}

double noise_from_differences(const std::vector<double>& x, int lag) {
  const auto L = static_cast<std::size_t>(std::max(1, lag));
  if (x.size() < 2 * L + 3) return 0.0;
  std::vector<double> d2(x.size() - 2 * L);
  for (std::size_t k = 0; k + 2 * L < x.size(); ++k) d2[k] = std::fabs(x[k + 2 * L] - 2.0 * x[k + L] + x[k]);
  return 1.4826 * median(std::move(d2)) / std::sqrt(6.0);
}

}  // namespace cpm::ident
