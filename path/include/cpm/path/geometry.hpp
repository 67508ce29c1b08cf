// SPDX-License-Identifier: Apache-2.0
// The path as the planner and the real-time sampler see it: a flat array of
// pieces (lines, arcs and the corner blends between them) laid end to end
// on one path parameter s (m), with the points where the platform must stop.
//
// Corner blending: where two segments meet at an angle, both are trimmed
// back and joined by a quintic Bezier curve tangent to both, whose
// curvature at each end equals that of the segment it meets (so a blend
// between lines starts and ends straight: no step in the centripetal
// acceleration, which a circular blend arc would have). The trim is the
// largest that keeps every point of the blend within the path tolerance of
// the programmed segments and takes at most half of either segment (so the
// blends at both ends of a segment never overlap). Without tolerance, or
// between segments too short to trim, the platform stops at the corner.
//
// Frame and units: machine frame (m, z down). The parameter s is arc length
// on lines, arcs and helices; on spirals it is proportional to the angle
// and on blends a quintic of the Bezier parameter with |dp/ds| = 1 at both
// ends, so dp/ds has unit length or nearly (within 0.1 % on a spiral the
// reader accepts, a few % inside a blend); every user takes the
// derivatives as they are.
#pragma once

#include <array>
#include <cstdint>
#include <string>
#include <vector>

#include "cpm/path/path.hpp"

namespace cpm::path {

enum class PieceKind : std::uint8_t { line, arc, blend };

// A point of the path and its derivatives along s: p (m), dp/ds (1), d2p/ds2 (1/m).
struct PathPoint {
  Vec3 p = Vec3::Zero();
  Vec3 d1 = Vec3::Zero();
  Vec3 d2 = Vec3::Zero();
};

struct Piece {
  PieceKind kind = PieceKind::line;
  double s0 = 0.0;      // where it starts on the path (m)
  double length = 0.0;  // m (of the parameter s)
  // line: P[0] start, P[1] end. arc: P[0] centre, P[1], P[2] the in-plane
  // unit axes (angle 0 and pi/2), P[3] the unit normal. blend: P[0..5] the
  // Bezier control points.
  std::array<Vec3, 6> P{};
  // arc: radius at angle 0 (m), its rate (m/rad), the rise along the normal
  // (m/rad), and the angles (rad) at the piece's start and end.
  double radius = 0.0, radius_rate = 0.0, rise_rate = 0.0, angle0 = 0.0, angle1 = 0.0;
  // blend: du/ds (1/m) of the Bezier parameter u at its start and end, so
  // that |dp/ds| = 1 there and the speed joins the neighbours' without a step.
  double rate0 = 0.0, rate1 = 0.0;
  double feed = 0.0;   // programmed speed (m/s); 0: rapid
  int segment = -1;    // index of its programmed segment (blends: the segment before the corner)

  // The point at `s` from the piece's start (0 <= s <= length). noexcept, no allocation.
  [[nodiscard]] PathPoint at(double s) const noexcept;
};

// Where the platform must be at rest on the path: a corner that is not
// blended, a dwell, the start and the end.
struct Stop {
  double s = 0.0;      // m
  double dwell = 0.0;  // s held there (beyond coming to rest)
  int segment = -1;    // the programmed segment that ends there (-1: the start)
};

struct Geometry {
  std::vector<Piece> pieces;
  std::vector<Stop> stops;  // in increasing s; the first at 0, the last at length()
  std::vector<int> lines;   // the program line of each programmed segment (0: none)
  [[nodiscard]] double length() const noexcept {
    return pieces.empty() ? 0.0 : pieces.back().s0 + pieces.back().length;
  }
  // Where s is, for people: "line 12, 345.6 mm along the path" (or the segment's index).
  [[nodiscard]] std::string where(double s) const;
  // Index of the piece containing s, searched in [lo, hi] (binary search);
  // `steps` (optional) counts the search's steps.
  [[nodiscard]] int find(double s, int lo, int hi, int* steps = nullptr) const noexcept;
};

// The pieces of the programmed segments, blended within the queue's
// tolerance. Throws Error when the queue holds no motion.
Geometry blend(const PathQueue& queue);

// The programmed segments as pieces, untrimmed and unblended: the path the
// program asks for, to measure the contour error against.
Geometry programmed(const PathQueue& queue);

// The point of a piece nearest to q: its parameter s (from the piece's
// start) and the distance (m).
double distance_to_piece(const Piece& piece, const Vec3& q, double* s = nullptr) noexcept;

// The piece of one programmed line or arc, from parameter a to b along it (m).
Piece piece_of(const Segment& segment, double a, double b);
// Length (m) of the parameter s of a programmed line or arc.
double segment_length(const Segment& segment);

}  // namespace cpm::path
