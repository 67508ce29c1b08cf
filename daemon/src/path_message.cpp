// SPDX-License-Identifier: Apache-2.0
// Programs as path_command_t chunks and back (path_message.hpp).
#include "cpm/daemon/path_message.hpp"

#include <algorithm>
#include <cmath>

#include "cpm/path/geometry.hpp"

namespace cpm::daemon {

using cpm_msgs::path_command_t;

namespace {

void put(double* dst, const Vec3& v) {
  dst[0] = v.x();
  dst[1] = v.y();
  dst[2] = v.z();
}
Vec3 vec(const double* v) { return Vec3(v[0], v[1], v[2]); }

}  // namespace

std::vector<path_command_t> path_chunks(const path::PathQueue& q, std::int64_t program) {
  const auto& segs = q.segments();
  std::vector<path_command_t> out;
  Vec3 at = q.start();
  for (std::size_t s0 = 0; s0 < segs.size() || out.empty(); s0 += kPathChunkSegments) {
    path_command_t m{};
    m.program = program;
    m.chunk = static_cast<std::int32_t>(out.size());
    put(m.start, at);
    m.tolerance = q.tolerance();
    const std::size_t n = std::min<std::size_t>(kPathChunkSegments, segs.size() - std::min(s0, segs.size()));
    m.count = static_cast<std::int16_t>(n);
    for (std::size_t i = 0; i < n; ++i) {
      const path::Segment& s = segs[s0 + i];
      m.kind[i] = s.kind == path::SegmentKind::line  ? path_command_t::KIND_LINE
                  : s.kind == path::SegmentKind::arc ? path_command_t::KIND_ARC
                                                     : path_command_t::KIND_DWELL;
      if (s.kind != path::SegmentKind::dwell) put(m.end[i], s.end);
      if (s.kind == path::SegmentKind::arc) {
        put(m.centre[i], s.centre);
        put(m.normal[i], s.normal);
        m.turns[i] = static_cast<std::int16_t>(s.turns);
      }
      m.feed[i] = s.feed;
      m.dwell[i] = s.dwell;
      m.line[i] = s.line;
      at = s.end;
    }
    out.push_back(m);
    if (s0 + n >= segs.size()) break;
  }
  out.back().last = true;
  return out;
}

void PathAssembly::clear() noexcept {
  queue_.reset();
  program_ = 0;
  next_chunk_ = 0;
  complete_ = false;
}

std::string PathAssembly::add(const path_command_t& m) {
  const auto refuse = [this](std::string why) {
    clear();
    return why;
  };
  if (m.chunk == 0) clear();
  if (m.chunk != 0 && (!queue_ || complete_ || m.program != program_ || m.chunk != next_chunk_))
    return refuse("chunk " + std::to_string(m.chunk) + " of program " + std::to_string(m.program) +
                  (queue_ && m.program == program_ && !complete_
                       ? " came when chunk " + std::to_string(next_chunk_) + " was due: send the program again from chunk 0"
                       : " belongs to no program being received: send the program from chunk 0"));
  if (m.count < 0 || m.count > kPathChunkSegments)
    return refuse("count must be 0.." + std::to_string(kPathChunkSegments) + ", got " + std::to_string(m.count));
  if (m.chunk == 0 && m.count == 0 && m.last) return refuse("the program has no segment");
  if (!(m.tolerance >= 0.0) || m.tolerance > 0.01)
    return refuse("tolerance must be 0 .. 10 mm, got " + std::to_string(m.tolerance * 1e3) + " mm");
  const Vec3 start = vec(m.start);
  try {
    if (!queue_) {
      queue_.emplace(start, m.tolerance);
      program_ = m.program;
    } else if (m.tolerance != queue_->tolerance()) {
      return refuse("the tolerance changed within the program (chunk " + std::to_string(m.chunk) + ")");
    } else if ((start - queue_->end()).norm() > 1e-9) {
      return refuse("chunk " + std::to_string(m.chunk) + " does not start where chunk " + std::to_string(m.chunk - 1) +
                    " ended");
    }
    if (static_cast<long>(queue_->segments().size()) + m.count > kMaxProgramSegments)
      return refuse("the program has more than " + std::to_string(kMaxProgramSegments) + " segments");
    for (int i = 0; i < m.count; ++i) {
      const auto seg = [&] {
        return "segment " + std::to_string(m.chunk * kPathChunkSegments + i) + " (line " + std::to_string(m.line[i]) +
               "): ";
      };
      switch (m.kind[i]) {
        case path_command_t::KIND_LINE:
          queue_->line(vec(m.end[i]), m.feed[i], m.line[i]);
          break;
        case path_command_t::KIND_ARC:
          if (!(m.feed[i] > 0.0)) return refuse(seg() + "an arc needs a feed > 0");
          if (m.turns[i] == 0) return refuse(seg() + "an arc needs turns != 0");
          queue_->arc(vec(m.end[i]), vec(m.centre[i]), vec(m.normal[i]), m.turns[i], m.feed[i], m.line[i]);
          break;
        case path_command_t::KIND_DWELL:
          if (m.dwell[i] > kMaxProgramDuration) return refuse(seg() + "a dwell longer than an hour");
          queue_->dwell(m.dwell[i], m.line[i]);
          break;
        default:
          return refuse(seg() + "unknown kind " + std::to_string(m.kind[i]));
      }
    }
  } catch (const Error& e) {
    return refuse("segment in chunk " + std::to_string(m.chunk) + ": " + e.what());
  }
  next_chunk_ = m.chunk + 1;
  complete_ = m.last;
  return {};
}

path::PathQueue PathAssembly::take() {
  path::PathQueue q = std::move(*queue_);
  clear();
  return q;
}

double program_duration_bound(const path::PathQueue& q, double rapid) {
  double t = 0.0;
  for (const path::Segment& s : q.segments()) {
    if (s.kind == path::SegmentKind::dwell) {
      t += s.dwell;
      continue;
    }
    const double feed = s.feed > 0.0 ? std::min(s.feed, rapid) : rapid;
    t += path::segment_length(s) / feed;
  }
  return t;
}

}  // namespace cpm::daemon
