// SPDX-License-Identifier: Apache-2.0
// Corner blending within the path tolerance (geometry.hpp says what and why).
#include <algorithm>
#include <cmath>
#include <numbers>

#include "cpm/path/geometry.hpp"
#include "internal.hpp"

namespace cpm::path {
namespace {

// Segments shorter than this are dropped: a G1 to where the platform is.
constexpr double kMinLength = 1e-9;  // m
// Junctions whose tangents differ by less than this are joined as they are:
// the velocity's direction steps by v * angle, 5e-7 m/s at 0.5 m/s.
constexpr double kJoinAngle = 1e-6;  // rad
// Near a reversal a blend would be a hairpin at almost no speed: stop instead.
constexpr double kReversalAngle = std::numbers::pi * 179.0 / 180.0;  // rad

struct Motion {
  int seg = -1;
  double length = 0.0;
  double trim_in = 0.0, trim_out = 0.0;  // m cut from the start and the end
};

struct Junction {
  bool stop = false;
  double dwell = 0.0;
  bool blended = false;
  double trim = 0.0;  // m cut from both segments for the blend
  Piece blend;
};

// Unit tangent and curvature vector (1/m) of a piece at s.
void frame_at(const Piece& pc, double s, Vec3& t, Vec3& k) {
  const PathPoint pp = pc.at(s);
  const double n2 = pp.d1.squaredNorm();
  t = pp.d1 / std::sqrt(n2);
  k = (pp.d2 - pp.d2.dot(t) * t) / n2;
}

// The blend trimming `trim` (m) from the end of A and the start of B.
Piece blend_piece(const Segment& A, double LA, const Segment& B, double trim) {
  const Piece a = piece_of(A, 0.0, LA), b = piece_of(B, 0.0, segment_length(B));
  Vec3 t0, k0, t5, k5;
  frame_at(a, LA - trim, t0, k0);
  frame_at(b, trim, t5, k5);
  // Control points three to a side along the tangents, 2/5 of the trim
  // apart, so that on a shallow corner the control polygon's five legs are
  // equal and the curve's speed dp/du nearly constant (s is then nearly arc
  // length); the third point is offset so that the curvature at each end
  // is the segment's (B''(0) = 25 h^2 k0).
  const double h = 0.4 * trim;
  Piece pc;
  pc.kind = PieceKind::blend;
  pc.P[0] = a.at(LA - trim).p;
  pc.P[5] = b.at(trim).p;
  pc.P[1] = pc.P[0] + h * t0;
  pc.P[2] = pc.P[0] + 2.0 * h * t0 + 1.25 * h * h * k0;
  pc.P[4] = pc.P[5] - h * t5;
  pc.P[3] = pc.P[5] - 2.0 * h * t5 + 1.25 * h * h * k5;
  pc.length = detail::bezier_length(pc.P);
  pc.rate0 = 1.0 / (5.0 * h);  // |dB/du| = 5 h at both ends
  pc.rate1 = pc.rate0;
  pc.feed = (A.feed > 0.0 && B.feed > 0.0) ? std::min(A.feed, B.feed) : std::max(A.feed, B.feed);
  return pc;
}

// Largest distance from the blend to the programmed corner it replaces.
double deviation(const Piece& blend, const Segment& A, double LA, const Segment& B, double trim) {
  const Piece a = piece_of(A, LA - trim, LA), b = piece_of(B, 0.0, trim);
  double worst = 0.0;
  constexpr int kSamples = 16;
  for (int k = 1; k < kSamples; ++k) {
    const Vec3 q = blend.at(blend.length * k / kSamples).p;
    worst = std::max(worst, std::min(distance_to_piece(a, q), distance_to_piece(b, q)));
  }
  return worst;
}

// The blend at the corner A -> B within `tol`, or false when none fits.
bool fit_blend(const Segment& A, double LA, const Segment& B, double LB, double tol, Piece& out, double& trim) {
  trim = 0.5 * std::min(LA, LB);
  for (int it = 0; it < 40 && trim > kMinLength; ++it) {
    out = blend_piece(A, LA, B, trim);
    const double dev = deviation(out, A, LA, B, trim);
    if (dev <= tol) return true;
    // The deviation grows about linearly with the trim.
    trim *= std::clamp(0.98 * tol / dev, 0.1, 0.9);
  }
  return false;
}

Junction junction(const Segment& A, const Motion& ma, const Segment& B, const Motion& mb, double tol) {
  Junction j;
  Vec3 ta, ka, tb, kb;
  frame_at(piece_of(A, 0.0, ma.length), ma.length, ta, ka);
  frame_at(piece_of(B, 0.0, mb.length), 0.0, tb, kb);
  const double angle = std::acos(std::clamp(ta.dot(tb), -1.0, 1.0));
  if (angle <= kJoinAngle) return j;
  if (tol <= 0.0 || angle >= kReversalAngle) {
    j.stop = true;
    return j;
  }
  j.blended = fit_blend(A, ma.length, B, mb.length, tol, j.blend, j.trim);
  j.stop = !j.blended;
  return j;
}

// The motion segments of the queue, and the dwell before each one (and after the last).
void collect(const PathQueue& q, std::vector<Motion>& motions, std::vector<double>& dwell_before, double& dwell_end) {
  double dwell = 0.0;
  bool any_dwell = false;
  const auto& segs = q.segments();
  for (std::size_t i = 0; i < segs.size(); ++i) {
    if (segs[i].kind == SegmentKind::dwell) {
      dwell += segs[i].dwell;
      any_dwell = true;
      continue;
    }
    const double L = segment_length(segs[i]);
    if (L < kMinLength) continue;
    motions.push_back(Motion{static_cast<int>(i), L});
    dwell_before.push_back(any_dwell ? std::max(dwell, 0.0) : -1.0);  // -1: no dwell there
    dwell = 0.0;
    any_dwell = false;
  }
  dwell_end = dwell;
  if (motions.empty()) throw Error("path: the queue holds no motion");
}

void set_lines(Geometry& g, const PathQueue& q) {
  for (const Segment& s : q.segments()) g.lines.push_back(s.line);
}

void add_piece(Geometry& g, Piece pc, int segment) {
  pc.s0 = g.length();
  pc.segment = segment;
  g.pieces.push_back(pc);
}

}  // namespace

Geometry blend(const PathQueue& q) {
  std::vector<Motion> m;
  std::vector<double> dwell_before;
  double dwell_end = 0.0;
  collect(q, m, dwell_before, dwell_end);
  const auto& segs = q.segments();
  std::vector<Junction> js(m.size());  // js[i]: between m[i - 1] and m[i]
  for (std::size_t i = 1; i < m.size(); ++i) {
    const Segment &A = segs[static_cast<std::size_t>(m[i - 1].seg)], &B = segs[static_cast<std::size_t>(m[i].seg)];
    if (dwell_before[i] >= 0.0) {
      js[i].stop = true;
      js[i].dwell = dwell_before[i];
      continue;
    }
    js[i] = junction(A, m[i - 1], B, m[i], q.tolerance());
    m[i - 1].trim_out = m[i].trim_in = js[i].trim;
  }
  Geometry g;
  set_lines(g, q);
  g.stops.push_back(Stop{0.0, std::max(dwell_before[0], 0.0), -1});
  for (std::size_t i = 0; i < m.size(); ++i) {
    const Segment& S = segs[static_cast<std::size_t>(m[i].seg)];
    if (i > 0 && js[i].stop) g.stops.push_back(Stop{g.length(), js[i].dwell, m[i - 1].seg});
    // A segment both blends take whole leaves nothing between them.
    if (m[i].length - m[i].trim_in - m[i].trim_out >= kMinLength)
      add_piece(g, piece_of(S, m[i].trim_in, m[i].length - m[i].trim_out), m[i].seg);
    if (i + 1 < m.size() && js[i + 1].blended) add_piece(g, js[i + 1].blend, m[i].seg);
  }
  g.stops.push_back(Stop{g.length(), dwell_end, m.back().seg});
  return g;
}

Geometry programmed(const PathQueue& q) {
  Geometry g;
  set_lines(g, q);
  const auto& segs = q.segments();
  for (std::size_t i = 0; i < segs.size(); ++i) {
    const double L = segment_length(segs[i]);
    if (segs[i].kind == SegmentKind::dwell || L < kMinLength) continue;
    add_piece(g, piece_of(segs[i], 0.0, L), static_cast<int>(i));
  }
  if (g.pieces.empty()) throw Error("path: the queue holds no motion");
  g.stops.push_back(Stop{0.0, 0.0, -1});
  g.stops.push_back(Stop{g.length(), 0.0, g.pieces.back().segment});
  return g;
}

}  // namespace cpm::path
