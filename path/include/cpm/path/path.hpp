// SPDX-License-Identifier: Apache-2.0
// A programmed path: lines, circular arcs in any plane and dwells, one after
// the other from a start point, with the path tolerance within which the
// planner may round the corners between them.
//
// Frame and units: the machine frame of docs/model.md (m, z down); feeds in
// m/s along the path, dwells in s, angles in rad. The G-code reader
// (gcode.hpp) converts a program's units and frame into this.
#pragma once

#include <cstdint>
#include <vector>

#include "cpm/kinematics/types.hpp"

namespace cpm::path {

enum class SegmentKind : std::uint8_t { line, arc, dwell };

// One programmed segment. Lines and arcs go from `start` to `end`; a dwell
// holds the platform at `start` (= `end`).
struct Segment {
  SegmentKind kind = SegmentKind::line;
  Vec3 start = Vec3::Zero(), end = Vec3::Zero();
  // Arcs: the centre on the plane through `start`, the plane's unit normal,
  // and the signed angle swept about the normal (> 0: counter-clockwise seen
  // from the normal's tip). The radius may change linearly with the angle
  // from |start - centre| to that of `end` (a spiral within the G-code
  // reader's radius tolerance), and `end` may lie off the start's plane
  // along the normal (a helix).
  Vec3 centre = Vec3::Zero(), normal = Vec3::UnitZ();
  double sweep = 0.0;
  int turns = 0;       // arcs: as given to PathQueue::arc (the sweep is made from it)
  double feed = 0.0;   // programmed speed along the path (m/s); 0: rapid, the planner's ceiling
  double dwell = 0.0;  // s, dwells only
  int line = 0;        // where it came from (a program's line number; 0: none)
};

// The queue of segments a plan is made from. Each segment starts where the
// previous one ended; the queue checks what it is given and throws Error
// saying what is wrong (non-finite numbers, a zero-radius arc, a negative
// feed or dwell).
class PathQueue {
 public:
  // `tolerance`: how far (m) the planned path may leave the programmed one
  // to round a corner; 0: no rounding, the platform stops at every corner.
  explicit PathQueue(const Vec3& start, double tolerance = 0.0);

  void line(const Vec3& end, double feed, int line = 0);
  void rapid(const Vec3& end, int line = 0);  // a line at the planner's velocity ceiling
  // An arc about `centre` in the plane of unit normal `normal` to `end`:
  // `turns` > 0 counter-clockwise about the normal, < 0 clockwise, |turns|
  // the number of times it passes the end angle (as rs274's ARC_FEED
  // rotation: 1 is at most one turn).
  void arc(const Vec3& end, const Vec3& centre, const Vec3& normal, int turns, double feed, int line = 0);
  void dwell(double seconds, int line = 0);

  [[nodiscard]] const std::vector<Segment>& segments() const noexcept { return segments_; }
  [[nodiscard]] const Vec3& start() const noexcept { return start_; }
  [[nodiscard]] const Vec3& end() const noexcept { return end_; }
  [[nodiscard]] double tolerance() const noexcept { return tolerance_; }
  [[nodiscard]] bool empty() const noexcept { return segments_.empty(); }

 private:
  std::vector<Segment> segments_;
  Vec3 start_, end_;
  double tolerance_;
};

// Signed sweep (rad) of an arc from `start` to `end` about `centre` and the
// unit `normal`, as rs274 counts it: `turns` > 0 counter-clockwise, in
// (0, 2 pi] for one turn (an end on the start is a full circle), plus
// 2 pi for every further turn; < 0 the same clockwise.
double arc_sweep(const Vec3& start, const Vec3& end, const Vec3& centre, const Vec3& normal, int turns) noexcept;

}  // namespace cpm::path
