// SPDX-License-Identifier: Apache-2.0
// A program against the machine's workspace, and into the planner's queue (gcode.hpp).
#include <cmath>
#include <cstdio>
#include <sstream>

#include "cpm/path/gcode.hpp"
#include "cpm/path/geometry.hpp"

namespace cpm::path {
namespace {

// The move as a segment in the program's frame (lines and arcs).
Segment segment_of(const CanonicalMove& mv) {
  Segment s;
  s.start = mv.start;
  s.end = mv.end;
  if (mv.kind == MoveKind::arc) {
    s.kind = SegmentKind::arc;
    s.normal = plane_normal(mv.plane);
    s.centre = mv.centre;
    s.sweep = arc_sweep(mv.start, mv.end, mv.centre, s.normal, mv.turn);
  }
  return s;
}

std::string point_text(const Vec3& p, Units u) {
  const double k = u == Units::inch ? 1.0 / 0.0254 : 1e3;
  std::ostringstream o;
  o.precision(4);
  o << std::fixed << "X" << p.x() * k << " Y" << p.y() * k << " Z" << p.z() * k << (u == Units::inch ? " (in)" : " (mm)");
  return o.str();
}

// Why machine point q is refused, or "" when it is fine.
std::string refused(const Vec3& q, const ctl::Machine& m, const SoftLimits& soft, const ProgramFrame& frame) {
  if (Status s = kin::check_pose(m.kinematics(), m.model().strokes, q, kin::KinematicInputs{}); !s) return describe(s);
  return soft_limit_text(q, soft, &frame);
}

}  // namespace

std::string soft_limit_text(const Vec3& q, const SoftLimits& soft, const ProgramFrame* frame, double margin) {
  for (int i = 0; i < 3; ++i) {
    const bool low = q[i] < soft.min[i] - margin, high = q[i] > soft.max[i] + margin;
    if (!low && !high) continue;
    const double limit = low ? soft.min[i] : soft.max[i];
    char b[200];
    const char machine_axis = "xyz"[i];
    if (!frame) {
      std::snprintf(b, sizeof b, "outside the soft limits on %c: %c = %.3f mm, %s the limit %.3f mm", machine_axis,
                    machine_axis, q[i] * 1e3, low ? "below" : "above", limit * 1e3);
      return b;
    }
    // The same point and limit in the program's frame (its z may be flipped).
    Vec3 at_limit = q;
    at_limit[i] = limit;
    const double p = frame->to_program(q)[i] * 1e3, lp = frame->to_program(at_limit)[i] * 1e3;
    const char axis = "XYZ"[i];
    std::snprintf(b, sizeof b, "outside the soft limits on %c: %c = %.3f mm, %s the limit %c %.3f mm (machine %c %.3f mm)",
                  axis, axis, p, p < lp ? "below" : "above", axis, lp, machine_axis, limit * 1e3);
    return b;
  }
  return "";
}

Vec3 ProgramFrame::to_machine(const Vec3& p) const noexcept {
  return origin + Vec3(p.x(), p.y(), z_up ? -p.z() : p.z());
}

Vec3 ProgramFrame::to_program(const Vec3& m) const noexcept {
  const Vec3 d = m - origin;
  return Vec3(d.x(), d.y(), z_up ? -d.z() : d.z());
}

Vec3 ProgramFrame::normal_to_machine(const Vec3& n) const noexcept {
  return z_up ? Vec3(-n.x(), -n.y(), n.z()) : n;  // det(R) R n, R = diag(1, 1, -1)
}

void check_workspace(const Program& program, const ctl::Machine& machine, const ProgramFrame& frame,
                     const SoftLimits& soft, const std::string& name, double step) {
  std::vector<Diagnostic> errors;
  for (const CanonicalMove& mv : program.moves) {
    if (mv.kind == MoveKind::dwell) continue;
    const Segment seg = segment_of(mv);
    const double L = segment_length(seg);
    const Piece pc = piece_of(seg, 0.0, L);
    const int n = std::max(1, static_cast<int>(std::ceil(L / step)));
    for (int k = 0; k <= n; ++k) {
      const Vec3 p = pc.at(L * k / n).p;
      if (const std::string why = refused(frame.to_machine(p), machine, soft, frame); !why.empty()) {
        errors.push_back(Diagnostic{mv.line, mv.column, "the move passes " + point_text(p, mv.units) +
                                                            ", outside the workspace: " + why});
        break;
      }
    }
  }
  if (!errors.empty()) throw ProgramError(name, std::move(errors));
}

PathQueue to_queue(const Program& program, const ProgramFrame& frame, double tolerance) {
  PathQueue q(frame.to_machine(program.start), program.tolerance >= 0.0 ? program.tolerance : tolerance);
  for (const CanonicalMove& mv : program.moves) {
    const Vec3 end = frame.to_machine(mv.end);
    switch (mv.kind) {
      case MoveKind::traverse: q.rapid(end, mv.line); break;
      case MoveKind::feed: q.line(end, mv.feed, mv.line); break;
      case MoveKind::arc:
        q.arc(end, frame.to_machine(mv.centre), frame.normal_to_machine(plane_normal(mv.plane)), mv.turn, mv.feed,
              mv.line);
        break;
      case MoveKind::dwell: q.dwell(mv.dwell, mv.line); break;
    }
  }
  return q;
}

}  // namespace cpm::path
