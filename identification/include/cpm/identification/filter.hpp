// Zero-phase Savitzky-Golay kernels: a polynomial of degree `order` fitted by
// least squares to the 2m+1 samples around sample k, evaluated (or
// differentiated) at k + offset. Offset 0.5 evaluates half a sample later,
// which the motion pipeline uses to line the state up with the force that a
// zero-order hold applied over [t_k, t_k+1).
#pragma once

#include <vector>

namespace cpm::ident {

struct SgKernel {
  int half_width = 0;          // m: the kernel spans samples k-m .. k+m
  std::vector<double> h;       // 2m+1 weights, h[j+m] multiplies y[k+j]
  // sum_j h_j y_{k+j}; for derivatives divide by dt^r yourself.
  [[nodiscard]] double apply(const double* y_centre, int stride = 1) const noexcept {
    double s = 0.0;
    for (int j = -half_width; j <= half_width; ++j) s += h[j + half_width] * y_centre[j * stride];
    return s;
  }
  // sqrt(sum h^2): the factor by which white noise of the input is scaled.
  [[nodiscard]] double noise_gain() const noexcept;
  // Amplitude response at f cycles per sample (0..0.5), zero-offset kernels.
  [[nodiscard]] double response(double f) const noexcept;
};

// derivative: 0 (smoothing), 1 or 2 (per sample^r; divide by dt^r).
// Throws Error when order >= 2m+1 or derivative > order.
SgKernel savitzky_golay(int half_width, int order, int derivative, double offset = 0.0);

}  // namespace cpm::ident
