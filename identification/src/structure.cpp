// SPDX-License-Identifier: Apache-2.0
#include "cpm/identification/structure.hpp"

#include <algorithm>
#include <cmath>
#include <numbers>
#include <optional>
#include <sstream>

#include "cpm/control/effects.hpp"
#include "cpm/identification/stats.hpp"

namespace cpm::ident {
namespace {


template <class... T>
std::string cat(const T&... parts) {
  std::ostringstream os;
  os.precision(3);
  (os << ... << parts);
  return os.str();
}

double mean(const std::vector<double>& x) {
  double s = 0.0;
  for (double v : x) s += v;
  return x.empty() ? 0.0 : s / static_cast<double>(x.size());
}

}  // namespace

void periodogram(const std::vector<double>& x, const std::vector<double>& y, double lmin, double lmax,
                 std::vector<double>& wavelength, std::vector<double>& power) {
  wavelength.clear();
  power.clear();
  const std::size_t n = x.size();
  if (n < 8 || !(lmax > lmin)) return;
  const auto [mn, mx] = std::minmax_element(x.begin(), x.end());
  const double span = *mx - *mn;
  if (!(span > 0.0)) return;
  const double kmin = 1.0 / lmax, kmax = 1.0 / lmin, dk = 1.0 / (4.0 * span);
  const int K = std::min(4000, static_cast<int>((kmax - kmin) / dk) + 1);
  const double step = K > 1 ? (kmax - kmin) / (K - 1) : 0.0;
  const double tp = 2.0 * std::numbers::pi;
  std::vector<double> pc(n), ps(n), rc(n), rs(n);
  const double ym = mean(y);
  for (std::size_t r = 0; r < n; ++r) {
    pc[r] = std::cos(tp * kmin * x[r]);
    ps[r] = std::sin(tp * kmin * x[r]);
    rc[r] = std::cos(tp * step * x[r]);
    rs[r] = std::sin(tp * step * x[r]);
  }
  for (int q = 0; q < K; ++q) {
    double cc = 0, cs = 0, ss = 0, cy = 0, sy = 0;
    for (std::size_t r = 0; r < n; ++r) {
      const double c = pc[r], s = ps[r], v = y[r] - ym;
      cc += c * c; cs += c * s; ss += s * s; cy += c * v; sy += s * v;
      pc[r] = c * rc[r] - s * rs[r];
      ps[r] = s * rc[r] + c * rs[r];
    }
    const double det = cc * ss - cs * cs;
    wavelength.push_back(1.0 / (kmin + q * step));
    power.push_back(det > 1e-300 ? (ss * cy * cy - 2 * cs * cy * sy + cc * sy * sy) / det : 0.0);
  }
}

namespace {

// The residual of one axis as the checks see it.
struct AxisResidual {
  int axis = 0;
  std::vector<double> y;  // per row (N)
  double mean = 0.0, var = 0.0, sd = 0.0;
  double infl = 1.0;      // variance inflation of a mean by the residual's autocorrelation
  double tiny = 0.0;      // size below which a finding is not worth a sentence
};

// Axis i's residual, or none when it is constant.
std::optional<AxisResidual> axis_residual(const Eigen::VectorXd& residual, int R, int i, const Vec3& axis_noise) {
  AxisResidual A;
  A.axis = i;
  A.y.resize(R);
  for (int r = 0; r < R; ++r) A.y[r] = residual(3 * r + i);
  A.mean = mean(A.y);
  for (double v : A.y) A.var += (v - A.mean) * (v - A.mean);
  A.var /= R;
  const double ne = effective_samples({A.y});
  A.infl = static_cast<double>(R) / std::max(2.0, ne);
  A.sd = std::sqrt(A.var);
  if (!(A.sd > 0.0)) return std::nullopt;
  // A third of the noise.
  A.tiny = std::max(0.3 * axis_noise[i], 1e-12);
  return A;
}

// 1. A difference between the two directions of motion of the axis.
std::optional<StructureFinding> direction_finding(const MotionProblem& P, const AxisResidual& A) {
  const int i = A.axis;
  std::vector<double> pos, neg;
  for (int r = 0; r < P.rows(); ++r) {
    if (P.v[r][i] > 2e-3) pos.push_back(A.y[r]);
    if (P.v[r][i] < -2e-3) neg.push_back(A.y[r]);
  }
  if (pos.size() <= 10 || neg.size() <= 10) return std::nullopt;
  const double diff = mean(pos) - mean(neg);
  const double se = A.sd * std::sqrt(A.infl * (1.0 / pos.size() + 1.0 / neg.size()));
  const double z = diff / se;
  if (!(std::fabs(z) > 5.0 && std::fabs(diff) > A.tiny)) return std::nullopt;
  return StructureFinding{"direction", i, cat("v", i + 1), 0.0, diff, z,
                          cat("axis ", i + 1, ": the residual differs by ", diff,
                              " N between moving forward and backward (direction-dependent force)")};
}

// The strongest sine of a periodogram: its wavelength (or period), amplitude
// and chi (~ chi^2 with 2 dof under noise), p corrected for `trials` x `places`.
struct Peak {
  double location = 0.0, amp = 0.0, chi = 0.0, p = 1.0;
};

std::optional<Peak> strongest_sine(const std::vector<double>& x, const AxisResidual& A, double lmin, double lmax,
                                   double trials, double places) {
  std::vector<double> wl, pw;
  periodogram(x, A.y, lmin, lmax, wl, pw);
  if (pw.empty()) return std::nullopt;
  const auto it = std::max_element(pw.begin(), pw.end());
  Peak k;
  k.chi = *it / (A.var * A.infl);
  k.p = std::min(1.0, std::exp(-0.5 * k.chi) * std::max(1.0, trials) * places);
  k.amp = std::sqrt(2.0 * *it / static_cast<double>(A.y.size()));
  k.location = wl[static_cast<std::size_t>(it - pw.begin())];
  return k;
}

// 2. A force periodic in the position of axis j (wavelengths 2 mm .. 2/3 of the stroke covered).
std::optional<StructureFinding> periodic_in_position(const MotionProblem& P, const AxisResidual& A, int j,
                                                     double span) {
  if (span < 0.01) return std::nullopt;
  std::vector<double> x(P.rows());
  for (int r = 0; r < P.rows(); ++r) x[r] = P.d[r][j];
  const double trials = span * (1.0 / 2e-3 - 1.5 / span);
  const auto k = strongest_sine(x, A, 2e-3, span / 1.5, trials, 9.0);
  if (!k || !(k->p < 1e-4 && k->amp > A.tiny)) return std::nullopt;
  const int i = A.axis;
  return StructureFinding{"periodic", i, cat("d", j + 1), k->location, k->amp, std::sqrt(k->chi),
                          cat("axis ", i + 1, ": a force periodic in the position of axis ", j + 1, ", wavelength ",
                              k->location * 1e3, " mm, amplitude ", k->amp, " N")};
}

// 3. A force periodic in time (periods of 4 rows .. half the log).
std::optional<StructureFinding> periodic_in_time(const std::vector<double>& t, const AxisResidual& A) {
  const int R = static_cast<int>(t.size());
  const double T = t.back() - t.front();
  const double rowdt = R > 1 ? T / (R - 1) : 1.0;
  const auto k = strongest_sine(t, A, 4.0 * rowdt, T / 2.0, T * (1.0 / (4.0 * rowdt)), 3.0);
  if (!k || !(k->p < 1e-4 && k->amp > A.tiny)) return std::nullopt;
  const double per = k->location;
  return StructureFinding{"periodic_time", A.axis, "t", per, k->amp, std::sqrt(k->chi),
                          cat("axis ", A.axis + 1, ": a force periodic in time, period ", per, " s (", 1.0 / per,
                              " Hz), amplitude ", k->amp, " N")};
}

// 4. A trend in time.
std::optional<StructureFinding> trend_in_time(const std::vector<double>& t, const AxisResidual& A) {
  const int R = static_cast<int>(t.size());
  const double tm = mean(t);
  double stt = 0, sty = 0;
  for (int r = 0; r < R; ++r) { stt += (t[r] - tm) * (t[r] - tm); sty += (t[r] - tm) * (A.y[r] - A.mean); }
  if (!(stt > 0.0)) return std::nullopt;
  const double slope = sty / stt;
  const double z = slope / (A.sd * std::sqrt(A.infl / stt));
  const double change = slope * (t.back() - t.front());
  if (!(std::fabs(z) > 5.0 && std::fabs(change) > A.tiny)) return std::nullopt;
  return StructureFinding{"trend", A.axis, "t", t.back(), change, z,
                          cat("axis ", A.axis + 1, ": the residual drifts by ", change, " N over the ",
                              t.back() - t.front(), " s of the log")};
}

// The rows in the order of the axis' own position, and the running sum of
// the residual (less its mean) in that order.
struct AlongPosition {
  std::vector<int> idx;
  std::vector<double> cum;  // cum[s]: sum over the first s rows
};

AlongPosition along_position(const MotionProblem& P, const AxisResidual& A) {
  const int R = P.rows(), i = A.axis;
  AlongPosition o;
  o.idx.resize(R);
  for (int r = 0; r < R; ++r) o.idx[r] = r;
  std::sort(o.idx.begin(), o.idx.end(), [&](int a, int b) { return P.d[a][i] < P.d[b][i]; });
  o.cum.assign(R + 1, 0.0);
  for (int r = 0; r < R; ++r) o.cum[r + 1] = o.cum[r] + (A.y[o.idx[r]] - A.mean);
  return o;
}

// 5a. A step along the axis' position: the split with the largest difference of means.
std::optional<StructureFinding> step_finding(const MotionProblem& P, const AxisResidual& A, const AlongPosition& o) {
  const int R = P.rows(), i = A.axis;
  double best_z = 0.0, best_diff = 0.0, best_x = 0.0;
  const int lo = std::max(10, R / 20), hi = R - lo;
  for (int s = lo; s < hi; s += std::max(1, R / 200)) {
    const double ml = o.cum[s] / s, mr = (o.cum[R] - o.cum[s]) / (R - s);
    const double se = A.sd * std::sqrt(A.infl * (1.0 / s + 1.0 / (R - s)));
    const double z = (mr - ml) / se;
    if (std::fabs(z) > std::fabs(best_z)) {
      best_z = z;
      best_diff = mr - ml;
      best_x = 0.5 * (P.d[o.idx[s - 1]][i] + P.d[o.idx[s]][i]);
    }
  }
  if (!(std::fabs(best_z) > 6.0 && std::fabs(best_diff) > A.tiny)) return std::nullopt;
  return StructureFinding{"step", i, cat("d", i + 1), best_x, best_diff, best_z,
                          cat("axis ", i + 1, ": the residual changes by ", best_diff, " N across d", i + 1, " = ",
                              best_x * 1e3, " mm")};
}

// 5b. A bump along the axis' position: the bin (of 20 of equal count) whose mean stands out most.
std::optional<StructureFinding> bump_finding(const MotionProblem& P, const AxisResidual& A, const AlongPosition& o) {
  const int R = P.rows(), i = A.axis, B = 20;
  double bz = 0.0, bmean = 0.0, bx = 0.0, blo = 0.0, bhi = 0.0;
  int b0 = 0, b1 = 0;  // the bin's first and one-past-last rows in position order
  for (int b = 0; b < B; ++b) {
    const int a0 = b * R / B, a1 = (b + 1) * R / B;
    if (a1 - a0 < 5) continue;
    const double m = (o.cum[a1] - o.cum[a0]) / (a1 - a0);
    const double z = m / (A.sd * std::sqrt(A.infl / (a1 - a0)));
    if (std::fabs(z) > std::fabs(bz)) {
      bz = z;
      bmean = m;
      b0 = a0;
      b1 = a1;
      bx = P.d[o.idx[(a0 + a1) / 2]][i];
      blo = P.d[o.idx[a0]][i];
      bhi = P.d[o.idx[a1 - 1]][i];
    }
  }
  // Its z against what is left with the excess taken out: the residual's own
  // spread and autocorrelation hold the bump itself (a 1.1 N bump on z stood
  // at 6 sigma behind them).
  if (std::fabs(bmean) > A.tiny) {
    std::vector<double> left = A.y;
    for (int q = b0; q < b1; ++q) left[static_cast<std::size_t>(o.idx[static_cast<std::size_t>(q)])] -= bmean;
    double m = 0.0, v = 0.0;
    for (double x : left) m += x / R;
    for (double x : left) v += (x - m) * (x - m) / R;
    const double infl = static_cast<double>(R) / std::max(2.0, effective_samples({left}));
    const double z_left = bmean / std::sqrt(v * infl / static_cast<double>(std::max(1, b1 - b0)));
    if (std::fabs(z_left) > std::fabs(bz)) bz = z_left;
  }
  if (!(std::fabs(bz) > 6.0 && std::fabs(bmean) > A.tiny)) return std::nullopt;
  return StructureFinding{"bump", i, cat("d", i + 1), bx, bmean, bz,
                          cat("axis ", i + 1, ": a local excess of ", bmean, " N around d", i + 1, " = ", bx * 1e3, " mm"),
                          blo, bhi};
}

// 6. A smooth force that follows one variable of the state: for each of d1..d3,
// v1..v3, a1..a3 and t, Legendre polynomials of degree 1..kSmoothDegree fitted
// to the axis' residual; the removed sum of squares, in units of the
// residual's variance inflated by its autocorrelation, is ~ chi^2 with
// kSmoothDegree dof under noise. Look-elsewhere over every (axis, variable)
// pair. The variable that removes most is reported, with those alike: those
// that remove at least 80 % as much (v_j and a_j of one sine, d_j and a_j),
// and those nearly affine in it over the log (|corr| of the two variables
// >= 0.9: on a circle v1 is -w (d2 - c), and a force of either is the same
// curve of both), whether or not their own fit passed.
constexpr double kSmoothAlsoShare = 0.8;
constexpr double kAlikeCorrelation = 0.9;
const char* const kSmoothVariables[] = {"d1", "d2", "d3", "v1", "v2", "v3", "a1", "a2", "a3", "t"};
constexpr int kSmoothPairs = 3 * 10 * 2;  // (axis, variable) pairs, two bases each

// A fit's removed sum of squares judged against what it leaves: in units of
// that residual's variance (over R rows less the fit's `params`) inflated by
// its own autocorrelation (the residual's variance before the fit holds the
// structure itself, and a strong one hid behind it at 7 sigma), chi ~ chi^2
// with `dof` degrees of freedom under noise; p after the look-elsewhere over
// `family` tries.
struct RemovalTest {
  double chi = 0.0, p = 1.0;
  double unit = 0.0;   // the inflated variance: one noise row's worth of sum of squares
  double n_eff = 0.0;  // effective rows of what is left
};

RemovalTest judge_removal(const Eigen::VectorXd& left, double removed, int params, int dof, double family) {
  RemovalTest t;
  const int R = static_cast<int>(left.size());
  const std::vector<double> left_v(left.data(), left.data() + R);
  const double var_left = left.squaredNorm() / std::max(1, R - params - 1);
  const double infl_left = static_cast<double>(R) / std::max(2.0, effective_samples({left_v}));
  t.unit = var_left * infl_left;
  t.n_eff = static_cast<double>(R) / infl_left;
  t.chi = t.unit > 0.0 ? removed / t.unit : 0.0;
  t.p = std::min(1.0, f_tail(t.chi / dof, dof, 1e7) * family);
  return t;
}

struct SmoothFit {
  std::string var;
  double lo = 0.0, hi = 0.0;
  double removed = 0.0, chi = 0.0, p = 1.0;
  Eigen::VectorXd coef;       // on the Legendre columns (after the mean)
  double linear_share = 0.0, odd_share = 0.0;
  bool table = false;  // removed, chi and p are the table's (table_fit)
};

std::vector<double> variable_values(const MotionProblem& P, const std::string& var) {
  std::vector<double> x(static_cast<std::size_t>(P.rows()));
  for (int r = 0; r < P.rows(); ++r) x[static_cast<std::size_t>(r)] = state_variable(P, r, var);
  return x;
}

}  // namespace

std::vector<double> table_nodes(std::vector<double> x) {
  std::vector<double> n;
  if (x.size() < 2) return n;
  std::sort(x.begin(), x.end());
  const double lo = x.front(), hi = x.back(), gap = (hi - lo) / 100.0;
  if (!(hi > lo)) return n;
  std::vector<double> c;
  for (int k = 0; k < kTableUniformNodes; ++k) c.push_back(lo + (hi - lo) * k / (kTableUniformNodes - 1));
  for (int k = 1; k + 1 < kTableQuantileNodes; ++k)
    c.push_back(x[static_cast<std::size_t>(static_cast<long>(k) * static_cast<long>(x.size() - 1) / (kTableQuantileNodes - 1))]);
  std::sort(c.begin(), c.end());
  for (double v : c)
    if (n.empty() || v > n.back() + gap) n.push_back(v);
  if (n.back() < hi) n.back() = hi;
  return n;
}

namespace {

// Pearson correlation of two series of one length (0 when either is constant).
double correlation(const std::vector<double>& a, const std::vector<double>& b) {
  const double ma = mean(a), mb = mean(b);
  double sab = 0.0, saa = 0.0, sbb = 0.0;
  for (std::size_t k = 0; k < a.size(); ++k) {
    sab += (a[k] - ma) * (b[k] - mb);
    saa += (a[k] - ma) * (a[k] - ma);
    sbb += (b[k] - mb) * (b[k] - mb);
  }
  return saa > 0.0 && sbb > 0.0 ? sab / std::sqrt(saa * sbb) : 0.0;
}

// A speed as a table: piecewise linear between table_nodes of its values
// (the hats of the nodes but the first, centred). A
// narrow hump (a force of v1 that peaks at 35 mm/s over +-275 mm/s) escapes a
// degree-5 polynomial and left its rest to be taken by library effects. Where
// the table removes more by BIC it gives the variable's
// removed sum of squares and p; its chi is scaled to kSmoothDegree degrees of
// freedom for the z the verdict's |z| >= 8 reads (the polynomial keeps the
// shape said to people).
void table_fit(const std::vector<double>& x, const Eigen::VectorXd& y, SmoothFit& s) {
  // Of a speed only: a local excess along a position is the bump finder's (a
  // table of d1 took a 3x bump's place there and cogging with a spring were named).
  if (s.var.empty() || s.var[0] != 'v') return;
  const int R = static_cast<int>(x.size());
  const std::vector<double> n = table_nodes(x);
  const int m = static_cast<int>(n.size()), K = m - 1;
  if (K <= kSmoothDegree) return;
  Eigen::MatrixXd T = Eigen::MatrixXd::Zero(R, K);
  for (int r = 0; r < R; ++r) {
    const double v = x[static_cast<std::size_t>(r)];
    const auto hi = std::upper_bound(n.begin(), n.end(), v);
    const int k = std::clamp(static_cast<int>(hi - n.begin()), 1, m - 1);  // v in [n[k-1], n[k]]
    const double w = std::clamp((v - n[static_cast<std::size_t>(k - 1)]) /
                                    (n[static_cast<std::size_t>(k)] - n[static_cast<std::size_t>(k - 1)]), 0.0, 1.0);
    T(r, k - 1) += w;
    if (k >= 2) T(r, k - 2) += 1.0 - w;
  }
  T.rowwise() -= T.colwise().mean();
  const Eigen::VectorXd b = T.transpose() * y;
  const Eigen::LDLT<Eigen::MatrixXd> ldlt(T.transpose() * T);
  if (ldlt.info() != Eigen::Success) return;
  const Eigen::VectorXd coef = ldlt.solve(b);
  const double removed = std::max(0.0, coef.dot(b));
  const RemovalTest t = judge_removal(y - T * coef, removed, K, K, kSmoothPairs);
  // The table where it removes more than its extra parameters would by BIC
  // (p of either underflows to 0 for strong structure and cannot choose).
  if (!(t.unit > 0.0) || !(removed - s.removed > t.unit * (K - kSmoothDegree) * std::log(std::max(t.n_eff, 3.0)))) return;
  s.removed = removed;
  s.p = t.p;
  s.chi = t.chi * kSmoothDegree / K;
  s.table = true;
}

SmoothFit smooth_fit(const MotionProblem& P, const AxisResidual& A, const std::string& var) {
  constexpr int K = kSmoothDegree;
  const int R = P.rows();
  SmoothFit s;
  s.var = var;
  std::vector<double> x(R);
  for (int r = 0; r < R; ++r) x[r] = state_variable(P, r, var);
  const auto [mn, mx] = std::minmax_element(x.begin(), x.end());
  s.lo = *mn;
  s.hi = *mx;
  if (!(s.hi > s.lo)) return s;
  Eigen::MatrixXd X(R, K);
  double row[K];
  for (int r = 0; r < R; ++r) {
    legendre_row(x[r], s.lo, s.hi, row);
    for (int k = 0; k < K; ++k) X(r, k) = row[k];
  }
  X.rowwise() -= X.colwise().mean();
  Eigen::VectorXd y(R);
  for (int r = 0; r < R; ++r) y(r) = A.y[r] - A.mean;
  const Eigen::MatrixXd G = X.transpose() * X;
  const Eigen::VectorXd b = X.transpose() * y;
  const Eigen::LDLT<Eigen::MatrixXd> ldlt(G);
  if (ldlt.info() != Eigen::Success) return s;
  s.coef = ldlt.solve(b);
  s.removed = std::max(0.0, s.coef.dot(b));
  const RemovalTest t = judge_removal(y - X * s.coef, s.removed, K, K, kSmoothPairs);
  s.chi = t.chi;
  s.p = t.p;
  // Shares of the fitted curve: its linear part and its odd part (P1, P3, P5).
  const Eigen::VectorXd fit = X * s.coef;
  const double ff = fit.squaredNorm();
  if (ff > 0.0) {
    const double x0f = X.col(0).dot(fit), x0x0 = X.col(0).squaredNorm();
    s.linear_share = x0x0 > 0.0 ? x0f * x0f / (x0x0 * ff) : 0.0;
    Eigen::VectorXd odd = Eigen::VectorXd::Zero(R);
    for (int k = 0; k < K; k += 2) odd += X.col(k) * s.coef(k);
    s.odd_share = odd.squaredNorm() / ff;
  }
  table_fit(x, y, s);
  return s;
}

// An axis that covers less than this (m) holds still in these data: its d, v
// and a are encoder noise and the tracking error the unexplained force itself
// causes, so they follow that force without being its cause (a force on x
// was said to follow d3 "over [73.2, 73.2] mm" on a circle in xy).
constexpr double kAxisMovesAtLeast = 0.005;

std::optional<StructureFinding> smooth_finding(const MotionProblem& P, const AxisResidual& A,
                                               const std::vector<double>& span) {
  const int R = P.rows(), i = A.axis;
  std::vector<SmoothFit> fits;
  const bool has_a = P.a_columns.size() >= static_cast<std::size_t>(R) || P.a.size() >= static_cast<std::size_t>(R);
  for (const char* v : kSmoothVariables) {
    if (v[0] == 'a' && !has_a) continue;
    if (v[0] != 't' && span[static_cast<std::size_t>(v[1] - '1')] < kAxisMovesAtLeast) continue;
    fits.push_back(smooth_fit(P, A, v));
  }
  if (fits.empty()) return std::nullopt;
  const auto best = std::max_element(fits.begin(), fits.end(),
                                     [](const SmoothFit& a, const SmoothFit& b) { return a.removed < b.removed; });
  if (best->coef.size() == 0 || !(best->p < 1e-4)) return std::nullopt;
  const double size = std::sqrt(best->removed / R);
  if (!(size > A.tiny)) return std::nullopt;
  StructureFinding f;
  f.kind = "smooth";
  f.axis = i;
  f.coordinate = best->var;
  f.size = size;
  f.z = std::sqrt(best->chi);
  f.lo = best->lo;
  f.hi = best->hi;
  f.shape = best->linear_share > 0.9 ? "linear" : best->odd_share > 0.9 ? "odd" : best->odd_share < 0.1 ? "even" : "mixed";
  // The curve at 7 values across the range, less its value at the middle (the mean goes with the base).
  double row[kSmoothDegree], mid[kSmoothDegree];
  legendre_row(0.5 * (f.lo + f.hi), f.lo, f.hi, mid);
  for (int q = 0; q < 7; ++q) {
    const double x = f.lo + (f.hi - f.lo) * q / 6.0;
    legendre_row(x, f.lo, f.hi, row);
    double v = 0.0;
    for (int k = 0; k < kSmoothDegree; ++k) v += (row[k] - mid[k]) * best->coef(k);
    f.nodes.push_back(x);
    f.values.push_back(v);
  }
  // The linear part per unit of the variable: P1 = 2 (x - mid) / (hi - lo).
  f.slope = 2.0 * best->coef(0) / (f.hi - f.lo);
  const std::vector<double> xb = variable_values(P, best->var);
  for (const SmoothFit& o : fits) {
    if (&o == &*best || !(o.hi > o.lo)) continue;
    const double corr = correlation(xb, variable_values(P, o.var));
    const double share = best->removed > 0.0 ? o.removed / best->removed : 0.0;
    if (std::fabs(corr) >= kAlikeCorrelation || (o.p < 1e-4 && share >= kSmoothAlsoShare)) {
      f.also_in.push_back(o.var);
      f.alike.push_back({o.var, corr, share});
    }
  }
  // The most alike first: affine ones by |corr|, then by the share they explain.
  std::vector<std::size_t> order(f.alike.size());
  for (std::size_t k = 0; k < order.size(); ++k) order[k] = k;
  auto key = [&](std::size_t k) {
    const AlikeVariable& a = f.alike[k];
    return std::fabs(a.correlation) >= kAlikeCorrelation ? 2.0 + std::fabs(a.correlation) : a.share;
  };
  std::stable_sort(order.begin(), order.end(), [&](std::size_t a, std::size_t b) { return key(a) > key(b); });
  std::vector<AlikeVariable> sorted;
  f.also_in.clear();
  for (std::size_t k : order) {
    sorted.push_back(f.alike[k]);
    f.also_in.push_back(f.alike[k].var);
  }
  f.alike = std::move(sorted);
  const std::string unit = f.coordinate[0] == 'd' ? "m" : f.coordinate[0] == 'v' ? "m/s" : f.coordinate[0] == 'a' ? "m/s^2" : "s";
  std::ostringstream os;
  os.precision(3);
  os << "axis " << i + 1 << ": a force that follows " << f.coordinate << " (" << f.shape;
  if (f.shape == "linear") os << ", " << f.slope << " N per " << unit;
  os << ", RMS " << size << " N over " << f.coordinate << " in [" << f.lo << ", " << f.hi << "] " << unit << ")";
  if (!f.alike.empty()) {
    os << "; seen alike in";
    for (std::size_t k = 0; k < f.alike.size(); ++k) {
      const AlikeVariable& a = f.alike[k];
      os << (k ? ", " : " ") << a.var;
      if (std::fabs(a.correlation) >= kAlikeCorrelation)
        os << " (corr " << a.correlation << " with " << f.coordinate << " over the log)";
    }
  }
  f.text = os.str();
  return f;
}

// 7. A friction that varies along the axis' own travel (a friction map: guide
// wear, a lubricant that thins towards one end): sign(v_i) (c0 + g(d_i)), g
// of Legendre P_1..P_kSmoothDegree. The direction finding takes a constant
// and the smooth scan one variable; neither sees the level change: on a
// circle sign(v1) (d1 - c) averages to nothing at every value of d1, d2 or
// v1, and a 0.3-1.7 N friction on axis 1 was named a 0.27 N Coulomb friction
// beside structure on axes 2 and 3. The level's change is tested beside what
// it could be mistaken for, a Coulomb friction and smooth forces of the
// axis' own position and speed (on a single sine |v_i| follows d_i); it is
// ~ F(K, inf) under noise, look-elsewhere over the smooth scan's family and
// one more pair per axis.
constexpr double kFrictionMapFamily = kSmoothPairs + 3;

// sign(v) as the library's Coulomb friction has it, and a softer one: a
// real contact turns over a few mm/s (pre-sliding), and what the sharp sign
// left of a map that turned over 2 mm/s was named a viscous and a Stribeck
// friction beside it. The two together span switches of either width.
double friction_sign(double v) { return std::tanh(v / ctl::kSignEpsilon); }
constexpr double kSoftSignSpeed = 5e-3;  // m/s
double soft_friction_sign(double v) { return std::tanh(v / kSoftSignSpeed); }

std::optional<StructureFinding> position_friction_finding(const MotionProblem& P, const AxisResidual& A) {
  constexpr int K = kSmoothDegree;
  const int R = P.rows(), i = A.axis;
  double lo = 1e300, hi = -1e300, vlo = 1e300, vhi = -1e300;
  for (int r = 0; r < R; ++r) {
    lo = std::min(lo, P.d[r][i]);
    hi = std::max(hi, P.d[r][i]);
    vlo = std::min(vlo, P.v[r][i]);
    vhi = std::max(vhi, P.v[r][i]);
  }
  if (!(hi > lo) || !(vhi > vlo)) return std::nullopt;
  // Columns: s | soft s | P(d) | P(v) | s P(d); the last K are the level's change.
  const int C = 2 + 3 * K;
  Eigen::MatrixXd X(R, C);
  double pd[K], pv[K];
  for (int r = 0; r < R; ++r) {
    const double sg = friction_sign(P.v[r][i]);
    legendre_row(P.d[r][i], lo, hi, pd);
    legendre_row(P.v[r][i], vlo, vhi, pv);
    X(r, 0) = sg;
    X(r, 1) = soft_friction_sign(P.v[r][i]);
    for (int k = 0; k < K; ++k) {
      X(r, 2 + k) = pd[k];
      X(r, 2 + K + k) = pv[k];
      X(r, 2 + 2 * K + k) = sg * pd[k];
    }
  }
  X.rowwise() -= X.colwise().mean();
  Eigen::VectorXd y(R);
  for (int r = 0; r < R; ++r) y(r) = A.y[r] - A.mean;
  const Eigen::MatrixXd G = X.transpose() * X;
  const Eigen::VectorXd b = X.transpose() * y;
  const Eigen::LDLT<Eigen::MatrixXd> full(G), rival(G.topLeftCorner(C - K, C - K));
  if (full.info() != Eigen::Success || rival.info() != Eigen::Success) return std::nullopt;
  const Eigen::VectorXd cf = full.solve(b), cr = rival.solve(b.head(C - K));
  const double gain = cf.dot(b) - cr.dot(b.head(C - K));
  if (!(gain > 0.0) || !std::isfinite(gain)) return std::nullopt;
  const RemovalTest t = judge_removal(y - X * cf, gain, C, K, kFrictionMapFamily);
  const double chi = t.chi, p = t.p;
  if (!(p < 1e-4) || !(std::sqrt(gain / R) > A.tiny)) return std::nullopt;
  // The map said to people: sign(v) (c0 + g(d)) alone, its level at 7 places.
  // (The sharp sign only: on a circle the ends of the stroke are where the
  // speed turns, and a softer sign there took the level's place, 0.14 N
  // reported against 0.4 N.)
  Eigen::MatrixXd M(R, 1 + K);
  M.col(0) = X.col(0);
  M.rightCols(K) = X.rightCols(K);
  const Eigen::VectorXd cm = M.colPivHouseholderQr().solve(y);
  StructureFinding f;
  f.kind = "position_friction";
  f.axis = i;
  f.coordinate = cat("d", i + 1);
  f.z = std::sqrt(chi);
  f.size = std::sqrt((M * cm).squaredNorm() / R);
  f.lo = lo;
  f.hi = hi;
  int at_min = 0, at_max = 0;
  for (int q = 0; q < 7; ++q) {
    const double x = lo + (hi - lo) * q / 6.0;
    legendre_row(x, lo, hi, pd);
    double level = cm(0);
    for (int k = 0; k < K; ++k) level += cm(1 + k) * pd[k];
    f.nodes.push_back(x);
    f.values.push_back(level);
    if (level < f.values[static_cast<std::size_t>(at_min)]) at_min = q;
    if (level > f.values[static_cast<std::size_t>(at_max)]) at_max = q;
  }
  f.location = f.nodes[static_cast<std::size_t>(at_max)];
  f.slope = (f.values.back() - f.values.front()) / (hi - lo);
  double lin = 0.0, all = 0.0;
  for (int k = 0; k < K; ++k) all += cm(1 + k) * cm(1 + k) / (2.0 * k + 3.0);  // mean square of c_k P_k over [-1, 1]
  lin = cm(1) * cm(1) / 3.0;
  f.shape = all > 0.0 && lin / all > 0.9 ? "linear" : "mixed";
  std::ostringstream os;
  os.precision(3);
  os << "axis " << i + 1 << ": a friction that varies along d" << i + 1 << ": " << f.values.front() << " N at "
     << lo * 1e3 << " mm to " << f.values.back() << " N at " << hi * 1e3 << " mm";
  if (at_min != 0 && at_min != 6) os << ", least " << f.values[static_cast<std::size_t>(at_min)] << " N at " << f.nodes[static_cast<std::size_t>(at_min)] * 1e3 << " mm";
  if (at_max != 0 && at_max != 6) os << ", most " << f.values[static_cast<std::size_t>(at_max)] << " N at " << f.nodes[static_cast<std::size_t>(at_max)] * 1e3 << " mm";
  os << ", both directions (a direction-dependent force whose level follows the position; RMS " << f.size << " N)";
  f.text = os.str();
  return f;
}

// Stroke covered by each axis (m).
std::vector<double> spans(const MotionProblem& P) {
  std::vector<double> span(3);
  for (int j = 0; j < 3; ++j) {
    double mn = 1e300, mx = -1e300;
    for (int r = 0; r < P.rows(); ++r) { mn = std::min(mn, P.d[r][j]); mx = std::max(mx, P.d[r][j]); }
    span[j] = mx - mn;
  }
  return span;
}

void add(std::vector<StructureFinding>& out, std::optional<StructureFinding> f) {
  if (f) out.push_back(std::move(*f));
}

}  // namespace

double state_variable(const MotionProblem& P, int r, const std::string& name) {
  if (name == "t") return P.t[static_cast<std::size_t>(r)];
  const int j = name.size() == 2 ? name[1] - '1' : -1;
  if (j < 0 || j > 2) throw Error("unknown state variable '" + name + "' (d1..d3, v1..v3, a1..a3, t)");
  const auto rr = static_cast<std::size_t>(r);
  switch (name[0]) {
    case 'd': return P.d[rr][j];
    case 'v': return P.v[rr][j];
    // The columns' long-kernel estimate; a problem made without it (tests) has the row's own.
    case 'a': return rr < P.a_columns.size() ? P.a_columns[rr][j] : P.a[rr][j];
    default: throw Error("unknown state variable '" + name + "' (d1..d3, v1..v3, a1..a3, t)");
  }
}

void legendre_row(double x, double lo, double hi, double* out) {
  const double u = std::clamp(hi > lo ? 2.0 * (x - lo) / (hi - lo) - 1.0 : 0.0, -1.0, 1.0);
  double pm = 1.0, p = u;  // P_0, P_1
  for (int n = 1; n <= kSmoothDegree; ++n) {
    out[n - 1] = p;
    const double next = ((2.0 * n + 1.0) * u * p - n * pm) / (n + 1.0);
    pm = p;
    p = next;
  }
}

namespace {

// Columns on `axis` of functions g_k of variable `var`, k < K, a constant last:
// of a position, velocity or time, g_k of each sample's value through the rows'
// own filter, as the library's effect columns are; of an acceleration, at the row.
template <class G>
Eigen::MatrixXd columns_of_variable(const MotionProblem& P, int axis, const std::string& var, int K, G g) {
  const int R = P.rows();
  Eigen::MatrixXd X = Eigen::MatrixXd::Zero(3 * R, K + 1);
  for (int r = 0; r < R; ++r) X(3 * r + axis, K) = 1.0;
  if (var.size() == 2 && var[0] == 'a') {
    for (int r = 0; r < R; ++r)
      for (int k = 0; k < K; ++k) X(3 * r + axis, k) = g(state_variable(P, r, var), k);
    return X;
  }
  const int j = var == "t" ? -1 : var[1] - '1';
  const bool position = var[0] == 'd';
  auto at_sample = [&](int s) {
    const auto ss = static_cast<std::size_t>(s);
    return j < 0 ? P.t_sample[ss] : position ? P.d_hat[ss][j] : P.v_hat[ss][j];
  };
  for (int k = 0; k < K; ++k) X.col(k) = P.filter_axis(axis, [&](int s, int) { return g(at_sample(s), k); });
  return X;
}

}  // namespace

Eigen::MatrixXd smooth_columns(const MotionProblem& P, int axis, const std::string& var, double lo, double hi) {
  return columns_of_variable(P, axis, var, kSmoothDegree, [lo, hi](double x, int k) {
    double row[kSmoothDegree];
    legendre_row(x, lo, hi, row);
    return row[k];
  });
}

Eigen::MatrixXd table_columns(const MotionProblem& P, int axis, const std::string& var) {
  const int R = P.rows();
  std::vector<double> x(static_cast<std::size_t>(R));
  for (int r = 0; r < R; ++r) x[static_cast<std::size_t>(r)] = state_variable(P, r, var);
  const std::vector<double> n = table_nodes(std::move(x));
  if (n.size() < 3) return Eigen::MatrixXd(3 * R, 0);
  const int m = static_cast<int>(n.size());
  // Hats 1..m-1 (hat 0 is the constant less the others).
  return columns_of_variable(P, axis, var, m - 1, [&n, m](double v, int c) {
    const int k = c + 1;
    const auto ku = static_cast<std::size_t>(k);
    if (v <= n[ku - 1]) return 0.0;
    if (v <= n[ku]) return (v - n[ku - 1]) / (n[ku] - n[ku - 1]);
    if (k == m - 1) return 1.0;
    if (v <= n[ku + 1]) return (n[ku + 1] - v) / (n[ku + 1] - n[ku]);
    return 0.0;
  });
}

Eigen::MatrixXd friction_map_columns(const MotionProblem& P, int axis, double lo, double hi) {
  constexpr int K = kSmoothDegree;
  Eigen::MatrixXd X(3 * P.rows(), K + 2);
  const auto at = [&P, axis](int s) { return std::pair(P.d_hat[static_cast<std::size_t>(s)][axis], P.v_hat[static_cast<std::size_t>(s)][axis]); };
  // The level's mean is the library's Coulomb friction column itself (its
  // sign averaged over the velocity's noise near rest): a column only close
  // to it let a 30 N Coulomb friction and -29 N of this one be fitted together.
  ctl::DynamicEffect coulomb;
  coulomb.type = ctl::DynamicEffectType::coulomb_friction;
  coulomb.axis = static_cast<std::int8_t>(axis);
  coulomb.param = {1.0, 0, 0, 0};
  X.col(0) = P.effect_column(coulomb, 0);
  X.col(1) = P.filter_axis(axis, [&](int s, int) { return soft_friction_sign(at(s).second); });
  for (int k = 0; k < K; ++k)
    X.col(k + 2) = P.filter_axis(axis, [&](int s, int) {
      double row[K];
      const auto [d, v] = at(s);
      legendre_row(d, lo, hi, row);
      return friction_sign(v) * row[k];
    });
  return X;
}

std::vector<StructureFinding> find_motion_structure(const MotionProblem& P,
                                                    const Eigen::VectorXd& residual,
                                                    const Vec3& axis_noise, bool bump_beside_step) {
  std::vector<StructureFinding> out;
  const int R = P.rows();
  if (R < 20) return out;
  const std::vector<double> span = spans(P), tvec(P.t.begin(), P.t.begin() + R);
  for (int i = 0; i < 3; ++i) {
    const std::optional<AxisResidual> A = axis_residual(residual, R, i, axis_noise);
    if (!A) continue;
    add(out, direction_finding(P, *A));
    for (int j = 0; j < 3; ++j) add(out, periodic_in_position(P, *A, j, span[j]));
    add(out, periodic_in_time(tvec, *A));
    add(out, trend_in_time(tvec, *A));
    add(out, smooth_finding(P, *A, span));
    if (span[i] < kAxisMovesAtLeast) continue;
    const AlongPosition o = along_position(P, *A);
    std::optional<StructureFinding> step = step_finding(P, *A, o);
    // A bump is not reported beside a step on the same axis.
    std::optional<StructureFinding> bump = step && !bump_beside_step ? std::nullopt : bump_finding(P, *A, o);
    add(out, std::move(step));
    add(out, std::move(bump));
    add(out, position_friction_finding(P, *A));
  }
  return out;
}

}  // namespace cpm::ident
