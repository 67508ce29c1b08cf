// SPDX-License-Identifier: Apache-2.0
// Stream files for the cpm stream tests, from closed forms (a multi-sine and
// its derivatives), written apart from the checker in cpm.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>

namespace cpm::test {

inline constexpr double kStep = 1e-3;        // s between rows

// A multi-sine about the workspace's middle, starting at rest (a raised
// cosine over the first second) and swelling to its largest at 9.8 s (an
// envelope 0.3 + 0.7 sin^2(pi t / 19.6 s)): p = c + k e(t) s(t),
// v = k (e' s + e s'), a = k (e'' s + 2 e' s' + e s'').
struct MultiSine {
  double phase = 0.0, k = 1.0;
  // A common first tone (its speed's largest values recur every half
  // period, so the envelope decides where the record falls) and one of
  // each axis' own.
  static constexpr double w[3][2] = {{2.5, 5.7}, {2.5, 4.3}, {2.5, 6.9}};
  static constexpr double a[3][2] = {{0.030, 0.004}, {0.020, 0.003}, {0.012, 0.002}};
  static void envelope(double t, double& e, double& de, double& dde) {
    const double W = M_PI / 19.6;
    const double g = 0.3 + 0.7 * std::sin(W * t) * std::sin(W * t);
    const double dg = 0.7 * W * std::sin(2 * W * t), ddg = 1.4 * W * W * std::cos(2 * W * t);
    double r = 1, dr = 0, ddr = 0;
    if (t < 1.0) {
      r = 0.5 * (1 - std::cos(M_PI * t));
      dr = 0.5 * M_PI * std::sin(M_PI * t);
      ddr = 0.5 * M_PI * M_PI * std::cos(M_PI * t);
    }
    e = r * g;
    de = dr * g + r * dg;
    dde = ddr * g + 2 * dr * dg + r * ddg;
  }
  void at(double t, double p[3], double v[3], double acc[3]) const {
    double e, de, dde;
    envelope(t, e, de, dde);
    for (int i = 0; i < 3; ++i) {
      double s = 0, ds = 0, dds = 0;
      for (int j = 0; j < 2; ++j) {
        const double q = w[i][j] * t + (j + 1) * phase + i;
        s += a[i][j] * std::sin(q);
        ds += a[i][j] * w[i][j] * std::cos(q);
        dds -= a[i][j] * w[i][j] * w[i][j] * std::sin(q);
      }
      p[i] = (i == 2 ? 0.377 : 0.425) + k * e * s;  // the soft limits' middle
      v[i] = k * (de * s + e * ds);
      acc[i] = k * (dde * s + 2 * de * ds + e * dds);
    }
  }
  [[nodiscard]] double speed(int row) const {
    double p[3], v[3], acc[3];
    at(row * kStep, p, v, acc);
    return std::sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]);
  }
  void write(const std::filesystem::path& f, int rows) const {
    std::FILE* o = std::fopen(f.c_str(), "w");
    std::fprintf(o, "t,x,y,z,vx,vy,vz\n");
    for (int r = 0; r < rows; ++r) {
      double p[3], v[3], acc[3];
      at(r * kStep, p, v, acc);
      std::fprintf(o, "%.6f,%.9f,%.9f,%.9f,%.9f,%.9f,%.9f\n", r * kStep, p[0], p[1], p[2], v[0], v[1], v[2]);
    }
    std::fclose(o);
  }
};

// The multi-sine whose speed first passes limit at data row `row` (1-based):
// a phase where that row's speed is a record by 0.1 %, scaled to pass the
// limit there by 0.05 %.
inline MultiSine over_at(int row, double limit) {
  const int i0 = row - 1;
  for (int n = 0; n < 2000; ++n) {
    MultiSine m;
    m.phase = n * 0.01;
    double before = 0;
    for (int r = 0; r < i0; ++r) before = std::max(before, m.speed(r));
    const double here = m.speed(i0);
    if (here < before * 1.001) continue;
    m.k = limit * 1.0005 / here;
    return m;
  }
  MultiSine none;
  none.k = 0;  // none found
  return none;
}

}  // namespace cpm::test
