// SPDX-License-Identifier: Apache-2.0
// The cogging fitter (candidates.hpp): a force periodic in the axis position.
// Its wavelength is searched by a periodogram of the base refit's residual
// against the position, its strongest peaks refined by golden section; the
// amplitude and phase are then linear (a sin/cos pair).
#include <algorithm>
#include <cmath>
#include <numbers>

#include "candidates.hpp"
#include "effect_search.hpp"
#include "internal.hpp"

namespace cpm::ident::detail {
namespace {

constexpr double kTwoPi = 2.0 * std::numbers::pi;

// The sin/cos pair of a unit cogging force at wavelength lambda (m).
Eigen::MatrixXd cogging_columns(const CandidateContext& ctx, double lambda) {
  return hcat({ctx.P.effect_column(ctx.with({1.0, lambda, 0.0, 0}), 0),
               ctx.P.effect_column(ctx.with({1.0, lambda, 0.5 * std::numbers::pi, 0}), 0)});
}

// The filter's amplitude response, tabulated (cycles per sample, 0..0.5).
constexpr int kResponseTable = 1024;
std::vector<double> tabulated_response(const SgKernel& filter) {
  std::vector<double> resp(kResponseTable + 1);
  for (int q = 0; q <= kResponseTable; ++q) resp[q] = filter.response(0.5 * q / kResponseTable);
  return resp;
}

// Rows of one axis: the phase of the first wavenumber and the rotation by one
// grid step (recurrence instead of a sin and cos per row and wavenumber), the
// squared weight, the residual, and the row's temporal frequency per unit
// wavenumber as an index into the response table.
struct AxisRows {
  std::vector<double> ph_c, ph_s, rot_c, rot_s, yr, wr, fper;
};

AxisRows axis_rows(const CandidateContext& ctx, double k_min, double dk) {
  const MotionProblem& P = ctx.P;
  const int R = P.rows(), axis = ctx.axis;
  const Eigen::VectorXd& yb = ctx.E.base_fit().residual;
  const Eigen::VectorXd& w = ctx.E.problem().w;
  AxisRows a;
  for (auto* v : {&a.ph_c, &a.ph_s, &a.rot_c, &a.rot_s, &a.yr, &a.wr, &a.fper}) v->resize(R);
  for (int r = 0; r < R; ++r) {
    const double x = P.d[r][axis];
    a.ph_c[r] = std::cos(kTwoPi * k_min * x);
    a.ph_s[r] = std::sin(kTwoPi * k_min * x);
    a.rot_c[r] = std::cos(kTwoPi * dk * x);
    a.rot_s[r] = std::sin(kTwoPi * dk * x);
    a.wr[r] = w(3 * r + axis) * w(3 * r + axis);
    a.yr[r] = yb(3 * r + axis);
    a.fper[r] = std::fabs(P.v[r][axis]) * P.dt * 2.0 * kResponseTable;
  }
  return a;
}

}  // namespace

Periodogram cogging_periodogram(const CandidateContext& ctx, double k_min, double k_max, double dk) {
  Periodogram pg;
  pg.k_min = k_min;
  pg.dk = dk;
  const int K = static_cast<int>((k_max - k_min) / dk) + 1;
  pg.power.resize(K);
  AxisRows a = axis_rows(ctx, k_min, dk);
  const std::vector<double> resp = tabulated_response(ctx.P.smooth_force);
  const int R = ctx.P.rows();
  for (int q = 0; q < K; ++q) {
    const double kq = k_min + q * dk;
    double cc = 0, cs = 0, ss = 0, cy = 0, sy = 0;
    for (int r = 0; r < R; ++r) {
      const double h = resp[std::min(kResponseTable, static_cast<int>(a.fper[r] * kq + 0.5))];
      const double cv = h * a.ph_c[r], sv = h * a.ph_s[r], ww = a.wr[r];
      cc += ww * cv * cv; cs += ww * cv * sv; ss += ww * sv * sv;
      cy += ww * cv * a.yr[r]; sy += ww * sv * a.yr[r];
      const double nc = a.ph_c[r] * a.rot_c[r] - a.ph_s[r] * a.rot_s[r];
      a.ph_s[r] = a.ph_s[r] * a.rot_c[r] + a.ph_c[r] * a.rot_s[r];
      a.ph_c[r] = nc;
    }
    const double det = cc * ss - cs * cs;
    pg.power[q] = det > 1e-300 ? (ss * cy * cy - 2 * cs * cy * sy + cc * sy * sy) / det : 0.0;
  }
  return pg;
}

std::vector<int> periodogram_peaks(const std::vector<double>& power, std::size_t n) {
  std::vector<double> negated(power.size());
  for (std::size_t q = 0; q < power.size(); ++q) negated[q] = -power[q];
  return lowest_local_minima(negated, n);
}

double refine_cogging_wavelength(const CandidateContext& ctx, const Periodogram& pg, const std::vector<int>& peaks,
                                 double k_max) {
  const double k_min = pg.k_min, dk = pg.dk;
  const double k = refine_grid_minima([&](double kx) { return ctx.E.rss(cogging_columns(ctx, 1.0 / kx)); }, peaks,
                                      {}, k_min, dk, k_min, k_max, 12, k_min + (peaks.empty() ? 0 : peaks[0]) * dk);
  return 1.0 / k;
}

// Wavenumbers 1/span apart give nearly independent columns.
double cogging_trials(double span, double k_min, double k_max) { return std::max(1.0, span * (k_max - k_min)); }

void fit_cogging(const CandidateContext& ctx, CandidateResult& c) {
  const ctl::EffectParameter& wavelength = ctx.effect.params[1];
  const double span = ctx.ex.span[ctx.axis];
  const double lmin = std::max(ctx.opt.cogging_lambda_min, wavelength.lower);
  const double lmax = std::min({ctx.opt.cogging_lambda_max, wavelength.upper, span / 1.5});
  if (ctx.vabs < 5e-3 || lmax <= lmin)
    return set_not_identifiable(ctx, c, "axis " + std::to_string(ctx.axis + 1) + " moves over " + fmt(span * 1e3) +
                                            " mm only: too little to see a force periodic in position (wavelength >= " +
                                            fmt(lmin * 1e3) + " mm)");
  // The grid: a quarter of the resolution 1/span, over 1/lmax..1/lmin.
  const double kmin = 1.0 / lmax, kmax = 1.0 / lmin, dk = 1.0 / (4.0 * span);
  const Periodogram pg = cogging_periodogram(ctx, kmin, kmax, dk);
  const double lambda = refine_cogging_wavelength(ctx, pg, periodogram_peaks(pg.power, 3), kmax);
  const Eigen::MatrixXd X = cogging_columns(ctx, lambda);
  const JointFit f = ctx.E.fit(X);
  const double a = std::hypot(f.beta(0), f.beta(1));
  const double phi = std::atan2(f.beta(1), f.beta(0));
  const ctl::DynamicEffect fe = ctx.with({a, lambda, phi, 0});
  const Eigen::MatrixXd jac =
      hcat({ctx.P.effect_column(fe, 0), ctx.P.effect_column(fe, 1), ctx.P.effect_column(fe, 2)});
  record_fit(ctx, c, X, f, jac, {a, lambda, phi}, true);
  c.trials = cogging_trials(span, kmin, kmax);
}

}  // namespace cpm::ident::detail
