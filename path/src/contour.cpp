// SPDX-License-Identifier: Apache-2.0
#include "cpm/path/contour.hpp"

#include <algorithm>
#include <cmath>

namespace cpm::path {
namespace {

// The programmed piece nearest to q among the segments within 3 of `hint`
// (the reference's), and the distance. Where the path passes twice (a side
// traced again), the segment nearer the hint wins a tie within 1 um.
double nearest(const Geometry& g, const Vec3& q, int hint, int& piece, double& s) {
  const auto first = std::lower_bound(g.pieces.begin(), g.pieces.end(), hint - 3,
                                      [](const Piece& pc, int seg) { return pc.segment < seg; });
  double best = 1e300;
  int best_gap = 0;
  for (auto it = first; it != g.pieces.end() && it->segment <= hint + 3; ++it) {
    double at = 0.0;
    const double d = distance_to_piece(*it, q, &at);
    const int gap = std::abs(it->segment - hint);
    if (d < best - 1e-6 || (d < best + 1e-6 && gap < best_gap)) {
      best = std::min(best, d), best_gap = gap;
      piece = static_cast<int>(it - g.pieces.begin()), s = it->s0 + at;
    }
  }
  return best;
}

}  // namespace

ContourFigures contour(const PathQueue& queue, const Plan& plan, const std::vector<RunSample>& run, double velocity) {
  const Geometry g = programmed(queue);
  ContourFigures f;
  double sum2 = 0.0, run_on_feed = 0.0, held = 0.0;
  long n = 0;
  for (std::size_t k = 0; k < run.size(); ++k) {
    const RunSample& r = run[k];
    const PathSample ref = plan.sample_path(r.t);
    ContourPoint c;
    c.t = r.t;
    c.p = r.p;
    int piece = 0;
    c.error = nearest(g, r.p, ref.segment, piece, c.s);
    c.tracking = (r.p - ref.ref.p).norm();
    c.along = ref.s;
    const Piece& pc = g.pieces[static_cast<std::size_t>(piece)];
    c.nearest = pc.at(c.s - pc.s0).p;
    c.segment = pc.segment;
    c.rapid = pc.feed <= 0.0;
    c.feed = r.p_dot.norm();
    c.programmed = c.rapid ? velocity : std::min(pc.feed, velocity);
    f.peak_force = f.peak_force.cwiseMax(r.force.cwiseAbs());
    if (!c.rapid) {
      int ref_piece = 0;
      double ref_s = 0.0;
      f.max_rounding = std::max(f.max_rounding, nearest(g, ref.ref.p, ref.segment, ref_piece, ref_s));
      f.max_error = std::max(f.max_error, c.error);
      f.max_tracking = std::max(f.max_tracking, c.tracking);
      sum2 += c.error * c.error;
      ++n;
      const double dt = k + 1 < run.size() ? run[k + 1].t - r.t : 0.0;
      run_on_feed += c.feed * dt;
      if (c.feed >= 0.95 * c.programmed) held += c.feed * dt;
    }
    f.points.push_back(c);
  }
  f.rms_error = n > 0 ? std::sqrt(sum2 / static_cast<double>(n)) : 0.0;
  f.feed_held = run_on_feed > 0.0 ? held / run_on_feed : 0.0;
  return f;
}

}  // namespace cpm::path
