// SPDX-License-Identifier: Apache-2.0
// The few statistics the diagnosis needs: F and chi-square tail
// probabilities, an effective sample size for correlated residuals, robust
// noise estimates.
#pragma once

#include <vector>

namespace cpm::ident {

// Regularised incomplete beta I_x(a, b).
double incomplete_beta(double a, double b, double x);
// P(F > f) for the F distribution with (d1, d2) degrees of freedom.
double f_tail(double f, double d1, double d2);
// Normal upper tail P(Z > z).
double normal_tail(double z);

// Effective number of independent samples in a residual series with
// autocorrelation: n (1 - rho1) / (1 + rho1), rho1 the lag-1 autocorrelation
// (computed per segment in `series`, pooled), clamped to [n/50, n].
double effective_samples(const std::vector<std::vector<double>>& series);

// sigma of white noise in a series from its second differences, robust to
// slow structure and a few steps: 1.4826 MAD(diff2) / sqrt(6). With lag L
// the second differences are x[k+2L] - 2 x[k+L] + x[k] (noise correlated
// over fewer than L samples is then white to them).
double noise_from_differences(const std::vector<double>& x, int lag = 1);

double median(std::vector<double> x);

}  // namespace cpm::ident
