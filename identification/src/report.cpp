// SPDX-License-Identifier: Apache-2.0
#include "cpm/identification/report.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <optional>
#include <sstream>

#include "cpm/identification/kinematic.hpp"
#include "cpm/identification/structure.hpp"
#include "internal.hpp"

namespace cpm::ident {

namespace detail {

double nice_step(double range, int n) {
  const double raw = range / n;
  const double mag = std::pow(10.0, std::floor(std::log10(raw)));
  for (double m : {1.0, 2.0, 5.0})
    if (m * mag >= raw) return m * mag;
  return 10.0 * mag;
}

std::string tick_text(double v, double step) {
  const int decimals = std::clamp(static_cast<int>(std::ceil(-std::log10(step) - 1e-9)), 0, 12);
  if (std::fabs(v) < 1e-9 * step) v = 0.0;
  char b[64];
  if (std::fabs(v) >= 1e7 || (v != 0.0 && std::fabs(v) < 1e-4 && decimals > 8)) std::snprintf(b, sizeof b, "%.3g", v);
  else std::snprintf(b, sizeof b, "%.*f", decimals, v);
  return b;
}

}  // namespace detail

namespace {

std::string num(double v, int prec = 4) {
  char b[64];
  std::snprintf(b, sizeof b, "%.*g", prec, v);
  return b;
}

std::string esc(const std::string& s) {
  std::string o;
  for (char c : s) {
    if (c == '<') o += "&lt;";
    else if (c == '>') o += "&gt;";
    else if (c == '&') o += "&amp;";
    else o += c;
  }
  return o;
}

struct Series {
  std::vector<double> x, y;
  std::string colour, label;
  bool line = false;
};

using detail::nice_step;
using detail::tick_text;

// A plot as inline SVG: axes with ticks, labelled, one or more series.
std::string svg_plot(const std::string& title, const std::string& xlabel, const std::string& ylabel,
                     const std::vector<Series>& series, bool logx = false) {
  // The legend sits in its own row under the title, not over the data.
  const double W = 460, H = 244, l = 58, r = 12, t = 38, b = 40;
  double x0 = 1e300, x1 = -1e300, y0 = 1e300, y1 = -1e300;
  for (const auto& s : series)
    for (std::size_t k = 0; k < s.x.size(); ++k) {
      const double xv = logx ? std::log10(std::max(1e-300, s.x[k])) : s.x[k];
      x0 = std::min(x0, xv); x1 = std::max(x1, xv);
      y0 = std::min(y0, s.y[k]); y1 = std::max(y1, s.y[k]);
    }
  if (!(x1 > x0)) { x0 -= 1; x1 += 1; }
  if (!(y1 > y0)) { y0 -= 1; y1 += 1; }
  // Axes on round numbers: the range widened to whole tick steps.
  const double ystep = nice_step(y1 - y0, 4);
  y0 = std::floor(y0 / ystep) * ystep;
  y1 = std::ceil(y1 / ystep) * ystep;
  const double xstep = logx ? 1.0 : nice_step(x1 - x0, 5);
  if (!logx) {
    x0 = std::floor(x0 / xstep) * xstep;
    x1 = std::ceil(x1 / xstep) * xstep;
  }
  auto X = [&](double v) { return l + (W - l - r) * ((logx ? std::log10(std::max(1e-300, v)) : v) - x0) / (x1 - x0); };
  auto Y = [&](double v) { return H - b - (H - t - b) * (v - y0) / (y1 - y0); };
  auto Xa = [&](double a) { return l + (W - l - r) * (a - x0) / (x1 - x0); };  // axis units (log10 for logx)
  std::ostringstream o;
  o << "<svg xmlns='http://www.w3.org/2000/svg' width='" << W << "' height='" << H
    << "' style='background:#fff;border:1px solid #ddd;margin:4px'>";
  o << "<text x='" << W / 2 << "' y='15' text-anchor='middle' font-size='13' font-weight='bold'>" << esc(title) << "</text>";
  o << "<rect x='" << l << "' y='" << t << "' width='" << W - l - r << "' height='" << H - t - b
    << "' fill='none' stroke='#888'/>";
  for (double yv = y0; yv <= y1 + 0.5 * ystep; yv += ystep) {
    const double yr = std::abs(yv) < 1e-9 * ystep ? 0.0 : yv;
    o << "<line x1='" << l << "' x2='" << W - r << "' y1='" << Y(yr) << "' y2='" << Y(yr) << "' stroke='#eee'/>";
    o << "<text x='" << l - 4 << "' y='" << Y(yr) + 4 << "' text-anchor='end' font-size='10'>" << tick_text(yr, ystep) << "</text>";
  }
  for (double xa = std::ceil(x0 / xstep) * xstep; xa <= x1 + 0.5 * xstep; xa += xstep) {
    const double xr = std::abs(xa) < 1e-9 * xstep ? 0.0 : xa;
    o << "<text x='" << Xa(xr) << "' y='" << H - b + 14 << "' text-anchor='middle' font-size='10'>"
      << (logx ? num(std::pow(10.0, xr), 4) : tick_text(xr, xstep)) << "</text>";
  }
  if (y0 < 0 && y1 > 0)
    o << "<line x1='" << l << "' x2='" << W - r << "' y1='" << Y(0) << "' y2='" << Y(0) << "' stroke='#aaa'/>";
  o << "<text x='" << (l + W - r) / 2 << "' y='" << H - 6 << "' text-anchor='middle' font-size='11'>" << esc(xlabel) << "</text>";
  o << "<text x='12' y='" << (t + H - b) / 2 << "' text-anchor='middle' font-size='11' transform='rotate(-90 12 "
    << (t + H - b) / 2 << ")'>" << esc(ylabel) << "</text>";
  double legend_used = 0.0;
  for (const auto& s : series) {
    if (s.line) {
      o << "<polyline fill='none' stroke='" << s.colour << "' stroke-width='1.2' points='";
      for (std::size_t k = 0; k < s.x.size(); ++k) o << num(X(s.x[k]), 5) << "," << num(Y(s.y[k]), 5) << " ";
      o << "'/>";
    } else {
      o << "<g fill='" << s.colour << "' fill-opacity='0.55'>";
      for (std::size_t k = 0; k < s.x.size(); ++k)
        o << "<circle cx='" << num(X(s.x[k]), 5) << "' cy='" << num(Y(s.y[k]), 5) << "' r='1.4'/>";
      o << "</g>";
    }
    if (!s.label.empty()) {
      // Entries from the right edge leftwards, about 6 px a character.
      o << "<text x='" << W - r - legend_used << "' y='" << t - 7 << "' text-anchor='end' font-size='11' fill='"
        << s.colour << "'>" << esc(s.label) << "</text>";
      legend_used += 6.0 * static_cast<double>(s.label.size()) + 14.0;
    }
  }
  o << "</svg>";
  return o.str();
}

// How far coordinate i of `d` travels (m). A coordinate that hardly moves
// is not a plot's x axis: the points would stack on one tick and what they
// show belongs to another axis.
template <class Points>
double travel(const Points& d, int i) {
  double mn = 1e300, mx = -1e300;
  for (const auto& p : d) { mn = std::min(mn, p[i]); mx = std::max(mx, p[i]); }
  return d.empty() ? 0.0 : mx - mn;
}
constexpr double kMinTravel = 1e-3;  // m
std::string not_plotted(const std::string& name, double span) {
  return "<p>" + name + " moves over " + num(span * 1e3, 3) + " mm only: not plotted against it.</p>";
}

// At most `n` evenly spaced rows.
std::vector<int> thin(int rows, int n) {
  std::vector<int> idx;
  const int step = std::max(1, rows / n);
  for (int r = 0; r < rows; r += step) idx.push_back(r);
  return idx;
}

const char* kStyle =
    "<style>body{font-family:sans-serif;margin:18px;color:#222;max-width:1450px}"
    "table{border-collapse:collapse;font-size:13px;margin:8px 0}td,th{border:1px solid #ccc;padding:3px 7px;text-align:right}"
    "th{background:#f2f2f2}td.l{text-align:left}.v{font-size:17px;padding:10px;background:#f6f9ff;border-left:4px solid #36c}"
    ".sig{background:#eaf7ea}.warn{color:#a40}</style>";

std::string plots_of(const MotionProblem& P, const Eigen::VectorXd& before, const Eigen::VectorXd* after,
                     const std::string& after_label) {
  std::ostringstream o;
  const auto idx = thin(P.rows(), 1500);
  o << "<h2>Residual over time</h2><div>";
  for (int i = 0; i < 3; ++i) {
    Series sb{{}, {}, after ? "#bbb" : "#36c", after ? "model as given" : "", false};
    Series sa{{}, {}, "#36c", after_label, false};
    for (int r : idx) {
      sb.x.push_back(P.t[r]); sb.y.push_back(before(3 * r + i));
      if (after) { sa.x.push_back(P.t[r]); sa.y.push_back((*after)(3 * r + i)); }
    }
    std::vector<Series> ss{sb};
    if (after) ss.push_back(sa);
    o << svg_plot("axis " + std::to_string(i + 1), "t (s)", "force residual (N)", ss);
  }
  o << "</div>";
  if (after) {
    // The evidence a person checks at a glance: the residual against velocity
    // (the friction map) and against position, before and after, with what the
    // named effects take out drawn over it.
    const Eigen::VectorXd fitted = before - *after;
    for (int coord = 0; coord < 2; ++coord) {
      o << (coord == 0 ? "<h2>Friction map: residual against each axis' velocity, before and after, with what the "
                         "named effects explain</h2><div>"
                       : "<h2>Residual against each axis' position, before and after, with what the named effects "
                         "explain</h2><div>");
      for (int i = 0; i < 3; ++i) {
        if (coord == 1 && travel(P.d, i) < kMinTravel) {
          o << not_plotted("d" + std::to_string(i + 1), travel(P.d, i));
          continue;
        }
        Series sb{{}, {}, "#bbb", "model as given", false}, sa{{}, {}, "#36c", after_label, false},
            sf{{}, {}, "#d33", "named effects", false};
        for (int r : idx) {
          const double x = coord == 0 ? P.v[r][i] * 1e3 : P.d[r][i] * 1e3;
          sb.x.push_back(x); sb.y.push_back(before(3 * r + i));
          sa.x.push_back(x); sa.y.push_back((*after)(3 * r + i));
          sf.x.push_back(x); sf.y.push_back(fitted(3 * r + i));
        }
        o << svg_plot("axis " + std::to_string(i + 1), coord == 0 ? "v" + std::to_string(i + 1) + " (mm/s)"
                                                                  : "d" + std::to_string(i + 1) + " (mm)",
                      "force residual (N)", {sb, sa, sf});
      }
      o << "</div>";
    }
  }
  o << "<h2>Residual along each axis' position, by direction of motion</h2><div>";
  const Eigen::VectorXd& show = after ? *after : before;
  for (int i = 0; i < 3; ++i) {
    if (travel(P.d, i) < kMinTravel) {
      o << not_plotted("d" + std::to_string(i + 1), travel(P.d, i));
      continue;
    }
    Series sp{{}, {}, "#1a7", "moving +", false}, sn{{}, {}, "#d33", "moving -", false};
    for (int r : idx) {
      Series& s = P.v[r][i] >= 0 ? sp : sn;
      s.x.push_back(P.d[r][i] * 1e3);
      s.y.push_back(show(3 * r + i));
    }
    o << svg_plot("axis " + std::to_string(i + 1) + (after ? " (" + after_label + ")" : ""),
                  "d" + std::to_string(i + 1) + " (mm)", "force residual (N)", {sp, sn});
  }
  o << "</div><h2>Periodogram against position (what repeats every λ mm of travel)</h2><div>";
  for (int i = 0; i < 3; ++i) {
    std::vector<double> x(P.rows()), y(P.rows()), wl, pw;
    double mn = 1e300, mx = -1e300;
    for (int r = 0; r < P.rows(); ++r) {
      x[r] = P.d[r][i]; y[r] = show(3 * r + i);
      mn = std::min(mn, x[r]); mx = std::max(mx, x[r]);
    }
    if (mx - mn < 0.01) {
      o << "<p>axis " << i + 1 << " moves over " << num((mx - mn) * 1e3, 3) << " mm only: no periodogram.</p>";
      continue;
    }
    periodogram(x, y, 2e-3, (mx - mn) / 1.5, wl, pw);
    Series s{{}, {}, "#639", "", true};
    for (std::size_t k = 0; k < wl.size(); ++k) {
      s.x.push_back(wl[k] * 1e3);
      s.y.push_back(std::sqrt(2.0 * pw[k] / P.rows()));
    }
    o << svg_plot("axis " + std::to_string(i + 1), "wavelength λ (mm, log)", "amplitude (N)", {s}, true);
  }
  o << "</div>";
  return o.str();
}

// Kinematic data: measurement - model (µm) per sample, against each axis'
// position (split by the direction of approach when known), against time,
// and the periodogram against position.
std::string kinematic_plots(const KinematicProblem& P, const Eigen::VectorXd& before, const Eigen::VectorXd* after,
                            const std::string& after_label) {
  std::ostringstream o;
  const int per = P.per_sample;
  const char* comp[3] = {"x", "y", "z"};
  const std::string what = P.kind == "ballbar" ? "bar length" : "position";
  const Eigen::VectorXd& show = after ? *after : before;
  o << "<h2>Measurement − model along each axis' position" << (P.has_dir ? ", by direction of approach" : "") << "</h2><div>";
  for (int i = 0; i < 3; ++i) {
    if (travel(P.d, i) < kMinTravel) {
      o << not_plotted("d" + std::to_string(i + 1), travel(P.d, i));
      continue;
    }
    Series sp{{}, {}, "#1a7", P.has_dir ? "approached +" : "", false}, sn{{}, {}, "#d33", "approached −", false};
    for (int r = 0; r < P.rows(); ++r) {
      const int j = r / per;
      Series& s = (!P.has_dir || P.inputs[static_cast<std::size_t>(j)].dir[i] > 0) ? sp : sn;
      s.x.push_back(P.d[static_cast<std::size_t>(j)][i] * 1e3);
      s.y.push_back(show(r) * 1e6);
    }
    std::vector<Series> ss{sp};
    if (P.has_dir) ss.push_back(sn);
    o << svg_plot("d" + std::to_string(i + 1) + (after ? " (" + after_label + ")" : ""), "d" + std::to_string(i + 1) + " (mm)",
                  what + " error (µm)", ss);
  }
  o << "</div><h2>Measurement − model per sample" << (P.has_time ? " over time" : "") << "</h2><div>";
  for (int k = 0; k < per; ++k) {
    Series sb{{}, {}, after ? "#bbb" : "#36c", after ? "model as given" : "", false};
    Series sa{{}, {}, "#36c", after_label, false};
    for (int j = 0; j < P.samples(); ++j) {
      const double x = P.has_time ? P.inputs[static_cast<std::size_t>(j)].t : j + 1.0;
      sb.x.push_back(x); sb.y.push_back(before(per * j + k) * 1e6);
      if (after) { sa.x.push_back(x); sa.y.push_back((*after)(per * j + k) * 1e6); }
    }
    std::vector<Series> ss{sb};
    if (after) ss.push_back(sa);
    o << svg_plot(per == 1 ? what : std::string(comp[k]), P.has_time ? "t (s)" : "sample", what + " error (µm)", ss);
  }
  o << "</div><h2>Periodogram against each axis' position (what repeats every λ mm)</h2><div>";
  for (int i = 0; i < 3; ++i) {
    std::vector<double> x, y, wl, pw;
    double mn = 1e300, mx = -1e300;
    for (int r = 0; r < P.rows(); ++r) {
      const double xv = P.d[static_cast<std::size_t>(r / per)][i];
      // The effect of axis i on this reading: divide by its sensitivity where it is large.
      const double s = P.sensitivity.rows() == P.rows() ? P.sensitivity(r, i) : 1.0;
      if (std::fabs(s) < 0.3) continue;
      x.push_back(xv); y.push_back(show(r) / s);
      mn = std::min(mn, xv); mx = std::max(mx, xv);
    }
    if (x.size() < 8 || mx - mn < 0.01) continue;
    periodogram(x, y, 1e-3, std::min(0.05, (mx - mn) / 1.5), wl, pw);
    Series s{{}, {}, "#639", "", true};
    for (std::size_t k = 0; k < wl.size(); ++k) {
      s.x.push_back(wl[k] * 1e3);
      s.y.push_back(std::sqrt(2.0 * pw[k] / static_cast<double>(x.size())) * 1e6);
    }
    o << svg_plot("axis " + std::to_string(i + 1) + " (readings it moves by ≥ 0.3 of its travel)",
                  "wavelength λ (mm, log)", "amplitude in d" + std::to_string(i + 1) + " (µm)", {s}, true);
  }
  o << "</div>";
  return o.str();
}

}  // namespace

ResidualSummary summarize(const MotionProblem& P, const Eigen::VectorXd& res, int bins) {
  ResidualSummary s;
  const int R = P.rows();
  s.rms = R ? std::sqrt(res.squaredNorm() / res.size()) : 0.0;
  s.max = R ? res.cwiseAbs().maxCoeff() : 0.0;
  for (int i = 0; i < 3; ++i) {
    double ss = 0, sf = 0, sb = 0, mf = 0, mb = 0, mx = 0;
    int nf = 0, nb = 0;
    double dmin = 1e300, dmax = -1e300;
    for (int r = 0; r < R; ++r) {
      const double e = res(3 * r + i);
      ss += e * e;
      mx = std::max(mx, std::fabs(e));
      if (P.v[r][i] > 1e-3) { sf += e * e; mf += e; ++nf; }
      if (P.v[r][i] < -1e-3) { sb += e * e; mb += e; ++nb; }
      dmin = std::min(dmin, P.d[r][i]); dmax = std::max(dmax, P.d[r][i]);
    }
    s.axis_rms[i] = std::sqrt(ss / std::max(1, R));
    s.axis_max[i] = mx;
    s.rms_forward[i] = nf ? std::sqrt(sf / nf) : 0.0;
    s.rms_backward[i] = nb ? std::sqrt(sb / nb) : 0.0;
    s.mean_forward[i] = nf ? mf / nf : 0.0;
    s.mean_backward[i] = nb ? mb / nb : 0.0;
    auto fill = [&](ResidualSummary::Bins& B, auto coord, double lo, double hi) {
      B.centre.assign(bins, 0.0); B.mean.assign(bins, 0.0); B.rms.assign(bins, 0.0); B.count.assign(bins, 0);
      const double w = (hi - lo) / bins;
      for (int b = 0; b < bins; ++b) B.centre[b] = lo + (b + 0.5) * w;
      if (!(w > 0.0)) return;
      for (int r = 0; r < R; ++r) {
        const int b = std::clamp(static_cast<int>((coord(r) - lo) / w), 0, bins - 1);
        const double e = res(3 * r + i);
        B.mean[b] += e; B.rms[b] += e * e; B.count[b]++;
      }
      for (int b = 0; b < bins; ++b)
        if (B.count[b]) { B.mean[b] /= B.count[b]; B.rms[b] = std::sqrt(B.rms[b] / B.count[b]); }
    };
    fill(s.along_position[i], [&](int r) { return P.d[r][i]; }, dmin, dmax + 1e-12);
    fill(s.over_time[i], [&](int r) { return P.t[r]; }, P.t.front(), P.t.back() + 1e-12);
    if (P.model_force.size() == res.size() && R > 1) {
      // y = residual + model force: the measured force the residual was taken from.
      double mean = 0.0;
      for (int r = 0; r < R; ++r) mean += res(3 * r + i) + P.model_force(3 * r + i);
      mean /= R;
      double spread = 0.0;
      for (int r = 0; r < R; ++r) {
        const double y = res(3 * r + i) + P.model_force(3 * r + i) - mean;
        spread += y * y;
      }
      s.fit_percent[i] = spread > 0.0 ? 100.0 * (1.0 - std::sqrt(ss / spread)) : std::nan("");
    }
  }
  return s;
}

ResidualCorrelation residual_correlation(const MotionProblem& P, const Eigen::VectorXd& res, int lags) {
  ResidualCorrelation c;
  const int R = P.rows();
  const int stride = std::max(1, P.stride);
  c.spacing = std::max(1, (2 * P.half_width + 1 + stride - 1) / stride);
  std::vector<int> rows;
  for (int r = 0; r < R; r += c.spacing) rows.push_back(r);
  const int N = static_cast<int>(rows.size());
  c.rows = N;
  c.lags = std::max(0, std::min(lags, N / 4));
  c.band = N > 0 ? 2.5758 / std::sqrt(static_cast<double>(N)) : 0.0;
  c.lag_s = N > 1 ? (P.t[static_cast<std::size_t>(rows.back())] - P.t.front()) / (N - 1) : 0.0;
  auto centred = [&](auto value) {
    std::vector<double> x(static_cast<std::size_t>(N));
    double m = 0.0;
    for (int n = 0; n < N; ++n) m += (x[static_cast<std::size_t>(n)] = value(rows[static_cast<std::size_t>(n)]));
    m /= std::max(1, N);
    for (double& v : x) v -= m;
    return x;
  };
  // r_xy(k) = sum_n x(n + k) y(n) / sqrt(sum x^2 sum y^2): x lags y by k rows.
  auto corr = [&](const std::vector<double>& x, const std::vector<double>& y, int k) {
    double sxy = 0.0, sxx = 0.0, syy = 0.0;
    for (int n = 0; n < N; ++n) {
      sxx += x[static_cast<std::size_t>(n)] * x[static_cast<std::size_t>(n)];
      syy += y[static_cast<std::size_t>(n)] * y[static_cast<std::size_t>(n)];
      if (n + k >= 0 && n + k < N) sxy += x[static_cast<std::size_t>(n + k)] * y[static_cast<std::size_t>(n)];
    }
    return sxx > 0.0 && syy > 0.0 ? sxy / std::sqrt(sxx * syy) : 0.0;
  };
  for (int i = 0; i < 3; ++i) {
    const std::vector<double> e = centred([&](int r) { return res(3 * r + i); });
    for (int k = 0; k <= c.lags; ++k) {
      const double r = corr(e, e, k);
      c.autocorrelation[i].push_back(r);
      if (k >= 1 && std::fabs(r) > c.band) ++c.auto_outside[i];
      if (k >= 1) c.auto_largest[i] = std::max(c.auto_largest[i], std::fabs(r));
    }
    const std::array<std::vector<double>, 3> inputs = {centred([&](int r) { return P.d[r][i]; }),
                                                       centred([&](int r) { return P.v[r][i]; }),
                                                       centred([&](int r) { return P.f[r][i]; })};
    for (int u = 0; u < 3; ++u)
      for (int k = -c.lags; k <= c.lags; ++k) {
        const double r = corr(e, inputs[static_cast<std::size_t>(u)], k);
        c.cross[i][u].push_back(r);
        if (std::fabs(r) > c.band) ++c.cross_outside[i][u];
      }
  }
  return c;
}

std::string correlation_text(const ResidualCorrelation& c) {
  std::ostringstream o;
  o << "residual correlation (as MATLAB's resid): " << c.rows << " rows " << num(c.lag_s * 1e3, 3)
    << " ms apart (every " << c.spacing << " kept rows: no two share a filtered sample), lags up to " << c.lags
    << ", 99 % band of a white residual +-" << num(c.band, 3) << "\n";
  static const char* input[3] = {"position", "velocity", "force"};
  for (int i = 0; i < 3; ++i) {
    o << "  axis " << i + 1 << ": autocorrelation outside the band at " << c.auto_outside[i] << " of " << c.lags
      << " lags (largest |r| " << num(c.auto_largest[i], 3) << "); cross-correlation outside at";
    for (int u = 0; u < 3; ++u)
      o << (u ? "," : "") << " " << c.cross_outside[i][u] << " of " << 2 * c.lags + 1 << " lags with " << input[u];
    o << "\n";
  }
  int outside = 0;
  for (int i = 0; i < 3; ++i) outside += c.auto_outside[i];
  // At 99 %, about 1 lag in 100 falls outside by chance.
  const double chance = 0.01 * 3 * c.lags;
  o << "  " << (outside <= std::max(2.0, 3.0 * chance) ? "the residual is white as far as these lags tell: nothing "
                                                         "the model misses shows in its correlation"
                                                       : "the residual is not white: the model misses something "
                                                         "(cpm diagnose names what)")
    << "\n";
  return o.str();
}

std::string correlation_html(const ResidualCorrelation& c) {
  std::ostringstream o;
  o << "<h2>Residual correlation (as MATLAB's resid)</h2><p>" << c.rows << " rows " << num(c.lag_s * 1e3, 3)
    << " ms apart (every " << c.spacing << " kept rows, so that no two share a filtered sample); the dashed lines are "
    << "the 99 % band of a white residual, ±" << num(c.band, 3) << ". A model that misses nothing leaves about 1 lag "
    << "in 100 outside.</p><div>";
  auto band = [&](double x0, double x1, double sign) {
    return Series{{x0, x1}, {sign * c.band, sign * c.band}, "#d33", sign > 0 ? "99 % band" : "", true};
  };
  for (int i = 0; i < 3; ++i) {
    Series a{{}, {}, "#36c", "", true};
    for (int k = 0; k <= c.lags; ++k) {
      a.x.push_back(k);
      a.y.push_back(c.autocorrelation[i][static_cast<std::size_t>(k)]);
    }
    o << svg_plot("axis " + std::to_string(i + 1) + ": autocorrelation", "lag (rows)", "r(k)",
                  {a, band(0, c.lags, 1), band(0, c.lags, -1)});
  }
  o << "</div><div>";
  static const char* input[3] = {"position", "velocity", "force"};
  static const char* colour[3] = {"#1a7", "#36c", "#639"};
  for (int i = 0; i < 3; ++i) {
    std::vector<Series> ss;
    for (int u = 0; u < 3; ++u) {
      Series x{{}, {}, colour[u], input[u], true};
      for (int k = -c.lags; k <= c.lags; ++k) {
        x.x.push_back(k);
        x.y.push_back(c.cross[i][u][static_cast<std::size_t>(k + c.lags)]);
      }
      ss.push_back(x);
    }
    ss.push_back(band(-c.lags, c.lags, 1));
    ss.push_back(band(-c.lags, c.lags, -1));
    o << svg_plot("axis " + std::to_string(i + 1) + ": cross-correlation with its inputs", "lag (rows; > 0: residual after input)",
                  "r(k)", ss);
  }
  o << "</div>";
  return o.str();
}

std::string summary_text(const ResidualSummary& s, const MotionProblem& P) {
  std::ostringstream o;
  o << "force residual (commanded - model), N, after the " << 2 * P.half_width + 1
    << "-sample zero-phase filter; acceleration: " << P.accel_source << "\n";
  o << "  all axes: RMS " << num(s.rms) << " N, max " << num(s.max) << " N over " << P.rows() << " samples\n";
  o << "  axis   RMS      max      RMS(+dir) RMS(-dir) mean(+)   mean(-)\n";
  for (int i = 0; i < 3; ++i) {
    char b[200];
    std::snprintf(b, sizeof b, "  %d   %8.4g %8.4g %9.4g %9.4g %+9.4g %+9.4g\n", i + 1, s.axis_rms[i], s.axis_max[i],
                  s.rms_forward[i], s.rms_backward[i], s.mean_forward[i], s.mean_backward[i]);
    o << b;
  }
  for (int i = 0; i < 3; ++i) {
    if (travel(P.d, i) < kMinTravel) {  // bins 0.004 mm wide would all read 73.2
      o << "  axis " << i + 1 << " moves over " << num(travel(P.d, i) * 1e3, 3) << " mm only: no breakdown along d"
        << i + 1 << "\n";
      continue;
    }
    o << "  axis " << i + 1 << " mean residual along d" << i + 1 << " (mm: N):";
    const auto& B = s.along_position[i];
    for (std::size_t b = 0; b < B.centre.size(); ++b)
      if (B.count[b]) o << " " << num(B.centre[b] * 1e3, 4) << ":" << num(B.mean[b], 3);
    o << "\n";
  }
  for (int i = 0; i < 3; ++i) {
    o << "  axis " << i + 1 << " RMS over time (s: N):";
    const auto& B = s.over_time[i];
    for (std::size_t b = 0; b < B.centre.size(); ++b)
      if (B.count[b]) o << " " << num(B.centre[b], 3) << ":" << num(B.rms[b], 3);
    o << "\n";
  }
  o << "  acceleration estimate adds about " << num(P.force_noise.maxCoeff(), 3) << " N (1 sigma) to the residual\n";
  if (std::isfinite(s.fit_percent.sum()))
    o << "  fit to the measured force (NRMSE, 100 (1 - |y - yhat| / |y - mean(y)|)): axis 1 " << num(s.fit_percent[0], 4)
      << " %, axis 2 " << num(s.fit_percent[1], 4) << " %, axis 3 " << num(s.fit_percent[2], 4) << " %\n";
  return o.str();
}

std::string diagnosis_text(const Diagnosis& D) {
  std::ostringstream o;
  const bool motion = D.kind == "motion";
  // Kinematic data in µm on screen (SI inside and in the JSON).
  const double k = motion ? 1.0 : 1e6;
  const char* u = motion ? "N" : "µm";
  if (motion) {
    const MotionProblem& P = D.motion;
    o << "data: " << D.data_file << " (kind motion, " << D.samples << " samples, " << D.rows / 3 << " filtered rows, "
      << P.segments << " segment(s))\n";
    o << "acceleration: " << P.accel_source << "; it adds about " << num(P.force_noise.maxCoeff(), 3) << " N\n";
    o << "residual of the model as given: RMS " << num(D.baseline_rms) << " N (axes " << num(D.baseline_axis_rms[0], 3)
      << ", " << num(D.baseline_axis_rms[1], 3) << ", " << num(D.baseline_axis_rms[2], 3) << "), max "
      << num(D.baseline_max) << " N; noise floor about " << num(D.noise_floor, 3) << " N\n";
  if (D.kind == "motion") {
    o << "force alignment: " << num(D.alignment.tau * 1e3, 3) << " ms";
    if (D.alignment.std_error >= 0) o << " ± " << num(D.alignment.std_error * 1e3, 2) << " ms";
    o << " (" << D.alignment.convention() << "; model's actuation_delay " << num(D.alignment.model_tau * 1e3, 3)
      << " ms)\n";
  }
    o << "after refitting the base (A, B, C, E, plane tilts): RMS " << num(D.base_refit_rms) << " N\n\n";
  } else {
    o << "data: " << D.data_file << " (kind " << D.kind << ", " << D.samples << " samples, " << D.rows << " readings)\n";
    o << "residual (model - measurement) of the model as given: RMS " << num(D.baseline_rms * k) << " µm, max "
      << num(D.baseline_max * k) << " µm\n";
    o << "after calibrating the base (" << (D.kind == "ballbar" ? "beta', dq, dl when the bar is not calibrated" : "the 12 plane parameters")
      << "): RMS " << num(D.base_refit_rms * k) << " µm " << detail::floor_after(D.base_refit_rms, D.noise_floor, D.units)
      << "\n\n";
  }
  o << "rank effect                      RMS after  explained  p(adj)     dBIC   signif  parameters\n";
  o << "                                 (" << u << ")\n";
  int rank = 0;
  for (const auto& c : D.candidates) {
    char b[200];
    std::snprintf(b, sizeof b, "%3d  %-27s %9.4g  %8.1f%%  %-9.2g %7.1f  %-6s  ", ++rank, c.label().c_str(), c.rms_after * k,
                  100.0 * c.explained, c.p_adjusted, c.delta_bic,
                  c.significant ? "YES" : (c.identifiable ? "no" : "n/a"));
    o << b;
    for (std::size_t j = 0; j < c.params.size(); ++j) {
      const auto& p = c.params[j];
      o << (j ? ", " : "") << p.name << " " << num(p.value, 4);
      if (p.std_error >= 0) o << " ± " << num(p.std_error, 2);
      o << " " << p.unit;
    }
    o << "\n";
    if (!c.note.empty()) o << "       note: " << c.note << "\n";
    for (const auto& cf : c.confounded)
      o << "       confounded with " << cf.with << " (|corr| " << num(cf.correlation, 3) << "): to separate, "
        << cf.separate_by << "\n";
  }
  o << "\nVERDICT: " << D.verdict_text << "\n";
  if (!D.structure.empty()) {
    o << "\nstructure no library effect explains (in the residual after the verdict):\n";
    for (const auto& f : D.structure) {
      o << "  - " << f.text;
      if (f.z > 0.0) o << " (" << num(f.z, 3) << " sigma)";
      o << "\n";
    }
  } else {
    o << "\nno further structure found in what remains (direction, periodic in position or time, trend, step, bump)\n";
  }
  for (const auto& n : D.notes) o << "note: " << n << "\n";
  for (const auto& w : D.warnings) o << "warning: " << w << "\n";
  return o.str();
}

// The alignment the comparison uses, and what it means: the force acts tau
// after t_k in the log; the model as given may take up to half a period
// either side of its own actuation_delay (how a log is sampled), so it is
// compared there; beyond that the model misses a delay.
std::string alignment_text(const Alignment& A) {
  char b[640];
  const double beyond = std::fabs(A.tau - A.reference);
  if (beyond < 1e-9)
    std::snprintf(b, sizeof b,
                  "force alignment: the logged force acts %.3f ms after t_k (%s), within half a sample period (%.3f ms) "
                  "of the model's actuation_delay %.3f ms: how the log was sampled. Compared there.",
                  A.tau * 1e3, A.convention().c_str(), 0.5 * A.period * 1e3, A.model_tau * 1e3);
  else
    std::snprintf(b, sizeof b,
                  "force alignment: the logged force acts %.3f ms after t_k (%s); the model's actuation_delay is %.3f "
                  "ms, and half a sample period (%.3f ms) either side of it is all a log's sampling explains. The model "
                  "as given is compared at %.3f ms, the nearest it can take: the other %.3f ms is a delay it misses "
                  "(cpm diagnose names actuation_delay), and part of the residual below.",
                  A.tau * 1e3, A.convention().c_str(), A.model_tau * 1e3, 0.5 * A.period * 1e3, A.reference * 1e3,
                  beyond * 1e3);
  return b;
}

std::string compare_html(const MotionProblem& P, const ResidualSummary& s, const std::string& title,
                         const ResidualCorrelation* correlation) {
  std::ostringstream o;
  o << "<!DOCTYPE html><html><head><meta charset='utf-8'><title>" << esc(title) << "</title>" << kStyle
    << "</head><body><h1>" << esc(title) << "</h1>";
  o << "<p>Force residual = commanded force (times the model's drive gain) − model force, per actuator, in N, after a "
    << 2 * P.half_width + 1 << "-sample zero-phase filter applied to both sides. Acceleration: " << esc(P.accel_source)
    << " (adds about " << num(P.force_noise.maxCoeff(), 3) << " N).</p>";
  o << "<table><tr><th>axis</th><th>RMS (N)</th><th>max (N)</th><th>RMS moving + (N)</th><th>RMS moving − (N)</th>"
       "<th>mean moving + (N)</th><th>mean moving − (N)</th></tr>";
  for (int i = 0; i < 3; ++i)
    o << "<tr><td>" << i + 1 << "</td><td>" << num(s.axis_rms[i]) << "</td><td>" << num(s.axis_max[i]) << "</td><td>"
      << num(s.rms_forward[i]) << "</td><td>" << num(s.rms_backward[i]) << "</td><td>" << num(s.mean_forward[i])
      << "</td><td>" << num(s.mean_backward[i]) << "</td></tr>";
  o << "<tr><th>all</th><th>" << num(s.rms) << "</th><th>" << num(s.max) << "</th><td colspan=4></td></tr></table>";
  if (std::isfinite(s.fit_percent.sum()) && P.model_force.size() == P.residual.size()) {
    o << "<h2>Measured against model (as MATLAB's compare)</h2><p>Fit: 100 (1 − ‖y − ŷ‖ / ‖y − mean(y)‖), y the "
         "measured force, ŷ the model's: axis 1 "
      << num(s.fit_percent[0], 4) << " %, axis 2 " << num(s.fit_percent[1], 4) << " %, axis 3 "
      << num(s.fit_percent[2], 4) << " %.</p><div>";
    const auto idx = thin(P.rows(), 1500);
    for (int i = 0; i < 3; ++i) {
      Series y{{}, {}, "#888", "measured", true}, yh{{}, {}, "#36c", "model", true};
      for (int r : idx) {
        y.x.push_back(P.t[r]);
        y.y.push_back(P.residual(3 * r + i) + P.model_force(3 * r + i));
        yh.x.push_back(P.t[r]);
        yh.y.push_back(P.model_force(3 * r + i));
      }
      o << svg_plot("axis " + std::to_string(i + 1) + ": fit " + num(s.fit_percent[i], 4) + " %", "t (s)", "force (N)",
                    {y, yh});
    }
    o << "</div>";
  }
  if (correlation) o << correlation_html(*correlation);
  o << plots_of(P, P.residual, nullptr, "");
  o << "</body></html>\n";
  return o.str();
}

std::string diagnosis_html(const Diagnosis& D) {
  std::ostringstream o;
  const std::string title = "cpm diagnose: " + D.data_file;
  o << "<!DOCTYPE html><html><head><meta charset='utf-8'><title>" << esc(title) << "</title>" << kStyle
    << "</head><body><h1>" << esc(title) << "</h1>";
  o << "<div class='v'><b>Verdict:</b> " << esc(D.verdict_text) << "</div>";
  const bool motion = D.kind == "motion";
  const double k = motion ? 1.0 : 1e6;
  const std::string u = motion ? "N" : "µm";
  if (motion)
    o << "<p>Residual of the model as given: RMS " << num(D.baseline_rms) << " N (max " << num(D.baseline_max)
      << " N); base refitted: " << num(D.base_refit_rms) << " N "
      << esc(detail::floor_after(D.base_refit_rms, D.noise_floor, D.units)) << ". Acceleration: " << esc(D.motion.accel_source) << ".</p>";
  else
    o << "<p>Kind " << esc(D.kind) << ", " << D.samples << " samples. Residual of the model as given: RMS "
      << num(D.baseline_rms * k) << " µm (max " << num(D.baseline_max * k) << " µm); calibrated base: "
      << num(D.base_refit_rms * k) << " µm " << esc(detail::floor_after(D.base_refit_rms, D.noise_floor, D.units))
      << ".</p>";
  o << "<h2>Candidates, best first</h2><table><tr><th>rank</th><th>effect</th><th>RMS after (" << u << ")</th><th>explained</th>"
       "<th>p (adjusted)</th><th>ΔBIC</th><th>significant</th><th>parameters (± 1σ)</th><th>confounded with</th><th>note</th></tr>";
  int rank = 0;
  for (const auto& c : D.candidates) {
    o << "<tr" << (c.significant ? " class='sig'" : "") << "><td>" << ++rank << "</td><td class='l'>" << esc(c.label())
      << "</td><td>" << num(c.rms_after * k) << "</td><td>" << num(100 * c.explained, 3) << " %</td><td>"
      << num(c.p_adjusted, 2) << "</td><td>" << num(c.delta_bic, 3) << "</td><td>"
      << (c.significant ? "yes" : (c.identifiable ? "no" : "n/a")) << "</td><td class='l'>";
    for (std::size_t j = 0; j < c.params.size(); ++j) {
      const auto& p = c.params[j];
      o << (j ? "<br>" : "") << esc(p.name) << " = " << esc(detail::human_value(p));
    }
    o << "</td><td class='l'>";
    for (const auto& cf : c.confounded)
      o << esc(cf.with) << " (" << num(cf.correlation, 3) << "; " << esc(cf.separate_by) << ")<br>";
    o << "</td><td class='l'>" << esc(c.note) << "</td></tr>";
  }
  o << "</table>";
  o << "<h2>Structure no library effect explains</h2>";
  if (D.structure.empty()) o << "<p>None found in what remains after the verdict.</p>";
  else {
    o << "<ul>";
    for (const auto& f : D.structure) o << "<li>" << esc(f.text) << " (" << num(f.z, 3) << " σ)</li>";
    o << "</ul>";
  }
  const std::string after_label =
      !D.outside_library.empty() ? "with the structure and effects found"
      : D.found().size() > 1     ? "with the " + std::to_string(D.found().size()) + " effects found"
      : D.verdict >= 0           ? "with " + D.candidates[D.verdict].label()
                                 : (motion ? "base refitted" : "calibrated base");
  if (motion) {
    const Eigen::VectorXd* after = D.residual_final.size() == D.motion.residual.size() ? &D.residual_final : nullptr;
    o << plots_of(D.motion, D.motion.residual, after, after_label);
  } else if (D.kinematic) {
    const KinematicProblem& P = *D.kinematic;
    const KinematicSummary s = summarize_kinematic(P, P.residual_given);
    if (s.circle) {
      o << "<h2>Circular test (ISO 230-4) of the model as given</h2>" << cal::circular_test_svg(*s.circle, "model as given");
      if (D.residual_final.size() == P.rows()) {
        const KinematicSummary s2 = summarize_kinematic(P, -D.residual_final);
        if (s2.circle) o << cal::circular_test_svg(*s2.circle, after_label);
      }
      if (!s.circle_note.empty()) o << "<p>" << esc(s.circle_note) << "</p>";
    }
    const Eigen::VectorXd before = -P.residual_given;
    const Eigen::VectorXd* after = D.residual_final.size() == P.rows() ? &D.residual_final : nullptr;
    o << kinematic_plots(P, before, after, after_label);
  }
  for (const auto& n : D.notes) o << "<p>" << esc(n) << "</p>";
  for (const auto& w : D.warnings) o << "<p class='warn'>" << esc(w) << "</p>";
  o << "</body></html>\n";
  return o.str();
}

// ---------------------------------------------------------------------------
// Kinematic data (ball-bar, positions): cpm compare

namespace {

constexpr double kPi = 3.141592653589793;

// RMS and mean of the residual by the direction each axis approached from.
void summarize_by_direction(const KinematicProblem& P, const Eigen::VectorXd& res, KinematicSummary& s) {
  const int per = P.per_sample;
  for (int i = 0; i < 3; ++i) {
    double sf = 0, sb = 0, mf = 0, mb = 0;
    int nf = 0, nb = 0;
    for (int r = 0; r < P.rows(); ++r) {
      const double e = res(r);
      if (P.inputs[static_cast<std::size_t>(r / per)].dir[i] > 0) { sf += e * e; mf += e; ++nf; }
      else { sb += e * e; mb += e; ++nb; }
    }
    s.rms_forward[i] = nf ? std::sqrt(sf / nf) : 0.0;
    s.rms_backward[i] = nb ? std::sqrt(sb / nb) : 0.0;
    s.mean_forward[i] = nf ? mf / nf : 0.0;
    s.mean_backward[i] = nb ? mb / nb : 0.0;
  }
}

// The measured bar ends relative to the pivot (the given model's forward
// kinematics), their mean distance R, and the machine plane they lie in when
// they lie on a circle about the pivot: within 2 % of R of the plane, their
// distance within 1 % of R (RMS). Nothing otherwise.
struct CirclePoints {
  std::vector<Vec3> v;
  double R = 0.0;
  ctl::CirclePlane plane = ctl::CirclePlane::xy;
};

std::optional<CirclePoints> circle_points(const KinematicProblem& P) {
  CirclePoints c;
  c.v.resize(static_cast<std::size_t>(P.samples()));
  double rsum = 0.0;
  for (int j = 0; j < P.samples(); ++j) {
    const auto u = static_cast<std::size_t>(j);
    Vec3 p;
    if (!kin::forward(P.given, P.d[u], P.inputs[u], p)) return std::nullopt;
    c.v[u] = p - P.pivot;
    rsum += c.v[u].norm();
  }
  c.R = rsum / P.samples();
  Vec3 mean = Vec3::Zero(), sq = Vec3::Zero();
  double rs = 0.0;
  for (const auto& x : c.v) { mean += x; rs += (x.norm() - c.R) * (x.norm() - c.R); }
  mean /= P.samples();
  for (const auto& x : c.v) sq += (x - mean).cwiseAbs2();
  Eigen::Index normal = 0;
  sq.minCoeff(&normal);
  if (std::sqrt(sq[normal] / P.samples()) > 0.02 * c.R || std::sqrt(rs / P.samples()) > 0.01 * c.R) return std::nullopt;
  c.plane = normal == 2 ? ctl::CirclePlane::xy : (normal == 0 ? ctl::CirclePlane::yz : ctl::CirclePlane::zx);
  return c;
}

// Each point's angle in the plane, in [0, 2 pi).
std::vector<double> angles_in_plane(const CirclePoints& c) {
  const auto [a, b] = cal::plane_axes(c.plane);
  std::vector<double> ang(c.v.size());
  for (std::size_t j = 0; j < c.v.size(); ++j) {
    double t = std::atan2(c.v[j][b], c.v[j][a]);
    if (t < 0) t += 2.0 * kPi;
    ang[j] = t;
  }
  return ang;
}

// The angle the points cover: the full turn less the widest gap between them.
double angular_cover(std::vector<double> all) {
  std::sort(all.begin(), all.end());
  double gap = all.front() + 2.0 * kPi - all.back();
  for (std::size_t k = 1; k < all.size(); ++k) gap = std::max(gap, all[k] - all[k - 1]);
  return 2.0 * kPi - gap;
}

// Each reading into the CCW or CW trace, by the direction of travel: the
// angle's progression to the next sample of the same run (the previous one
// at a run's end).
void split_by_travel(const KinematicProblem& P, const Eigen::VectorXd& res, const std::vector<double>& ang,
                     cal::CircularTestResult& c) {
  for (int j = 0; j < P.samples(); ++j) {
    const auto u = static_cast<std::size_t>(j);
    const long run = P.run.empty() ? 0 : P.run[u];
    int nb = j + 1 < P.samples() && (P.run.empty() || P.run[u + 1] == run) ? j + 1 : j - 1;
    if (nb < 0 || (!P.run.empty() && P.run[static_cast<std::size_t>(nb)] != run)) nb = j;
    double dth = std::remainder(ang[static_cast<std::size_t>(nb)] - ang[u], 2.0 * kPi);
    if (nb < j) dth = -dth;
    auto& tr = dth >= 0.0 ? c.ccw : c.cw;
    tr.angle.push_back(ang[u]);
    tr.deviation.push_back(-res(j));  // bar reading minus the model's distance
  }
}

void sort_by_angle(cal::CircularTrace& t) {
  std::vector<std::size_t> idx(t.angle.size());
  for (std::size_t k = 0; k < idx.size(); ++k) idx[k] = k;
  std::sort(idx.begin(), idx.end(), [&](std::size_t x, std::size_t y) { return t.angle[x] < t.angle[y]; });
  cal::CircularTrace o;
  for (auto k : idx) { o.angle.push_back(t.angle[k]); o.deviation.push_back(t.deviation[k]); }
  t = o;
}

// Ball-bar readings on a circle about the pivot in a machine plane, over at
// least 3/4 of a turn: the polar trace with G, H, F (ISO 230-4).
void summarize_circle(const KinematicProblem& P, const Eigen::VectorXd& res, KinematicSummary& s) {
  if (P.kind != "ballbar" || P.samples() < 16) return;
  const std::optional<CirclePoints> pts = circle_points(P);
  if (!pts) return;
  const std::vector<double> ang = angles_in_plane(*pts);
  cal::CircularTestResult c;
  c.spec.radius = pts->R;
  c.spec.plane = pts->plane;
  c.pivot = P.pivot;
  split_by_travel(P, res, ang, c);
  if (angular_cover(ang) < 1.5 * kPi) return;
  if (c.ccw.angle.empty() || c.cw.angle.empty()) {
    (c.ccw.angle.empty() ? c.ccw : c.cw) = c.ccw.angle.empty() ? c.cw : c.ccw;
    s.circle_note = "one direction of travel only: the hysteresis H is not measured (shown as 0)";
  }
  sort_by_angle(c.ccw);
  sort_by_angle(c.cw);
  cal::evaluate_circular_traces(c);
  s.circle = c;
}

}  // namespace

KinematicSummary summarize_kinematic(const KinematicProblem& P, const Eigen::VectorXd& res) {
  KinematicSummary s;
  const int per = P.per_sample;
  s.rms = Engine::rms(res);
  s.max = res.size() ? res.cwiseAbs().maxCoeff() : 0.0;
  for (int k = 0; k < per; ++k) {
    double q = 0.0;
    for (int j = 0; j < P.samples(); ++j) q += res(per * j + k) * res(per * j + k);
    s.component_rms[k] = std::sqrt(q / std::max(1, P.samples()));
  }
  if (P.has_dir) summarize_by_direction(P, res, s);
  summarize_circle(P, res, s);
  return s;
}

std::string kinematic_summary_text(const KinematicProblem& P, const KinematicSummary& s) {
  std::ostringstream o;
  const std::string what = P.kind == "ballbar" ? "bar length" : "platform position";
  o << what << " residual (model - measurement), µm, " << P.samples() << " samples\n";
  o << "  RMS " << num(s.rms * 1e6) << " µm, max " << num(s.max * 1e6) << " µm";
  if (P.kind == "position")
    o << " (x " << num(s.component_rms[0] * 1e6, 3) << ", y " << num(s.component_rms[1] * 1e6, 3) << ", z "
      << num(s.component_rms[2] * 1e6, 3) << ")";
  o << "\n";
  if (P.kind == "ballbar" && P.with_dl) o << "  (bar length not calibrated: its mean offset removed)\n";
  if (P.has_dir)
    for (int i = 0; i < 3; ++i)
      o << "  axis " << i + 1 << " approached +: mean " << num(s.mean_forward[i] * 1e6, 3) << " µm (RMS "
        << num(s.rms_forward[i] * 1e6, 3) << "); approached -: mean " << num(s.mean_backward[i] * 1e6, 3) << " µm (RMS "
        << num(s.rms_backward[i] * 1e6, 3) << ")\n";
  if (s.circle) {
    const auto& c = *s.circle;
    o << "  circle about the pivot in " << cal::plane_name(c.spec.plane) << ", radius " << num(c.spec.radius * 1e3, 5)
      << " mm: G " << num(c.G_bidirectional * 1e6, 3) << " µm (CCW " << num(c.ccw_metrics.G * 1e6, 3) << ", CW "
      << num(c.cw_metrics.G * 1e6, 3) << "), H " << num(c.H * 1e6, 3) << " µm, F " << num(c.F_min * 1e6, 3) << " .. "
      << num(c.F_max * 1e6, 3) << " µm\n";
    if (!s.circle_note.empty()) o << "  " << s.circle_note << "\n";
  }
  return o.str();
}

std::string kinematic_compare_html(const KinematicProblem& P, const KinematicSummary& s, const std::string& title) {
  std::ostringstream o;
  o << "<!DOCTYPE html><html><head><meta charset='utf-8'><title>" << esc(title) << "</title>" << kStyle
    << "</head><body><h1>" << esc(title) << "</h1>";
  o << "<pre>" << esc(kinematic_summary_text(P, s)) << "</pre>";
  if (s.circle) o << cal::circular_test_svg(*s.circle, "model as given");
  const Eigen::VectorXd before = -P.residual_given;
  o << kinematic_plots(P, before, nullptr, "");
  o << "</body></html>\n";
  return o.str();
}

}  // namespace cpm::ident
