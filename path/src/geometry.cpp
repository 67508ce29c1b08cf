// SPDX-License-Identifier: Apache-2.0
// Evaluating pieces: lines, arcs (with the spiral and helix terms) and the
// quintic Bezier blends; their lengths; the nearest point on a piece.
#include "cpm/path/geometry.hpp"

#include <algorithm>
#include <cmath>
#include <sstream>

#include "internal.hpp"

namespace cpm::path {
namespace {

// Gauss-Legendre nodes and weights on [-1, 1], 8 points: exact for
// polynomials to degree 15, so the blends' speed (a smooth function of
// degree-4 polynomials) and the arcs' integrand are integrated to ~1e-12.
constexpr std::array<double, 8> kNodes{-0.9602898564975363, -0.7966664774136267, -0.5255324099163290,
                                       -0.1834346424956498, 0.1834346424956498,  0.5255324099163290,
                                       0.7966664774136267,  0.9602898564975363};
constexpr std::array<double, 8> kWeights{0.1012285362903763, 0.2223810344533745, 0.3137066458778873,
                                         0.3626837833783620, 0.3626837833783620, 0.3137066458778873,
                                         0.2223810344533745, 0.1012285362903763};

template <class F>
double integrate(F f, double a, double b, int parts) {
  double sum = 0.0;
  const double h = (b - a) / parts;
  for (int k = 0; k < parts; ++k) {
    const double m = a + (k + 0.5) * h;
    for (std::size_t i = 0; i < kNodes.size(); ++i) sum += kWeights[i] * f(m + 0.5 * h * kNodes[i]);
  }
  return 0.5 * h * sum;
}

// Position and derivatives of an arc with respect to its angle.
void arc_at_angle(const Piece& a, double th, Vec3& p, Vec3& d1, Vec3& d2) noexcept {
  const double c = std::cos(th), s = std::sin(th);
  const Vec3 u = c * a.P[1] + s * a.P[2];
  const Vec3 w = -s * a.P[1] + c * a.P[2];
  const double r = a.radius + a.radius_rate * th;
  p = a.P[0] + r * u + a.rise_rate * th * a.P[3];
  d1 = a.radius_rate * u + r * w + a.rise_rate * a.P[3];
  d2 = 2.0 * a.radius_rate * w - r * u;
}

// Quintic Bezier and its first two derivatives with respect to u in [0, 1].
void bezier_at(const std::array<Vec3, 6>& P, double u, Vec3& p, Vec3& d1, Vec3& d2) noexcept {
  const double v = 1.0 - u;
  const double u2 = u * u, v2 = v * v;
  const std::array<double, 6> b5{v2 * v2 * v, 5 * u * v2 * v2, 10 * u2 * v2 * v, 10 * u2 * u * v2, 5 * u2 * u2 * v,
                                 u2 * u2 * u};
  const std::array<double, 5> b4{v2 * v2, 4 * u * v2 * v, 6 * u2 * v2, 4 * u2 * u * v, u2 * u2};
  const std::array<double, 4> b3{v2 * v, 3 * u * v2, 3 * u2 * v, u2 * u};
  p.setZero();
  d1.setZero();
  d2.setZero();
  for (int i = 0; i < 6; ++i) p += b5[i] * P[i];
  for (int i = 0; i < 5; ++i) d1 += (5.0 * b4[i]) * (P[i + 1] - P[i]);
  for (int i = 0; i < 4; ++i) d2 += (20.0 * b3[i]) * (P[i + 2] - 2.0 * P[i + 1] + P[i]);
}

// The blend's parameter u in [0, 1] at s, and du/ds, d2u/ds2: a quintic in
// s whose rate at each end makes |dp/ds| = 1 there (P[0..5] alone give
// |dB/du| / length, not 1, and the speed would step at the blend's ends).
void blend_parameter(const Piece& b, double s, double& u, double& du, double& ddu) noexcept {
  const double L = b.length;
  detail::quintic_hermite({0.0, b.rate0, 0.0, 1.0, b.rate1, 0.0}, L, s / L, u, du, ddu);
}

double arc_speed(const Piece& a, double th) {
  const double r = a.radius + a.radius_rate * th;
  return std::sqrt(r * r + a.radius_rate * a.radius_rate + a.rise_rate * a.rise_rate);
}

// The arc's constants (centre, axes, radius and its rate, rise), angles unset.
Piece arc_constants(const Segment& seg) {
  Piece pc;
  pc.kind = PieceKind::arc;
  const Vec3& n = seg.normal;
  const Vec3 r0 = seg.start - seg.centre;
  pc.P[0] = seg.centre;
  pc.P[1] = r0.normalized();
  pc.P[2] = n.cross(pc.P[1]);
  pc.P[3] = n;
  const Vec3 q = seg.end - seg.centre;
  const double h = q.dot(n);
  pc.radius = r0.norm();
  pc.radius_rate = ((q - h * n).norm() - pc.radius) / seg.sweep;
  pc.rise_rate = h / seg.sweep;
  return pc;
}

double arc_length(const Piece& a, double sweep) {
  const int parts = 1 + static_cast<int>(std::abs(sweep) / 1.5);
  const double lo = std::min(0.0, sweep), hi = std::max(0.0, sweep);
  return integrate([&](double th) { return arc_speed(a, th); }, lo, hi, parts);
}

}  // namespace

PathPoint Piece::at(double s) const noexcept {
  PathPoint out;
  switch (kind) {
    case PieceKind::line: {
      const Vec3 d = P[1] - P[0];
      out.d1 = length > 0.0 ? Vec3(d / length) : Vec3::Zero();
      out.p = P[0] + s * out.d1;
      break;
    }
    case PieceKind::arc: {
      const double rate = length > 0.0 ? (angle1 - angle0) / length : 0.0;  // rad per m
      arc_at_angle(*this, angle0 + rate * s, out.p, out.d1, out.d2);
      out.d1 *= rate;
      out.d2 *= rate * rate;
      break;
    }
    case PieceKind::blend: {
      double u, du, ddu;
      blend_parameter(*this, s, u, du, ddu);
      Vec3 b1, b2;
      bezier_at(P, u, out.p, b1, b2);
      out.d1 = b1 * du;
      out.d2 = b2 * (du * du) + b1 * ddu;
      break;
    }
  }
  return out;
}

int Geometry::find(double s, int lo, int hi, int* steps) const noexcept {
  // The last piece whose start is <= s.
  while (lo < hi) {
    if (steps) ++*steps;
    const int mid = (lo + hi + 1) / 2;
    if (pieces[static_cast<std::size_t>(mid)].s0 <= s) lo = mid;
    else hi = mid - 1;
  }
  return lo;
}

std::string Geometry::where(double s) const {
  std::ostringstream o;
  const int seg = pieces[static_cast<std::size_t>(find(s, 0, static_cast<int>(pieces.size()) - 1))].segment;
  const int line = seg >= 0 && static_cast<std::size_t>(seg) < lines.size() ? lines[static_cast<std::size_t>(seg)] : 0;
  if (line > 0) o << "line " << line;
  else o << "segment " << seg;
  o << ", " << s * 1e3 << " mm along the path";
  return o.str();
}

double segment_length(const Segment& seg) {
  if (seg.kind == SegmentKind::line) return (seg.end - seg.start).norm();
  if (seg.kind == SegmentKind::dwell) return 0.0;
  return arc_length(arc_constants(seg), seg.sweep);
}

Piece piece_of(const Segment& seg, double a, double b) {
  Piece pc;
  if (seg.kind == SegmentKind::line) {
    const double L = (seg.end - seg.start).norm();
    const Vec3 dir = L > 0.0 ? Vec3((seg.end - seg.start) / L) : Vec3::Zero();
    pc.P[0] = seg.start + a * dir;
    pc.P[1] = seg.start + b * dir;
  } else {
    pc = arc_constants(seg);
    const double L = arc_length(pc, seg.sweep);
    pc.angle0 = seg.sweep * a / L;
    pc.angle1 = seg.sweep * b / L;
  }
  pc.feed = seg.feed;
  pc.length = b - a;
  return pc;
}

double distance_to_piece(const Piece& piece, const Vec3& q, double* s_out) noexcept {
  const double L = piece.length;
  double best_s = 0.0, best = (piece.at(0.0).p - q).squaredNorm();
  if (piece.kind == PieceKind::line) {
    const Vec3 d = piece.P[1] - piece.P[0];
    const double dd = d.squaredNorm();
    const double u = dd > 0.0 ? std::clamp((q - piece.P[0]).dot(d) / dd, 0.0, 1.0) : 0.0;
    if (s_out) *s_out = u * L;
    return (piece.P[0] + u * d - q).norm();
  }
  // Coarse samples, then Newton on (p(s) - q) . p'(s) = 0 from the two
  // nearest (a full circle's ends are one point: one of them may be stuck
  // at its end of the range).
  constexpr int kCoarse = 24;
  double second_s = 0.0, second = 1e300;
  for (int k = 1; k <= kCoarse; ++k) {
    const double s = L * k / kCoarse;
    const double e = (piece.at(s).p - q).squaredNorm();
    if (e < best) second = best, second_s = best_s, best = e, best_s = s;
    else if (e < second) second = e, second_s = s;
  }
  for (double s : {best_s, second_s}) {
    for (int it = 0; it < 8; ++it) {
      const PathPoint pp = piece.at(s);
      const Vec3 r = pp.p - q;
      const double f = r.dot(pp.d1), df = pp.d1.squaredNorm() + r.dot(pp.d2);
      if (df <= 0.0) break;
      s = std::clamp(s - f / df, 0.0, L);
    }
    const double e = (piece.at(s).p - q).squaredNorm();
    if (e < best) best = e, best_s = s;
  }
  if (s_out) *s_out = best_s;
  return std::sqrt(best);
}

void detail::quintic_hermite(const std::array<double, 6>& y, double h, double tau, double& v, double& d1,
                             double& d2) noexcept {
  const double t2 = tau * tau, t3 = t2 * tau, t4 = t3 * tau, t5 = t4 * tau;
  const double w[6] = {y[0], h * y[1], h * h * y[2], h * h * y[5], h * y[4], y[3]};
  const double H[6] = {1 - 10 * t3 + 15 * t4 - 6 * t5, tau - 6 * t3 + 8 * t4 - 3 * t5,
                       0.5 * (t2 - 3 * t3 + 3 * t4 - t5), 0.5 * (t3 - 2 * t4 + t5),
                       -4 * t3 + 7 * t4 - 3 * t5, 10 * t3 - 15 * t4 + 6 * t5};
  const double D[6] = {-30 * t2 + 60 * t3 - 30 * t4, 1 - 18 * t2 + 32 * t3 - 15 * t4,
                       0.5 * (2 * tau - 9 * t2 + 12 * t3 - 5 * t4), 0.5 * (3 * t2 - 8 * t3 + 5 * t4),
                       -12 * t2 + 28 * t3 - 15 * t4, 30 * t2 - 60 * t3 + 30 * t4};
  const double DD[6] = {-60 * tau + 180 * t2 - 120 * t3, -36 * tau + 96 * t2 - 60 * t3,
                        0.5 * (2 - 18 * tau + 36 * t2 - 20 * t3), 0.5 * (6 * tau - 24 * t2 + 20 * t3),
                        -24 * tau + 84 * t2 - 60 * t3, 60 * tau - 180 * t2 + 120 * t3};
  v = d1 = d2 = 0.0;
  for (int i = 0; i < 6; ++i) {
    v += H[i] * w[i];
    d1 += D[i] * w[i];
    d2 += DD[i] * w[i];
  }
  d1 /= h;
  d2 /= h * h;
}

double detail::bezier_length(const std::array<Vec3, 6>& P) {
  return integrate(
      [&](double u) {
        Vec3 p, d1, d2;
        bezier_at(P, u, p, d1, d2);
        return d1.norm();
      },
      0.0, 1.0, 2);
}

}  // namespace cpm::path
