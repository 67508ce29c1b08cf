// SPDX-License-Identifier: Apache-2.0
#include "svg.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <sstream>

namespace cpm::path::report {
namespace {

std::string fmt(double v, int digits = 4) {
  char b[48];
  std::snprintf(b, sizeof b, "%.*g", digits, v);
  return b;
}

// A round tick step (1, 2 or 5 times a power of ten) giving about n ticks.
double tick_step(double span, int n) {
  const double raw = span / n, p = std::pow(10.0, std::floor(std::log10(raw)));
  return raw <= p ? p : raw <= 2 * p ? 2 * p : raw <= 5 * p ? 5 * p : 10 * p;
}

struct Box {
  double x0 = 1e300, x1 = -1e300, y0 = 1e300, y1 = -1e300;
  void add(double x, double y) {
    x0 = std::min(x0, x), x1 = std::max(x1, x), y0 = std::min(y0, y), y1 = std::max(y1, y);
  }
  void pad() {
    if (!(x1 > x0)) x0 -= 1, x1 += 1;
    if (!(y1 > y0)) y0 -= 1, y1 += 1;
  }
};

// Blue -> cyan -> green -> yellow -> red for v in [0, 1].
std::string colour(double v) {
  v = std::clamp(v, 0.0, 1.0);
  const double r = std::clamp(2.0 * v - 0.5, 0.0, 1.0) * 255, g = (1.0 - std::abs(2.0 * v - 1.0)) * 255,
               b = std::clamp(1.0 - 2.0 * v, 0.0, 1.0) * 255;
  char out[16];
  std::snprintf(out, sizeof out, "#%02x%02x%02x", static_cast<int>(r), static_cast<int>(g), static_cast<int>(b));
  return out;
}

void axes(std::ostringstream& o, const Box& b, double W, double H, double l, double t, double r, double bt,
          const std::string& xlabel, const std::string& ylabel) {
  const auto X = [&](double x) { return l + (W - l - r) * (x - b.x0) / (b.x1 - b.x0); };
  const auto Y = [&](double y) { return H - bt - (H - t - bt) * (y - b.y0) / (b.y1 - b.y0); };
  o << "<rect x='" << l << "' y='" << t << "' width='" << W - l - r << "' height='" << H - t - bt
    << "' fill='none' stroke='#999'/>";
  const double ys = tick_step(b.y1 - b.y0, 4), xs = tick_step(b.x1 - b.x0, 6);
  for (double y = std::ceil(b.y0 / ys) * ys; y <= b.y1 + 1e-9 * ys; y += ys)
    o << "<line x1='" << l << "' x2='" << W - r << "' y1='" << Y(y) << "' y2='" << Y(y) << "' stroke='#eee'/>"
      << "<text x='" << l - 4 << "' y='" << Y(y) + 4 << "' font-size='10' text-anchor='end'>" << fmt(y) << "</text>";
  for (double x = std::ceil(b.x0 / xs) * xs; x <= b.x1 + 1e-9 * xs; x += xs)
    o << "<text x='" << X(x) << "' y='" << H - bt + 13 << "' font-size='10' text-anchor='middle'>" << fmt(x) << "</text>";
  o << "<text x='" << (l + W - r) / 2 << "' y='" << H - 4 << "' font-size='11' text-anchor='middle'>" << xlabel << "</text>"
    << "<text x='11' y='" << (t + H - bt) / 2 << "' font-size='11' text-anchor='middle' transform='rotate(-90 11 "
    << (t + H - bt) / 2 << ")'>" << ylabel << "</text>";
}

}  // namespace

std::string chart(const std::string& title, const std::string& xlabel, const std::string& ylabel,
                  const std::vector<Line>& lines, double W, double H) {
  const double l = 56, r = 10, t = 34, bt = 34;
  Box b;
  for (const Line& s : lines)
    for (std::size_t k = 0; k < s.x.size(); ++k) b.add(s.x[k], s.y[k]);
  b.pad();
  std::ostringstream o;
  o << "<svg xmlns='http://www.w3.org/2000/svg' width='" << W << "' height='" << H
    << "' style='background:#fff;margin:4px'><text x='" << W / 2
    << "' y='15' font-size='13' font-weight='bold' text-anchor='middle'>" << title << "</text>";
  axes(o, b, W, H, l, t, r, bt, xlabel, ylabel);
  double legend = W - r;
  for (const Line& s : lines) {
    o << "<polyline fill='none' stroke-width='1.1' stroke='" << s.colour << "' points='";
    for (std::size_t k = 0; k < s.x.size(); ++k)
      o << fmt(l + (W - l - r) * (s.x[k] - b.x0) / (b.x1 - b.x0), 6) << ","
        << fmt(H - bt - (H - t - bt) * (s.y[k] - b.y0) / (b.y1 - b.y0), 6) << " ";
    o << "'/><text x='" << legend << "' y='" << t - 6 << "' font-size='11' text-anchor='end' fill='" << s.colour
      << "'>" << s.label << "</text>";
    legend -= 7.0 * static_cast<double>(s.label.size()) + 16;
  }
  o << "</svg>";
  return o.str();
}

std::string coloured_path(const ColouredPath& c, double size) {
  Box b;
  for (std::size_t k = 0; k < c.px.size(); ++k) b.add(c.px[k], c.py[k]);
  b.pad();
  const double span = std::max(b.x1 - b.x0, b.y1 - b.y0) * 1.08, mx = (b.x0 + b.x1) / 2, my = (b.y0 + b.y1) / 2;
  const double m = 40, S = size - 2 * m;
  const auto X = [&](double x) { return m + S * ((x - mx) / span + 0.5); };
  const auto Y = [&](double y) { return m + S * (0.5 - (y - my) / span); };
  std::ostringstream o;
  o << "<svg xmlns='http://www.w3.org/2000/svg' width='" << size << "' height='" << size + 30
    << "' style='background:#fff;margin:4px'><text x='" << size / 2
    << "' y='18' font-size='13' font-weight='bold' text-anchor='middle'>" << c.title << "</text>";
  o << "<polyline fill='none' stroke='#bbb' stroke-width='5' points='";
  for (std::size_t k = 0; k < c.px.size(); ++k) o << fmt(X(c.px[k]), 6) << "," << fmt(Y(c.py[k]), 6) << " ";
  o << "'/>";
  // One polyline per run of points of one colour (the value in 20 steps).
  const auto level = [&](std::size_t k) { return std::lround(std::clamp(c.value[k] / c.top, 0.0, 1.0) * 20); };
  for (std::size_t first = 1; first < c.x.size();) {
    std::size_t last = first;
    while (last + 1 < c.x.size() && level(last + 1) == level(first)) ++last;
    o << "<polyline fill='none' stroke-width='2' stroke='" << colour(static_cast<double>(level(first)) / 20) << "' points='";
    for (std::size_t k = first - 1; k <= last; ++k) o << fmt(X(c.x[k]), 5) << "," << fmt(Y(c.y[k]), 5) << " ";
    o << "'/>";
    first = last + 1;
  }
  for (int k = 0; k <= 10; ++k)  // the scale
    o << "<rect x='" << m + S * k / 11.0 << "' y='" << size + 2 << "' width='" << S / 11.0 << "' height='10' fill='"
      << colour(k / 10.0) << "'/>";
  o << "<text x='" << m << "' y='" << size + 26 << "' font-size='10'>0</text><text x='" << m + S << "' y='" << size + 26
    << "' font-size='10' text-anchor='end'>" << fmt(c.top, 3) << " " << c.unit << "</text></svg>";
  return o.str();
}

}  // namespace cpm::path::report
