// SPDX-License-Identifier: Apache-2.0
// The path's pieces and corner blends: lengths, continuity, tolerance.
#include <gtest/gtest.h>

#include <cmath>
#include <numbers>

#include "cpm/path/geometry.hpp"
#include "path_fixtures.hpp"

namespace cpm::path::test {
namespace {

constexpr double kPi = std::numbers::pi;

// Distance from q to the segment a-b, computed here.
double to_segment(const Vec3& q, const Vec3& a, const Vec3& b) {
  const double u = std::clamp((q - a).dot(b - a) / (b - a).squaredNorm(), 0.0, 1.0);
  return (a + u * (b - a) - q).norm();
}

TEST(Geometry, ArcLengthAndSweepInEveryPlane) {
  for (const Vec3& n : {Vec3(Vec3::UnitZ()), Vec3(Vec3::UnitY()), Vec3(Vec3::UnitX())}) {
    const Vec3 r0 = n.cross(Vec3(1, 1, 1)).normalized() * 0.05;
    PathQueue q(kCentre + r0);
    q.arc(kCentre - r0, kCentre, n, 1, 0.1);   // half a turn counter-clockwise
    q.arc(kCentre + r0, kCentre, n, -2, 0.1);  // back clockwise, twice round
    EXPECT_NEAR(q.segments()[0].sweep, kPi, 1e-12);
    EXPECT_NEAR(q.segments()[1].sweep, -3 * kPi, 1e-12);
    EXPECT_NEAR(segment_length(q.segments()[0]), 0.05 * kPi, 1e-12);
    EXPECT_NEAR(segment_length(q.segments()[1]), 0.05 * 3 * kPi, 1e-12);
    const Piece pc = piece_of(q.segments()[0], 0.0, 0.05 * kPi);
    const PathPoint mid = pc.at(0.025 * kPi);
    EXPECT_NEAR((mid.p - kCentre).norm(), 0.05, 1e-12);
    EXPECT_NEAR(mid.d1.norm(), 1.0, 1e-12);            // s is arc length
    EXPECT_NEAR(mid.d2.norm(), 1.0 / 0.05, 1e-9);      // curvature 1/r
    EXPECT_NEAR(mid.d1.dot(n), 0.0, 1e-12);            // in the plane
    // Counter-clockwise about n: r x t along n.
    EXPECT_GT((mid.p - kCentre).cross(mid.d1).dot(n), 0.0);
  }
}

TEST(Geometry, HelixRisesAlongTheNormal) {
  PathQueue q(kCentre + Vec3(0.05, 0, 0));
  q.arc(kCentre + Vec3(0.05, 0, 0.02), kCentre, Vec3::UnitZ(), 1, 0.1);  // one turn, 20 mm up
  const double L = segment_length(q.segments()[0]);
  EXPECT_NEAR(L, std::hypot(2 * kPi * 0.05, 0.02), 1e-12);
  const Piece pc = piece_of(q.segments()[0], 0.0, L);
  EXPECT_NEAR((pc.at(L).p - (kCentre + Vec3(0.05, 0, 0.02))).norm(), 0.0, 1e-12);
  EXPECT_NEAR(pc.at(L / 2).p.z() - kCentre.z(), 0.01, 1e-12);
}

TEST(Geometry, BlendsStayWithinTheToleranceAndJoinSmoothly) {
  for (double tol : {1e-5, 1e-4, 5e-4}) {
    const Geometry g = blend(square(0.2, 0.1, tol));
    const double h = 0.1;
    const std::array<Vec3, 5> corner{kCentre + Vec3(-h, -h, 0), kCentre + Vec3(h, -h, 0), kCentre + Vec3(h, h, 0),
                                     kCentre + Vec3(-h, h, 0), kCentre + Vec3(-h, -h, 0)};
    int blends = 0;
    for (std::size_t k = 0; k < g.pieces.size(); ++k) {
      const Piece& pc = g.pieces[k];
      if (pc.kind != PieceKind::blend) continue;
      ++blends;
      const int c = pc.segment + 1;  // the corner after its segment
      for (int i = 0; i <= 50; ++i) {
        const Vec3 q = pc.at(pc.length * i / 50).p;
        const double dev = std::min(to_segment(q, corner[c - 1], corner[c]), to_segment(q, corner[c], corner[c + 1]));
        EXPECT_LE(dev, tol * (1 + 1e-9)) << "tolerance " << tol;
      }
      // Position, direction and curvature (zero: lines) continuous at both ends.
      const Piece &before = g.pieces[k - 1], &after = g.pieces[k + 1];
      const PathPoint b0 = pc.at(0.0), b1 = pc.at(pc.length);
      EXPECT_LT((before.at(before.length).p - b0.p).norm(), 1e-12);
      EXPECT_LT((after.at(0.0).p - b1.p).norm(), 1e-12);
      EXPECT_LT((b0.d1.normalized() - before.at(before.length).d1).norm(), 1e-9);
      EXPECT_LT((b1.d1.normalized() - after.at(0.0).d1).norm(), 1e-9);
      EXPECT_LT((b0.d2 - b0.d2.dot(b0.d1.normalized()) * b0.d1.normalized()).norm(), 1e-6);
      EXPECT_NEAR(pc.s0, before.s0 + before.length, 1e-12);
    }
    EXPECT_EQ(blends, 3) << "three inner corners";
    EXPECT_EQ(g.stops.size(), 2u) << "only the start and the end";
  }
}

TEST(Geometry, WithoutToleranceEveryCornerIsAStop) {
  const Geometry g = blend(square(0.2, 0.1, 0.0));
  EXPECT_EQ(g.pieces.size(), 4u);
  EXPECT_EQ(g.stops.size(), 5u);
}

TEST(Geometry, LineIntoArcBlendMatchesTheArcsCurvature) {
  PathQueue q(kCentre + Vec3(-0.05, 0, 0), 2e-4);
  q.line(kCentre + Vec3(0.05, 0, 0), 0.1);
  q.arc(kCentre + Vec3(0, 0.05, 0), kCentre, Vec3::UnitZ(), 1, 0.1);  // a corner: the arc starts going +y
  const Geometry g = blend(q);
  ASSERT_EQ(g.pieces.size(), 3u);
  ASSERT_EQ(g.pieces[1].kind, PieceKind::blend);
  const PathPoint end = g.pieces[1].at(g.pieces[1].length), arc = g.pieces[2].at(0.0);
  const Vec3 t = end.d1.normalized();
  EXPECT_LT((t - arc.d1).norm(), 1e-9);
  const Vec3 k_blend = (end.d2 - end.d2.dot(t) * t) / end.d1.squaredNorm();
  EXPECT_NEAR((k_blend - arc.d2).norm() * 0.05, 0.0, 1e-6);  // curvature 1/r, relative
}

TEST(Geometry, NearestPointOnPieces) {
  PathQueue q(kCentre + Vec3(0.05, 0, 0));
  q.arc(kCentre + Vec3(-0.05, 0, 0), kCentre, Vec3::UnitZ(), 1, 0.1);
  const Geometry g = programmed(q);
  double s = 0.0;
  EXPECT_NEAR(distance_to_piece(g.pieces[0], kCentre + Vec3(0, 0.07, 0.001), &s), std::hypot(0.02, 0.001), 1e-12);
  EXPECT_NEAR(s, 0.05 * kPi / 2, 1e-9);
}

TEST(Geometry, QueueRefusesWhatIsNotAPath) {
  PathQueue q(kCentre);
  EXPECT_THROW(q.line(Vec3(NAN, 0, 0), 0.1), Error);
  EXPECT_THROW(q.line(kCentre + Vec3(0.01, 0, 0), -1.0), Error);
  EXPECT_THROW(q.arc(kCentre + Vec3(0.01, 0, 0), kCentre, Vec3::UnitZ(), 1, 0.1), Error);  // zero radius at start
  EXPECT_THROW(q.dwell(-1.0), Error);
  EXPECT_THROW(PathQueue(kCentre, -1e-3), Error);
  EXPECT_THROW(blend(PathQueue(kCentre)), Error);
}

}  // namespace
}  // namespace cpm::path::test
