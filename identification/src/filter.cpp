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

}  // namespace cpm::ident
