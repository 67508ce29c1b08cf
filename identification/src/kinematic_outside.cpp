// SPDX-License-Identifier: Apache-2.0
// Kinematic data in the open world (kinematic_stages.hpp): the noise floor
// from the data's own repeatability, a smooth non-periodic error of an axis'
// reading (a lead screw's pitch error growing along the stroke), the
// verdict's rule that names a library effect only when nothing significant is
// left, and the pitch table that would describe what is.
//
// Why: a pitch error growing along one axis was named a cyclic error of
// 1.2 mm wavelength on position data, and a guide error, a cyclic error and a
// limb twist on other axes on ball-bar data, because the floor was taken
// from what those candidates left (1.19 µm for a bar whose noise was 0.29 µm).
#include <algorithm>
#include <cmath>
#include <limits>
#include <numbers>
#include <numeric>

#include "cpm/calibration/workflow.hpp"
#include "cpm/identification/kinematic.hpp"
#include "cpm/identification/model_loop.hpp"
#include "kinematic_internal.hpp"

namespace cpm::ident {

using namespace kinematic_detail;
using detail::hcat;

// ---------------------------------------------------------------------------
// The noise floor

double repeated_pose_sigma(const KinematicProblem& P, const Eigen::VectorXd& r, int* poses) {
  constexpr double kSame = 1e-6;  // m: readings of one pose measured again
  const int n = P.samples();
  std::vector<int> order(static_cast<std::size_t>(n));
  std::iota(order.begin(), order.end(), 0);
  std::sort(order.begin(), order.end(), [&](int a, int b) { return P.d[a][0] < P.d[b][0]; });
  auto same = [&](int a, int b) {
    if ((P.d[a] - P.d[b]).cwiseAbs().maxCoeff() > kSame) return false;
    return !P.has_dir || P.inputs[a].dir == P.inputs[b].dir;
  };
  std::vector<char> taken(static_cast<std::size_t>(n), 0);
  double ss = 0.0;
  long dof = 0;
  int repeated = 0;
  for (int s = 0; s < n; ++s) {
    const int a = order[s];
    if (taken[a]) continue;
    std::vector<int> g{a};
    for (int u = s + 1; u < n && P.d[order[u]][0] - P.d[a][0] <= kSame; ++u)
      if (!taken[order[u]] && same(a, order[u])) g.push_back(order[u]);
    for (int j : g) taken[j] = 1;
    if (g.size() < 2) continue;
    ++repeated;
    for (int c = 0; c < P.per_sample; ++c) {
      double m = 0.0;
      for (int j : g) m += r(P.per_sample * j + c);
      m /= static_cast<double>(g.size());
      for (int j : g) ss += std::pow(r(P.per_sample * j + c) - m, 2);
      dof += static_cast<long>(g.size()) - 1;
    }
  }
  if (poses) *poses = repeated;
  return dof >= 5 ? std::sqrt(ss / static_cast<double>(dof)) : 0.0;
}

double local_high_band_sigma(const KinematicProblem& P, const Eigen::VectorXd& r, int k, int degree) {
  const int n = P.samples();
  if (P.per_sample != 1 || n < k + 2 || r.size() != n) return 0.0;
  double num = 0.0, den = 0.0;
  std::vector<std::pair<double, int>> dist;
  // Long files (a dense path, thousands of lengths): the neighbours are
  // looked for within 500 samples of the file order, which keeps it linear.
  const int window = n > 4000 ? 500 : n;
  for (int j = 0; j < n; ++j) {
    dist.clear();
    for (int o = std::max(0, j - window); o < std::min(n, j + window + 1); ++o)
      if (o != j) dist.emplace_back((P.d[o] - P.d[j]).squaredNorm(), o);
    std::nth_element(dist.begin(), dist.begin() + (k - 1), dist.end());
    Eigen::MatrixXd U(k, 3);
    Eigen::VectorXd rn(k);
    for (int q = 0; q < k; ++q) {
      U.row(q) = (P.d[dist[q].second] - P.d[j]).transpose();
      rn(q) = r(dist[q].second);
    }
    // The directions the neighbours spread in (a circle: one; a hemisphere:
    // two; two radii: three); a local polynomial in those.
    const Eigen::JacobiSVD<Eigen::MatrixXd> svd(U, Eigen::ComputeThinV);
    const Eigen::VectorXd sv = svd.singularValues();
    int m = 0;
    while (m < 3 && sv(m) > 0.1 * sv(0)) ++m;
    const Eigen::MatrixXd Z = U * svd.matrixV().leftCols(m) / std::max(sv(0), 1e-300);
    const int cols = 1 + m + (degree >= 2 ? m * (m + 1) / 2 : 0);
    if (k < cols + 3) continue;
    Eigen::MatrixXd X(k, cols);
    X.col(0).setOnes();
    X.middleCols(1, m) = Z;
    int c = 1 + m;
    if (degree >= 2)
      for (int a = 0; a < m; ++a)
        for (int b = a; b < m; ++b) X.col(c++) = Z.col(a).cwiseProduct(Z.col(b));
    Eigen::VectorXd e0 = Eigen::VectorXd::Zero(cols);
    e0(0) = 1.0;
    const Eigen::VectorXd a = (X.transpose() * X).ldlt().solve(e0);
    const Eigen::VectorXd w = X * a;  // the prediction at this sample from its neighbours
    if (!w.allFinite()) continue;
    num += std::pow(r(j) - w.dot(rn), 2);
    den += 1.0 + w.squaredNorm();
  }
  return den > 0.0 ? std::sqrt(num / den) : 0.0;
}

namespace {

// What the base refit leaves less a smooth error of every axis' reading
// (Legendre degree 2..4 each): the slow part a machine error lives in; and
// less, beside it, up to two candidates of the library that are significant
// there (a backlash or a guide error beside a pitch error: what neither a
// smooth function of one reading nor the poses' neighbours take).
Eigen::VectorXd without_smooth_part_and_effects(const KinematicProblem& P, const Engine& E,
                                    const std::vector<CandidateResult>& candidates, double alpha);

}  // namespace

KinematicNoiseFloor kinematic_noise_floor_of(const KinematicProblem& P, const Engine& E,
                                             const std::vector<CandidateResult>& candidates) {
  const int suggest = std::clamp(P.samples() / 5, 5, 20);
  const std::string how = "repeat " + std::to_string(suggest) +
                          " poses (the same readings, approached the same way, spread over the run) to measure the "
                          "instrument's own scatter";
  int repeated = 0;
  const double rep = repeated_pose_sigma(P, P.residual, &repeated);
  if (rep > 0.0)
    return {rep, "repeated poses", false,
            "noise floor " + fmt(rep * 1e6) + " µm from the scatter of the " + std::to_string(repeated) +
                " poses measured more than once"};
  if (P.sigma_declared > 0.0)
    return {P.sigma_declared, "declared sigma", false,
            "noise floor " + fmt(P.sigma_declared * 1e6) +
                " µm: the instrument's declared sigma (no pose is repeated to check it: " + how + ")"};
  const double N = E.rows();
  double best = Engine::rms(E.base_fit().residual) * std::sqrt(N / std::max(1.0, N - E.base_rank()));
  std::string best_label = "the base refit";
  for (const auto& c : candidates)
    if (c.identifiable && c.rss > 0.0 && c.rss < E.rss_base()) {
      const double s = Engine::rms(c.residual_after) * std::sqrt(N / std::max(1.0, N - c.k_total));
      if (s < best) { best = s; best_label = c.label(); }
    }
  if (P.kind == "ballbar") {
    constexpr double kEffectOut = 0.01;  // a candidate taken out first: p x its trials x candidates below this
    const double hb = local_high_band_sigma(P, without_smooth_part_and_effects(P, E, candidates, kEffectOut), 12, 1);
    // Below what any description leaves by more than the scatter of either
    // estimate: the high band holds structure finer than the poses' spacing
    // (a short cyclic error), and the floor is known only as an upper bound.
    if (hb > 0.0 && !(best < 0.8 * hb))
      return {hb, "bar length high band", false,
              "noise floor " + fmt(hb * 1e6) +
                  " µm from the high band of the bar's length (each length against a linear fit of its 12 nearest "
                  "poses, the smooth part of every axis' reading removed first); no pose is repeated: " + how +
                  " to confirm it"};
    if (hb > 0.0)
      return {best, "residual (upper bound)", true,
              "noise floor at most " + fmt(best * 1e6) + " µm, what " + best_label +
                  " leaves: the high band of the bar's length (" + fmt(hb * 1e6) +
                  " µm) holds structure finer than the poses' spacing; no pose is repeated: " + how};
  }
  return {best, "residual (upper bound)", true,
          "noise floor at most " + fmt(best * 1e6) +
              " µm: no pose is repeated, so it is the residual the best single description leaves, an upper "
              "bound, not the instrument's noise; " + how};
}

double kinematic_noise_floor(const KinematicProblem& P, const Engine& E, const std::vector<CandidateResult>& candidates) {
  return kinematic_noise_floor_of(P, E, candidates).value;
}

// ---------------------------------------------------------------------------
// Smooth structure

namespace {

constexpr double kMinStroke = 2e-3;  // m: an axis covering less shows no curvature

// Legendre polynomials of degree 2 and 3 on [-1, 1].
double legendre2(double u) { return 0.5 * (3.0 * u * u - 1.0); }
double legendre3(double u) { return 0.5 * (5.0 * u * u * u - 3.0 * u); }
double legendre4(double u) { return (35.0 * u * u * u * u - 30.0 * u * u + 3.0) / 8.0; }

}  // namespace

Eigen::MatrixXd smooth_displacement_columns(const KinematicProblem& P, int axis, int degree) {
  const KinematicSpan sp = span_of(P);
  const double h = 0.5 * (sp.hi[axis] - sp.lo[axis]), c = 0.5 * (sp.hi[axis] + sp.lo[axis]);
  if (!(2.0 * h > kMinStroke)) return Eigen::MatrixXd(P.rows(), 0);
  auto u = [&](int j) { return (P.d[static_cast<std::size_t>(j)][axis] - c) / h; };
  Eigen::MatrixXd X = hcat({displacement_column(P, axis, [&](int j) { return legendre2(u(j)); }),
                            displacement_column(P, axis, [&](int j) { return legendre3(u(j)); })});
  if (degree >= 4)
    X = detail::hstack(X, hcat({displacement_column(P, axis, [&](int j) { return legendre4(u(j)); })}));
  return X;
}

namespace {

Eigen::VectorXd without_smooth_part_and_effects(const KinematicProblem& P, const Engine& E,
                                    const std::vector<CandidateResult>& candidates, double alpha) {
  Eigen::MatrixXd X(P.rows(), 0);
  for (int i = 0; i < 3; ++i) X = detail::hstack(X, smooth_displacement_columns(P, i, 4));
  if (X.cols() == 0 || P.samples() < 3 * X.cols()) return E.base_fit().residual;
  JointFit f = E.fit(X);
  if (!f.residual.allFinite()) return E.base_fit().residual;
  std::vector<char> used(candidates.size(), 0);
  const double trials = std::max<double>(1.0, static_cast<double>(candidates.size()));
  for (int round = 0; round < 2; ++round) {
    int pick = -1;
    double best_p = alpha;
    JointFit best;
    for (std::size_t k = 0; k < candidates.size(); ++k) {
      const CandidateResult& c = candidates[k];
      if (used[k] || !c.identifiable || c.effect == "actuator_scale" || c.columns.rows() != P.rows() ||
          c.columns.cols() == 0 || P.samples() < 3 * (X.cols() + c.columns.cols()))
        continue;
      const Eigen::MatrixXd Xc = detail::hstack(X, c.columns);
      const JointFit g = E.fit(Xc);
      if (!g.full_rank || !g.residual.allFinite()) continue;
      const int q = static_cast<int>(c.columns.cols());
      const NestedTest t = E.nested(f.rss, g.rss, q, E.base_rank() + static_cast<int>(Xc.cols()), g.n_eff);
      const double pc = std::min(1.0, t.p_value * std::max(1.0, c.trials) * trials);
      if (t.f_stat > 0.0 && pc < best_p) {
        best_p = pc;
        pick = static_cast<int>(k);
        best = g;
      }
    }
    if (pick < 0) break;
    used[static_cast<std::size_t>(pick)] = 1;
    X = detail::hstack(X, candidates[static_cast<std::size_t>(pick)].columns);
    f = best;
  }
  return f.residual;
}

// A column set tested against an engine's base refit, p corrected for `trials`.
struct ColumnTest {
  bool ok = false;
  double p = 1.0, f = 0.0, rss = 0.0;
  JointFit fit;
};

ColumnTest test_columns(const Engine& E, const Eigen::MatrixXd& X, double trials, bool gate_share = true) {
  ColumnTest t;
  if (X.cols() == 0 || X.rows() != E.rows() || (gate_share && E.base_share(X).maxCoeff() > 0.995)) return t;
  t.fit = E.fit(X);
  if (!t.fit.full_rank) return t;
  const int q = static_cast<int>(X.cols());
  const NestedTest n = E.nested(E.rss_base(), t.fit.rss, q, E.base_rank() + q, t.fit.n_eff);
  t.ok = n.f_stat > 0.0;
  t.f = n.f_stat;
  t.p = std::min(1.0, n.p_value * trials);
  t.rss = t.fit.rss;
  return t;
}


// Peak to peak (m) over the stroke of the smooth error b2 P2 + b3 P3 (no linear part).
double smooth_size(const Eigen::VectorXd& b) {
  double lo = 1e300, hi = -1e300;
  for (int s = 0; s <= 100; ++s) {
    const double u = -1.0 + 0.02 * s, v = b(0) * legendre2(u) + b(1) * legendre3(u);
    lo = std::min(lo, v);
    hi = std::max(hi, v);
  }
  return hi - lo;
}

double weighted_rss(const Engine& E, const Eigen::VectorXd& r) {
  return (r.array() * E.problem().w.array()).square().sum();
}

// Forms of one axis' smooth error tried, one per axis: the look-elsewhere factor.
constexpr double kSmoothTrials = 3.0;
// The residual reaches the floor: its sigma within this factor of it (the
// floor's own scatter on 100-200 readings is 10-15 %).
constexpr double kAtFloor = 1.3;
// BIC by which a smooth error must beat the library's description when the
// floor is only an upper bound ("strong" evidence).
constexpr double kClearlyBetter = 2.0;

}  // namespace

namespace {

// P(chi'^2 > c) for the noncentral chi-square of 2 degrees of freedom and
// noncentrality lambda: the Poisson mixture of central chi-squares of 2 + 2j
// degrees of freedom, whose tails are e^(-c/2) sum_{i<=j} (c/2)^i / i!.
double chi2_2_power(double lambda, double c) {
  double pois = std::exp(-0.5 * lambda), term = std::exp(-0.5 * c), tail = term, p = pois * tail;
  for (int j = 1; j < 1000 && pois > 1e-300 * (1 + j); ++j) {
    pois *= 0.5 * lambda / j;
    term *= 0.5 * c / j;
    tail += term;
    p += pois * std::min(1.0, tail);
  }
  return std::min(1.0, p);
}

// The noncentrality at which the power reaches `power` (bisection; power grows with lambda).
double noncentrality_for(double power, double c) {
  double lo = 0.0, hi = 1000.0;
  for (int k = 0; k < 60; ++k) {
    const double mid = 0.5 * (lo + hi);
    (chi2_2_power(mid, c) < power ? lo : hi) = mid;
  }
  return 0.5 * (lo + hi);
}

}  // namespace

Diagnosis::SmoothDetectability smooth_detectability(const KinematicProblem& P, const Engine& E, int axis, double sigma,
                                                    double alpha, const Eigen::MatrixXd* beside) {
  Diagnosis::SmoothDetectability out;
  out.axis = axis;
  const Eigen::MatrixXd X = smooth_displacement_columns(P, axis);
  const double w = E.problem().w.size() ? E.problem().w(0) : 0.0;  // kinematic rows: one weight
  if (X.cols() != 2 || !(sigma > 0.0) || !(w > 0.0)) return out;
  // The columns' part the base cannot take, in m (the weight is constant).
  Eigen::MatrixXd G = (E.project_off_base(X) / w).eval();
  if (beside && beside->rows() == X.rows() && beside->cols() > 0) {
    // ... and off what the library effect's columns take beyond the base.
    const Eigen::MatrixXd C = E.project_off_base(*beside) / w;
    const Eigen::ColPivHouseholderQR<Eigen::MatrixXd> qr(C);
    const Eigen::MatrixXd Q = Eigen::MatrixXd(qr.householderQ()).leftCols(qr.rank());
    G -= Q * (Q.transpose() * G);
  }
  const Eigen::Matrix2d GtG = G.transpose() * G;
  // The test's critical value: F(2, many) at alpha / trials is chi^2_2 / 2, whose tail is e^(-c/2).
  const double c = -2.0 * std::log(alpha / kSmoothTrials);
  const double l10 = noncentrality_for(0.10, c), l90 = noncentrality_for(0.90, c);
  double lo = 1e300, hi = 0.0;
  for (int k = 0; k < 180; ++k) {
    const double th = std::numbers::pi * k / 180.0;
    const Eigen::Vector2d b(std::cos(th), std::sin(th));
    const double g = b.dot(GtG * b) / (sigma * sigma);  // noncentrality per unit amplitude squared
    const double ptp = smooth_size(b);
    if (!(g > 1e-12 * GtG.trace() / (sigma * sigma))) {
      hi = std::numeric_limits<double>::infinity();  // a shape taken whole: never found
      continue;
    }
    lo = std::min(lo, ptp * std::sqrt(l10 / g));
    hi = std::max(hi, ptp * std::sqrt(l90 / g));
  }
  out.missed_below = lo;
  out.found_above = hi;
  return out;
}

namespace {

// The pitch table fitted as the suggestion is, with what the verdict weighs it
// by: the weighted RSS it leaves beside the base and its effective number of
// parameters (the trace of its smoother at the smoothness chosen).
struct TableFit {
  SuggestedUserEffect table;
  double rss = 0.0, df = 0.0;
};

TableFit fit_table(const KinematicProblem& P, const Engine& E, int axis, int n);

}  // namespace

SuggestedUserEffect fit_pitch_table(const KinematicProblem& P, const Engine& E, int axis, int n) {
  return fit_table(P, E, axis, n).table;
}

namespace {

TableFit fit_table(const KinematicProblem& P, const Engine& E, int axis, int n) {
  TableFit out;
  SuggestedUserEffect& T = out.table;
  T.kind = "pitch_table";
  T.axis = axis;
  const KinematicSpan sp = span_of(P);
  const double lo = sp.lo[axis], hi = sp.hi[axis];
  if (!(hi - lo > kMinStroke) || n < 4) return out;
  for (int k = 0; k < n; ++k) T.nodes.push_back(lo + (hi - lo) * k / (n - 1));
  // Hat functions of the nodes as displacement columns, weighted.
  const LinearProblem& L = E.problem();
  const int N = E.rows();
  Eigen::MatrixXd H = Eigen::MatrixXd::Zero(N, n);
  for (int r = 0; r < N; ++r) {
    const double u = std::clamp((P.d[static_cast<std::size_t>(P.sample_of_row(r))][axis] - lo) / (hi - lo), 0.0, 1.0) *
                     (n - 1);
    const int k = std::min(n - 2, static_cast<int>(u));
    const double f = u - k;
    H(r, k) = P.sensitivity(r, axis) * (1.0 - f) * L.w(r);
    H(r, k + 1) = P.sensitivity(r, axis) * f * L.w(r);
  }
  const Eigen::VectorXd wy = L.y.cwiseProduct(L.w);
  const Eigen::MatrixXd WB = L.w.asDiagonal() * L.B;
  // What the base takes out (its offset and scale of the axis among it).
  const Eigen::ColPivHouseholderQR<Eigen::MatrixXd> qr(WB);
  const int rank = static_cast<int>(qr.rank());
  const Eigen::MatrixXd Q = Eigen::MatrixXd(qr.householderQ()).leftCols(rank);
  const Eigen::VectorXd y = wy - Q * (Q.transpose() * wy);
  const Eigen::MatrixXd Hp = H - Q * (Q.transpose() * H);
  Eigen::MatrixXd D2 = Eigen::MatrixXd::Zero(n - 2, n);
  for (int k = 0; k + 2 < n; ++k) D2.row(k).segment(k, 3) << 1.0, -2.0, 1.0;
  const Eigen::MatrixXd HtH = Hp.transpose() * Hp, R = D2.transpose() * D2;
  const Eigen::VectorXd Hty = Hp.transpose() * y;
  const double scale = std::max(HtH.trace() / n, 1e-300);
  // The smoothness by generalised cross-validation over a log grid.
  double best_gcv = 1e300;
  Eigen::VectorXd best_v = Eigen::VectorXd::Zero(n);
  for (int g = 0; g <= 40; ++g) {
    const double lambda = scale * std::pow(10.0, -6.0 + 0.2 * g);
    const Eigen::MatrixXd A = HtH + lambda * R + 1e-9 * scale * Eigen::MatrixXd::Identity(n, n);
    const Eigen::LDLT<Eigen::MatrixXd> ldlt(A);
    const Eigen::VectorXd v = ldlt.solve(Hty);
    const double rss = (y - Hp * v).squaredNorm();
    const double df = ldlt.solve(HtH).trace();
    const double dof = N - rank - df;
    if (!(dof > 1.0)) continue;
    const double gcv = N * rss / (dof * dof);
    if (gcv < best_gcv) {
      best_gcv = gcv;
      best_v = v;
      out.rss = rss;
      out.df = df;
    }
  }
  // The linear part of the table is an offset and a scale of the axis, which
  // the calibration holds: removed so the table holds only what it does not.
  Eigen::MatrixXd A(n, 2);
  for (int k = 0; k < n; ++k) A.row(k) << 1.0, T.nodes[static_cast<std::size_t>(k)] - lo;
  const Eigen::VectorXd lin = A.colPivHouseholderQr().solve(best_v);
  const Eigen::VectorXd v = best_v - A * lin;
  T.values.assign(v.data(), v.data() + n);
  const Eigen::VectorXd left = (y - Hp * best_v).cwiseQuotient(L.w);
  T.rms_after = Engine::rms(left);
  double vmin = v.minCoeff(), vmax = v.maxCoeff();
  T.text = "a pitch_table on axis " + std::to_string(axis + 1) + ": " + std::to_string(n) + " nodes over d" +
           std::to_string(axis + 1) + " = " + fmt(lo * 1e3, 4) + " .. " + fmt(hi * 1e3, 4) + " mm, values " +
           fmt(vmin * 1e6) + " .. " + fmt(vmax * 1e6) +
           " µm (smoothness by cross-validation, its linear part left to the calibration); with it the residual is " +
           fmt(T.rms_after * 1e6) + " µm RMS";
  return out;
}

// The table's curve as one displacement column of the axis (linear between
// nodes, held beyond the ends, as kin::PitchTable applies it).
Eigen::MatrixXd table_column(const KinematicProblem& P, const SuggestedUserEffect& T) {
  const auto& x = T.nodes;
  const auto& v = T.values;
  return hcat({displacement_column(P, T.axis, [&](int j) {
    const double d = P.d[static_cast<std::size_t>(j)][T.axis];
    if (d <= x.front()) return v.front();
    for (std::size_t k = 1; k < x.size(); ++k)
      if (d <= x[k]) return v[k - 1] + (v[k] - v[k - 1]) * (d - x[k - 1]) / (x[k] - x[k - 1]);
    return v.back();
  })});
}


// One form of an axis' smooth error tested against an engine: P2, P3, or the
// pitch table when its BIC, with its effective parameters, is below theirs.
struct SmoothForm {
  ColumnTest t;
  Eigen::MatrixXd X;   // the columns tested
  double k = 2.0;      // parameters counted by BIC
  double size = 0.0;   // m, peak to peak of the curved part
  bool table = false;
};

SmoothForm smooth_form(const Engine& E, const Eigen::MatrixXd& X) {
  SmoothForm f;
  f.t = test_columns(E, X, kSmoothTrials);
  f.X = X;
  if (f.t.fit.beta.size() == 2) f.size = smooth_size(f.t.fit.beta);
  return f;
}

// The pitch table of axis i fitted on E's residual replaces the P2, P3 form
// in f when its BIC is lower and its columns are significant there.
void table_form(const KinematicProblem& P, const Engine& E, int i, int N, SmoothForm& f) {
  const TableFit tf = fit_table(P, E, i, 11);
  const double lnN = std::log(static_cast<double>(N));
  const double bic_s = f.t.ok ? N * std::log(std::max(f.t.rss, 1e-300) / N) + 2.0 * lnN : 1e300;
  if (tf.table.values.empty() || !(tf.df > 0.0) || !(tf.rss > 0.0) || !(N * std::log(tf.rss / N) + tf.df * lnN < bic_s))
    return;
  const Eigen::MatrixXd Xt = table_column(P, tf.table);
  ColumnTest t = test_columns(E, Xt, kSmoothTrials);
  if (!t.ok) return;
  const int q = std::max(1, static_cast<int>(std::lround(tf.df)));
  t.p = std::min(1.0, kSmoothTrials * E.nested(E.rss_base(), tf.rss, q, E.base_rank() + q, t.fit.n_eff).p_value);
  t.rss = tf.rss;
  const auto [vmin, vmax] = std::minmax_element(tf.table.values.begin(), tf.table.values.end());
  f = {t, Xt, tf.df, *vmax - *vmin, true};
}

// The table's hat functions over the stroke covered (n nodes) as
// displacement columns of the axis: every curve a table of the axis can take.
Eigen::MatrixXd hat_columns(const KinematicProblem& P, int axis, int n) {
  const KinematicSpan sp = span_of(P);
  const double lo = sp.lo[axis], hi = sp.hi[axis];
  if (!(hi - lo > kMinStroke) || n < 2) return Eigen::MatrixXd(P.rows(), 0);
  Eigen::MatrixXd X(P.rows(), n);
  for (int k = 0; k < n; ++k)
    X.col(k) = displacement_column(P, axis, [&](int j) {
      const double u = std::clamp((P.d[static_cast<std::size_t>(j)][axis] - lo) / (hi - lo), 0.0, 1.0) * (n - 1);
      return std::max(0.0, 1.0 - std::fabs(u - k));
    });
  return X;
}

}  // namespace

void kinematic_outside_library(const KinematicProblem& P, const Engine& E, const DiagnoseOptions& opt, Diagnosis& D) {
  const int N = E.rows();
  if (P.samples() < 12 || D.residual_final.size() != N) return;
  D.smooth_detectability.clear();
  for (int i = 0; i < 3; ++i) {
    Diagnosis::SmoothDetectability b = smooth_detectability(P, E, i, D.noise_floor, opt.alpha);
    if (!(b.found_above > 0.0)) continue;
    // Told from the library: the effect that imitates it best sets the size.
    b.told_above = b.found_above;
    for (const CandidateResult& c : D.candidates) {
      if (!c.identifiable || c.effect == "actuator_scale" || c.columns.rows() != N || c.columns.cols() == 0) continue;
      const double t = smooth_detectability(P, E, i, D.noise_floor, opt.alpha, &c.columns).found_above;
      if (t > b.told_above) {
        b.told_above = t;
        b.confused_with = c.label();
      }
    }
    D.smooth_detectability.push_back(b);
  }
  // Said when nothing smooth is found: how large a pitch error could hide in these data.
  auto say_bounds = [&] {
    if (D.smooth_detectability.empty()) return;
    std::string t = "a smooth error of an axis' reading (a lead screw's pitch error; peak to peak of its curved part "
                    "over the stroke covered) is missed by these data below, and found in 90 % of data sets above:";
    for (const auto& b : D.smooth_detectability) {
      t += " axis " + std::to_string(b.axis + 1) + " " + fmt(b.missed_below * 1e6) + " .. " + fmt(b.found_above * 1e6) +
           " µm";
      if (!b.confused_with.empty())
        t += " (told from " + b.confused_with + " above " +
             (std::isfinite(b.told_above) ? fmt(b.told_above * 1e6) + " µm" : std::string("no size: it takes a shape whole")) +
             ")";
      t += ";";
    }
    t += " one below the first figure cannot be told from the calibration's offset and scale: to find a smaller one, "
         "spread the poses further along the axis" + std::string(P.kind == "ballbar" ? " (measure a second bar radius)" : "");
    D.notes.push_back(t);
  };
  const double lnN = std::log(static_cast<double>(N));
  const std::vector<int> found = D.found();
  int k_lib = 0;
  for (int j : found) k_lib += D.candidates[static_cast<std::size_t>(j)].n_params;
  const double rms_lib = Engine::rms(D.residual_final);
  const double rss_lib = std::max(weighted_rss(E, D.residual_final), 1e-300);
  const double bic_lib = N * std::log(rss_lib / N) + k_lib * lnN;
  const double sigma_lib =
      Engine::rms(D.residual_final) * std::sqrt(N / std::max(1.0, static_cast<double>(N - E.base_rank() - k_lib)));
  const bool at_floor = sigma_lib <= kAtFloor * D.noise_floor;
  // What the library's effects leave, as a problem of its own.
  KinematicProblem Pf = P;
  Pf.residual = -D.residual_final;
  const Engine Ef(kinematic_linear_problem(Pf));

  int axis = -1, tie_axis = -1;
  double best_p = 1.0, tie_delta = 0.0, tie_size = 0.0, best_size = 0.0;
  ColumnTest alone_best, left_best;
  for (int i = 0; i < 3; ++i) {
    const Eigen::MatrixXd X = smooth_displacement_columns(P, i);
    if (X.cols() == 0) continue;
    // The pitch-table form is tried wherever P2, P3 are (the suggestion's
    // nodes and smoothness): a pitch error that stops growing inside the
    // stroke is a kink P2, P3 cannot follow, and a long cyclic error then
    // fits it better than they do (a 1 mm cyclic error on axis 2 of 120
    // position poses), or beside a library effect the kink's remainder is
    // left as structure.
    SmoothForm left = smooth_form(Ef, X);
    table_form(Pf, Ef, i, N, left);
    // In place of the library's effects: of all of them (alone on the base
    // refit), or of one of them beside the others, the best by BIC. Against
    // all of them only, a phantom cyclic error on the kinked axis stayed
    // named beside a real one on another axis, which the smooth error alone
    // could not replace.
    SmoothForm alone;
    double k_swap = 0.0;  // parameters of the library's effects kept beside it
    auto bic_of = [&](const SmoothForm& f, double k_kept) {
      return f.t.ok ? N * std::log(std::max(f.t.rss, 1e-300) / N) + (f.k + k_kept) * lnN : 1e300;
    };
    if (!found.empty()) {
      alone = smooth_form(E, X);
      table_form(P, E, i, N, alone);
      if (found.size() > 1)
        for (int c : found) {
          Eigen::MatrixXd others(N, 0);
          int k_others = 0;
          for (int o : found) {
            const CandidateResult& co = D.candidates[static_cast<std::size_t>(o)];
            if (o == c || co.columns.rows() != N) continue;
            others = detail::hstack(others, co.columns);
            k_others += co.n_params;
          }
          const Engine Eo = with_base_columns(E, others, "library effect");
          SmoothForm g = smooth_form(Eo, X);
          table_form(P, Eo, i, N, g);
          if (g.t.ok && g.t.p < opt.alpha && bic_of(g, k_others) < bic_of(alone, k_swap)) {
            alone = g;
            k_swap = k_others;
          }
        }
    }
    const double size = alone.table ? alone.size : left.table ? left.size : alone.t.ok ? alone.size : left.size;
    const bool left_sig = left.t.ok && left.t.p < opt.alpha;
    bool better = false;
    if (!found.empty() && alone.t.ok && alone.t.p < opt.alpha) {
      const double bic_s = bic_of(alone, k_swap);
      better = bic_s < bic_lib - kClearlyBetter || (!D.noise_floor_upper_bound && !at_floor && bic_s < bic_lib);
      // Within the margin either way: the data fit both alike.
      if (!better && std::fabs(bic_s - bic_lib) <= kClearlyBetter && (tie_axis < 0 || bic_s - bic_lib < tie_delta)) {
        tie_axis = i;
        tie_delta = bic_s - bic_lib;
        tie_size = size;
      }
    }
    if (!(left_sig || better)) continue;
    const double p = left_sig ? std::min(left.t.p, alone.t.p) : alone.t.p;
    if (axis < 0 || p < best_p) {
      axis = i;
      best_p = p;
      alone_best = alone.t;
      left_best = left.t;
      best_size = size;
    }
  }
  if (axis < 0 && tie_axis >= 0) {
    // Two explanations fit alike: the library's stays named, the other is said beside it.
    const KinematicSpan sp = span_of(P);
    const std::string ax = std::to_string(tie_axis + 1);
    StructureFinding f;
    f.kind = "smooth";
    f.axis = tie_axis;
    f.coordinate = "d" + ax;
    f.location = 0.5 * (sp.lo[tie_axis] + sp.hi[tie_axis]);
    f.size = tie_size;
    f.lo = sp.lo[tie_axis];
    f.hi = sp.hi[tie_axis];
    const std::string apart = P.kind == "ballbar" ? "measure with a second bar radius, or axis " + ax +
                                                        " alone along its stroke with a linear interferometer"
                                                  : "measure axis " + ax +
                                                        " alone along its stroke with a linear interferometer";
    f.text = "axis " + ax + ": an error that follows d" + ax + ", smooth, not periodic, size " + fmt(f.size * 1e6) +
             " µm, fits these data as well as the effects named (BIC " + fmt(tie_delta, 2) +
             " against them): a pitch error outside the library is as likely; to tell them apart, " + apart;
    D.structure.push_back(f);
    D.ambiguous = true;
    CandidateResult& v = D.candidates[static_cast<std::size_t>(found.front())];
    v.alternatives.push_back("outside_library[axis " + ax + "]");
    v.confounded.push_back({"outside_library[axis " + ax + "]", "", tie_axis, 1.0, apart});
    D.verdict_text += ". As well as these, " + f.text;
    say_bounds();
    return;
  }
  if (axis < 0) {
    say_bounds();
    if (!found.empty() && !at_floor && !D.noise_floor_upper_bound)
      D.notes.push_back("the residual after the effects named (" + fmt(sigma_lib * 1e6) + " µm) stays " +
                        fmt(sigma_lib / D.noise_floor, 2) + " x the noise floor (" + D.noise_floor_source +
                        "): part of it is not explained by the library nor by a smooth error of one axis");
    return;
  }
  // The finding, sized by the smooth error fitted alone on the base refit.
  const KinematicSpan sp = span_of(P);
  const std::string ax = std::to_string(axis + 1);
  StructureFinding f;
  f.kind = "smooth";
  f.axis = axis;
  f.coordinate = "d" + ax;
  f.location = 0.5 * (sp.lo[axis] + sp.hi[axis]);
  f.size = best_size;
  f.z = std::sqrt(2.0 * std::max(alone_best.f, left_best.f));
  f.lo = sp.lo[axis];
  f.hi = sp.hi[axis];

  // Library effects that still add something beside it stay named; the
  // others explained part of it only. Judged beside every shape a table of
  // the axis can take (its 11 hat functions, unpenalised), not beside one
  // shape fitted: fitted on the base refit, that shape imitated a guide error
  // on another axis (which was then dropped as partial); fitted on what the
  // library's effects leave, it lacked what a phantom cyclic error on the
  // kinked axis took (which then stayed named).
  const Engine Es = with_base_columns(E, hat_columns(P, axis, 11), "smooth error");
  std::vector<int> kept, partial;
  Eigen::MatrixXd XK(N, 0);
  for (int j : found) {
    const CandidateResult& c = D.candidates[static_cast<std::size_t>(j)];
    bool keep = false;
    if (c.effect == "actuator_scale") {
      keep = true;  // judged at the model as given, where the calibration does not absorb it
    } else if (c.columns.rows() == N && c.columns.cols() > 0) {
      // Not gated by its share in the base: the selection named it on what
      // lies off the base (a guide error's columns are 99.95 % in the
      // calibration's span, its remainder 0.9 µm RMS on a two-radius bar).
      const ColumnTest t =
          test_columns(Es, c.columns, std::max(1.0, c.trials) * static_cast<double>(found.size()), false);
      keep = t.ok && t.p < opt.alpha;
    }
    (keep ? kept : partial).push_back(j);
    if (keep && c.columns.rows() == N) XK = detail::hstack(XK, c.columns);
  }
  D.verdict = kept.empty() ? -1 : kept.front();
  D.also.assign(kept.size() > 1 ? kept.begin() + 1 : kept.end(), kept.end());
  D.partial.clear();
  for (int j : partial) D.partial.push_back(D.candidates[static_cast<std::size_t>(j)].label());
  // The table suggested is fitted beside the library effects named, and sizes the finding.
  const Engine Ek = XK.cols() ? with_base_columns(E, XK, "library effect") : E;
  const SuggestedUserEffect T = fit_pitch_table(P, Ek, axis, 11);
  const JointFit joint = T.values.empty() ? Es.fit(XK) : Ek.fit(table_column(P, T));
  D.residual_final = joint.residual;
  if (!T.values.empty() && XK.cols() > 0) {
    // The effects named refitted jointly beside the table: fitted alone with
    // the base, a guide error beside a kink read 6.5-7.9 % low on a two-radius bar.
    const Engine Et = with_base_columns(E, table_column(P, T), "pitch table");
    const JointFit fk = Et.fit(XK);
    if (fk.full_rank && fk.beta.allFinite()) {
      const Eigen::MatrixXd cov = Et.covariance(XK, fk, Et.base_rank() + static_cast<int>(XK.cols()), true);
      int at = 0;
      for (int j : kept) {
        CandidateResult& c = D.candidates[static_cast<std::size_t>(j)];
        if (c.columns.rows() != N || c.columns.cols() == 0) continue;
        const auto type = kin::kinematic_effect_from_name(c.effect);
        const KinematicEffectFitter* fit = type ? kinematic_fitter(*type) : nullptr;
        CandidateResult again = c;
        std::array<double, 3> v{};
        try {
          if (fit && fit->joint_values) {
            fit->joint_values(fk, at, cov, again, v);
            c = std::move(again);
          }
        } catch (const Error&) {
          // a value the joint fit cannot hold (a negative backlash): the one fitted alone stays
        }
        at += static_cast<int>(c.columns.cols());
      }
    }
  }
  if (!T.values.empty()) {
    D.suggested_user_effects = {T};
    const auto [vmin, vmax] = std::minmax_element(T.values.begin(), T.values.end());
    f.size = *vmax - *vmin;
  }
  f.text = "axis " + ax + ": an error that follows d" + ax + ", smooth, not periodic, size " + fmt(f.size * 1e6) +
           " µm (peak to peak of its curved part over d" + ax + " = " + fmt(f.lo * 1e3, 4) + " .. " +
           fmt(f.hi * 1e3, 4) + " mm; p = " + fmt(best_p, 2) + ")";
  D.outside_library = {f};

  std::ostringstream os;
  os << "missing: something no library effect describes: " << f.text << ". With it the residual falls from "
     << detail::amount(D.base_refit_rms, D.units) << " (base refitted) to " << detail::amount(Engine::rms(joint.residual), D.units)
     << " RMS; " << D.noise_floor_text;
  if (!partial.empty()) {
    os << ". Library effects explain part of it and are not named: ";
    for (std::size_t k = 0; k < partial.size(); ++k) {
      const CandidateResult& c = D.candidates[static_cast<std::size_t>(partial[k])];
      os << (k ? ", " : "") << c.label();
    }
    os << " (the library's effects together leave " << detail::amount(rms_lib, D.units) << " RMS)";
  }
  if (!kept.empty()) {
    os << ". Beside it, named: ";
    for (std::size_t k = 0; k < kept.size(); ++k) os << (k ? ", " : "") << D.candidates[static_cast<std::size_t>(kept[k])].label();
  }
  os << ". To tell a pitch error from the library's effects, measure axis " << ax
     << " alone along its whole stroke with a linear interferometer at steps of a few mm: a pitch error shows there "
        "as a smooth curve, a cyclic error would repeat, a guide error or a limb twist would not show on the axis' own "
        "reading";
  if (!T.values.empty()) os << ". Suggested user effect: " << T.text;
  D.verdict_text = os.str();
  D.ambiguous = false;
}

PitchTableFit fit_pitch_table(const io::DataSet& data, const ctl::MachineModel& model, int axis, int nodes) {
  if (axis < 0 || axis > 2) throw Error("pitch_table: axis " + std::to_string(axis + 1) + " (must be 1, 2 or 3)");
  const std::string ax = std::to_string(axis + 1);
  if (nodes < 4 || nodes > kin::PitchTable::kCapacity)
    throw Error("pitch_table:" + ax + ": " + std::to_string(nodes) + " nodes (4 to " +
                std::to_string(kin::PitchTable::kCapacity) + ")");
  PitchTableFit out;
  // The table replaces any the axis had: fitted on what the model leaves without it.
  ctl::MachineModel without = model;
  const bool had = !without.kinematics.effects[static_cast<std::size_t>(axis)].pitch_table.empty();
  without.kinematics.effects[static_cast<std::size_t>(axis)].pitch_table = {};
  const KinematicProblem P = prepare_kinematic(data, without.kinematics);
  out.before = had ? Engine::rms(prepare_kinematic(data, model.kinematics).residual_given) : Engine::rms(P.residual_given);
  const Engine E(kinematic_linear_problem(P));
  out.table = fit_pitch_table(P, E, axis, nodes);
  if (out.table.values.empty()) {
    const KinematicSpan sp = span_of(P);
    throw Error("pitch_table:" + ax + ": the data move axis " + ax + " over " +
                fmt((sp.hi[axis] - sp.lo[axis]) * 1e3, 3) + " mm only (a table needs at least " +
                fmt(kMinStroke * 1e3, 2) + " mm of its stroke)");
  }
  bool tilts = false;
  for (const auto& e : without.kinematics.effects) tilts = tilts || e.guide_ka != 0.0 || e.guide_kb != 0.0 || e.twist != 0.0;
  if (tilts) {
    // The plane calibration cannot run under a guide error or a limb twist
    // (what a pitch error is most often named beside): the planes refitted
    // by the linearised base refit beside the table instead, as `cpm fit`
    // refits them beside library effects.
    const JointFit b = E.base_fit();
    out.base_only = Engine::rms(P.residual_of_model(P.model_of(P.base_value + P.base_map * b.base_delta, P.given.effects)));
    const JointFit f = E.fit(table_column(P, out.table));
    if (f.beta.size() == 1 && std::isfinite(f.beta(0)))
      for (double& v : out.table.values) v *= f.beta(0);
    KinematicEffects eff = P.given.effects;
    eff[static_cast<std::size_t>(axis)].pitch_table = pitch_table_of(out.table);
    out.model = without;
    out.model.kinematics = P.model_of(P.base_value + P.base_map * f.base_delta, eff);
    out.after = Engine::rms(P.residual_of_model(out.model.kinematics));
    out.notes.push_back("the model carries a guide_angular_error or limb_twist, under which the planes cannot be "
                        "calibrated: they were refitted linearised at the calibrated point beside the table");
  } else {
    // The planes recalibrated without and with it (the model file holds them calibrated).
    io::ModelFile in;
    in.model = without;
    out.base_only = cal::calibrate(in, data, "", "", "cpm fit").residual_rms();
    in.model.kinematics.effects[static_cast<std::size_t>(axis)].pitch_table = pitch_table_of(out.table);
    const cal::CalibrationResult C = cal::calibrate(in, data, "", "", "cpm fit");
    out.model = C.model.model;
    out.after = C.residual_rms();
  }
  if (had) out.notes.push_back("the model's pitch_table on axis " + ax + " was replaced by the one fitted");
  if (!(out.after < out.base_only))
    out.notes.push_back("the table does not lower the residual (" + fmt(out.base_only * 1e6) + " -> " +
                        fmt(out.after * 1e6) + " µm): these data show no smooth error of d" + ax);
  return out;
}

}  // namespace cpm::ident
