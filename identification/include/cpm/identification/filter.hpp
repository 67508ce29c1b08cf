// SPDX-License-Identifier: Apache-2.0
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

// Under a zero-order hold the acceleration is a_j over [t_j, t_j+1), and an
// acceleration estimate made from sampled velocities (derivative = 1: the
// kernel applied to v, times 1/dt) or positions (derivative = 2: applied to
// d, times 1/dt^2) is exactly a weighted sum of those interval accelerations:
//     a_hat_k = sum_j g_j a_{k+j},   j = -m .. m-1.
// zoh_force_kernel returns g (h[j+m] multiplies the value held over interval
// k+j; the last weight is 0). Filtering the commanded forces with g makes
// them consistent with a_hat whatever the motion's frequency content (the
// sharp force of friction at a reversal included), where a smoother of its
// own would differ from the estimator beyond the polynomial degree.
SgKernel zoh_force_kernel(const SgKernel& accel_estimator, int derivative);
// The same weights for a force that acts continuously (an effect evaluated
// at the samples): each interval's mean taken as the mean of its two ends.
SgKernel zoh_state_kernel(const SgKernel& force_kernel);

}  // namespace cpm::ident
