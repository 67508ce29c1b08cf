#include "cpm/identification/structure.hpp"

#include <algorithm>
#include <cmath>
#include <numbers>
#include <sstream>

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

std::vector<StructureFinding> find_motion_structure(const MotionProblem& P,
                                                    const Eigen::VectorXd& residual,
                                                    const Vec3& axis_noise) {
  std::vector<StructureFinding> out;
  const int R = P.rows();
  if (R < 20) return out;
  std::vector<double> span(3), tvec(R);
  for (int r = 0; r < R; ++r) tvec[r] = P.t[r];
  for (int j = 0; j < 3; ++j) {
    double mn = 1e300, mx = -1e300;
    for (int r = 0; r < R; ++r) { mn = std::min(mn, P.d[r][j]); mx = std::max(mx, P.d[r][j]); }
    span[j] = mx - mn;
  }
  for (int i = 0; i < 3; ++i) {
    std::vector<double> y(R);
    for (int r = 0; r < R; ++r) y[r] = residual(3 * r + i);
    const double my = mean(y);
    double var = 0.0;
    for (double v : y) var += (v - my) * (v - my);
    var /= R;
    const double ne = effective_samples({y});
    const double infl = static_cast<double>(R) / std::max(2.0, ne);
    const double sd = std::sqrt(var);
    if (!(sd > 0.0)) continue;
    // Size below which a finding is not worth a sentence: a third of the noise.
    const double tiny = std::max(0.3 * axis_noise[i], 1e-12);
    // 1. direction of motion of this axis
    {
      std::vector<double> pos, neg;
      for (int r = 0; r < R; ++r) {
        if (P.v[r][i] > 2e-3) pos.push_back(y[r]);
        if (P.v[r][i] < -2e-3) neg.push_back(y[r]);
      }
      if (pos.size() > 10 && neg.size() > 10) {
        const double diff = mean(pos) - mean(neg);
        const double se = sd * std::sqrt(infl * (1.0 / pos.size() + 1.0 / neg.size()));
        const double z = diff / se;
        if (std::fabs(z) > 5.0 && std::fabs(diff) > tiny)
          out.push_back({"direction", i, cat("v", i + 1), 0.0, diff, z,
                         cat("axis ", i + 1, ": the residual differs by ", diff, " N between moving forward and backward (direction-dependent force)")});
      }
    }
    // 2. periodic against each axis' position
    for (int j = 0; j < 3; ++j) {
      if (span[j] < 0.01) continue;
      std::vector<double> x(R), wl, pw;
      for (int r = 0; r < R; ++r) x[r] = P.d[r][j];
      periodogram(x, y, 2e-3, span[j] / 1.5, wl, pw);
      if (pw.empty()) continue;
      const auto it = std::max_element(pw.begin(), pw.end());
      const double trials = span[j] * (1.0 / 2e-3 - 1.5 / span[j]);
      const double chi = *it / (var * infl);  // ~ chi^2 with 2 dof under noise
      const double p = std::min(1.0, std::exp(-0.5 * chi) * std::max(1.0, trials) * 9.0);
      const double amp = std::sqrt(2.0 * *it / R);
      if (p < 1e-4 && amp > tiny) {
        const double lam = wl[static_cast<std::size_t>(it - pw.begin())];
        out.push_back({"periodic", i, cat("d", j + 1), lam, amp, std::sqrt(chi),
                       cat("axis ", i + 1, ": a force periodic in the position of axis ", j + 1, ", wavelength ", lam * 1e3, " mm, amplitude ", amp, " N")});
      }
    }
    // 3. periodic in time
    {
      const double T = tvec.back() - tvec.front();
      std::vector<double> wl, pw;
      const double rowdt = R > 1 ? T / (R - 1) : 1.0;
      periodogram(tvec, y, 4.0 * rowdt, T / 2.0, wl, pw);
      if (!pw.empty()) {
        const auto it = std::max_element(pw.begin(), pw.end());
        const double chi = *it / (var * infl);
        const double trials = T * (1.0 / (4.0 * rowdt));
        const double p = std::min(1.0, std::exp(-0.5 * chi) * std::max(1.0, trials) * 3.0);
        const double amp = std::sqrt(2.0 * *it / R);
        if (p < 1e-4 && amp > tiny) {
          const double per = wl[static_cast<std::size_t>(it - pw.begin())];
          out.push_back({"periodic_time", i, "t", per, amp, std::sqrt(chi),
                         cat("axis ", i + 1, ": a force periodic in time, period ", per, " s (", 1.0 / per, " Hz), amplitude ", amp, " N")});
        }
      }
    }
    // 4. trend in time
    {
      const double tm = mean(tvec);
      double stt = 0, sty = 0;
      for (int r = 0; r < R; ++r) { stt += (tvec[r] - tm) * (tvec[r] - tm); sty += (tvec[r] - tm) * (y[r] - my); }
      if (stt > 0.0) {
        const double slope = sty / stt;
        const double z = slope / (sd * std::sqrt(infl / stt));
        const double change = slope * (tvec.back() - tvec.front());
        if (std::fabs(z) > 5.0 && std::fabs(change) > tiny)
          out.push_back({"trend", i, "t", tvec.back(), change, z,
                         cat("axis ", i + 1, ": the residual drifts by ", change, " N over the ", tvec.back() - tvec.front(), " s of the log")});
      }
    }
    // 5. a step or a bump along this axis' position
    if (span[i] >= 0.005) {
      std::vector<int> idx(R);
      for (int r = 0; r < R; ++r) idx[r] = r;
      std::sort(idx.begin(), idx.end(), [&](int a, int b) { return P.d[a][i] < P.d[b][i]; });
      std::vector<double> cum(R + 1, 0.0);
      for (int r = 0; r < R; ++r) cum[r + 1] = cum[r] + (y[idx[r]] - my);
      double best_z = 0.0, best_diff = 0.0, best_x = 0.0;
      const int lo = std::max(10, R / 20), hi = R - lo;
      for (int s = lo; s < hi; s += std::max(1, R / 200)) {
        const double ml = cum[s] / s, mr = (cum[R] - cum[s]) / (R - s);
        const double se = sd * std::sqrt(infl * (1.0 / s + 1.0 / (R - s)));
        const double z = (mr - ml) / se;
        if (std::fabs(z) > std::fabs(best_z)) {
          best_z = z;
          best_diff = mr - ml;
          best_x = 0.5 * (P.d[idx[s - 1]][i] + P.d[idx[s]][i]);
        }
      }
      if (std::fabs(best_z) > 6.0 && std::fabs(best_diff) > tiny)
        out.push_back({"step", i, cat("d", i + 1), best_x, best_diff, best_z,
                       cat("axis ", i + 1, ": the residual changes by ", best_diff, " N across d", i + 1, " = ", best_x * 1e3, " mm")});
      // bump: 20 bins of equal count
      const int B = 20;
      double bz = 0.0, bmean = 0.0, bx = 0.0, blo = 0.0, bhi = 0.0;
      for (int b = 0; b < B; ++b) {
        const int a0 = b * R / B, a1 = (b + 1) * R / B;
        if (a1 - a0 < 5) continue;
        const double m = (cum[a1] - cum[a0]) / (a1 - a0);
        const double z = m / (sd * std::sqrt(infl / (a1 - a0)));
        if (std::fabs(z) > std::fabs(bz)) {
          bz = z;
          bmean = m;
          bx = P.d[idx[(a0 + a1) / 2]][i];
          blo = P.d[idx[a0]][i];
          bhi = P.d[idx[a1 - 1]][i];
        }
      }
      const bool near_step = !out.empty() && out.back().kind == "step" && out.back().axis == i;
      if (std::fabs(bz) > 6.0 && std::fabs(bmean) > tiny && !near_step)
        out.push_back({"bump", i, cat("d", i + 1), bx, bmean, bz,
                       cat("axis ", i + 1, ": a local excess of ", bmean, " N around d", i + 1, " = ", bx * 1e3, " mm"),
                       blo, bhi});
    }
  }
  return out;
}

}  // namespace cpm::ident
