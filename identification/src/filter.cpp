// SPDX-License-Identifier: Apache-2.0
#include "cpm/identification/filter.hpp"

#include <cmath>
#include <numbers>

#include <Eigen/Dense>

#include "cpm/kinematics/types.hpp"

namespace cpm::ident {

double SgKernel::noise_gain() const noexcept {
  double s = 0.0;
  for (double x : h) s += x * x;
  return std::sqrt(s);
}

double SgKernel::response(double f) const noexcept {
  double re = 0.0, im = 0.0;
  for (int j = -half_width; j <= half_width; ++j) {
    re += h[j + half_width] * std::cos(2.0 * std::numbers::pi * f * j);
    im += h[j + half_width] * std::sin(2.0 * std::numbers::pi * f * j);
  }
  return std::hypot(re, im);
}

SgKernel savitzky_golay(int half_width, int order, int derivative, double offset) {
  if (half_width < 1 || order < 0 || order >= 2 * half_width + 1 || derivative < 0 ||
      derivative > order || derivative > 2)
    throw Error("Savitzky-Golay kernel: need 0 <= derivative <= order < 2m+1 (m = " +
                std::to_string(half_width) + ", order " + std::to_string(order) + ")");
  const int n = 2 * half_width + 1;
  const double m = half_width;
  // Abscissa scaled to [-1, 1] for conditioning.
  Eigen::MatrixXd V(n, order + 1);
  for (int j = 0; j < n; ++j) {
    const double u = (j - half_width) / m;
    double p = 1.0;
    for (int l = 0; l <= order; ++l, p *= u) V(j, l) = p;
  }
  // e_l = d^r/du^r u^l at u0, then /m^r for per-sample units.
  const double u0 = offset / m;
  Eigen::VectorXd e = Eigen::VectorXd::Zero(order + 1);
  for (int l = derivative; l <= order; ++l) {
    double c = 1.0;
    for (int q = 0; q < derivative; ++q) c *= (l - q);
    e(l) = c * std::pow(u0, l - derivative);
  }
  e /= std::pow(m, derivative);
  const Eigen::MatrixXd VtV = V.transpose() * V;
  const Eigen::VectorXd h = V * VtV.ldlt().solve(e);
  SgKernel k;
  k.half_width = half_width;
  k.h.assign(h.data(), h.data() + n);
  return k;
}

SgKernel zoh_force_kernel(const SgKernel& est, int derivative) {
  if (derivative != 1 && derivative != 2) throw Error("zoh_force_kernel: derivative must be 1 or 2");
  const int m = est.half_width;
  SgKernel g;
  g.half_width = m;
  g.h.assign(static_cast<std::size_t>(2 * m + 1), 0.0);
  // A unit acceleration over interval j only, from rest (units dt = 1): the
  // velocity is 1 at every sample after it, the position 1/2 at its end and
  // then grows by 1 per sample.
  for (int j = -m; j < m; ++j) {
    double a_hat = 0.0;
    for (int i = j + 1; i <= m; ++i)
      a_hat += est.h[static_cast<std::size_t>(i + m)] * (derivative == 1 ? 1.0 : (i - j) - 0.5);
    g.h[static_cast<std::size_t>(j + m)] = a_hat;
  }
  return g;
}

SgKernel zoh_state_kernel(const SgKernel& force) {
  const int m = force.half_width;
  SgKernel s;
  s.half_width = m;
  s.h.assign(static_cast<std::size_t>(2 * m + 1), 0.0);
  for (int i = -m; i <= m; ++i) {
    const double left = i > -m ? force.h[static_cast<std::size_t>(i - 1 + m)] : 0.0;  // interval i-1 ends at i
    const double right = force.h[static_cast<std::size_t>(i + m)];                     // interval i starts at i
    s.h[static_cast<std::size_t>(i + m)] = 0.5 * (left + right);
  }
  return s;
}

}  // namespace cpm::ident
