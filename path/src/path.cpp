// SPDX-License-Identifier: Apache-2.0
#include "cpm/path/path.hpp"

#include <cmath>
#include <numbers>
#include <sstream>

namespace cpm::path {
namespace {

constexpr double kTwoPi = 2.0 * std::numbers::pi;

void check_finite(const Vec3& v, const char* what) {
  if (!v.allFinite()) throw Error(std::string("path: ") + what + " is not a finite point");
}

void check_feed(double feed) {
  if (!std::isfinite(feed) || feed < 0.0) {
    std::ostringstream o;
    o << "path: a feed must be >= 0 m/s (0: rapid), got " << feed;
    throw Error(o.str());
  }
}

}  // namespace

double arc_sweep(const Vec3& start, const Vec3& end, const Vec3& centre, const Vec3& normal, int turns) noexcept {
  const Vec3 r0 = start - centre;
  const Vec3 e1 = (r0 - r0.dot(normal) * normal).normalized();
  const Vec3 e2 = normal.cross(e1);
  const Vec3 q = end - centre;
  double angle = std::atan2(q.dot(e2), q.dot(e1));  // (-pi, pi]
  const int n = turns == 0 ? 1 : std::abs(turns);
  if (turns >= 0) {
    if (angle <= 0.0) angle += kTwoPi;  // an end on the start is a full turn
    return angle + (n - 1) * kTwoPi;
  }
  if (angle >= 0.0) angle -= kTwoPi;
  return angle - (n - 1) * kTwoPi;
}

PathQueue::PathQueue(const Vec3& start, double tolerance) : start_(start), end_(start), tolerance_(tolerance) {
  check_finite(start, "the start");
  if (!std::isfinite(tolerance) || tolerance < 0.0) throw Error("path: the path tolerance must be >= 0 m");
}

void PathQueue::line(const Vec3& end, double feed, int line) {
  check_finite(end, "a line's end");
  check_feed(feed);
  Segment s;
  s.kind = SegmentKind::line;
  s.start = end_;
  s.end = end;
  s.feed = feed;
  s.line = line;
  segments_.push_back(s);
  end_ = end;
}

void PathQueue::rapid(const Vec3& end, int line) { this->line(end, 0.0, line); }

void PathQueue::arc(const Vec3& end, const Vec3& centre, const Vec3& normal, int turns, double feed, int line) {
  check_finite(end, "an arc's end");
  check_finite(centre, "an arc's centre");
  check_feed(feed);
  if (!normal.allFinite() || std::abs(normal.norm() - 1.0) > 1e-9)
    throw Error("path: an arc's normal must be a unit vector");
  Segment s;
  s.kind = SegmentKind::arc;
  s.start = end_;
  s.end = end;
  s.normal = normal;
  // The centre on the plane through the start: a helix rises from there.
  s.centre = centre + (end_ - centre).dot(normal) * normal;
  const double r0 = (end_ - s.centre).norm();
  const Vec3 q = end - s.centre;
  const double r1 = (q - q.dot(normal) * normal).norm();
  if (r0 < 1e-9 || r1 < 1e-9) throw Error("path: an arc of zero radius");
  s.sweep = arc_sweep(end_, end, s.centre, normal, turns);
  s.turns = turns;
  s.feed = feed;
  s.line = line;
  segments_.push_back(s);
  end_ = end;
}

void PathQueue::dwell(double seconds, int line) {
  if (!std::isfinite(seconds) || seconds < 0.0) throw Error("path: a dwell must be >= 0 s");
  Segment s;
  s.kind = SegmentKind::dwell;
  s.start = s.end = end_;
  s.dwell = seconds;
  s.line = line;
  segments_.push_back(s);
}

}  // namespace cpm::path
