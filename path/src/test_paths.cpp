// SPDX-License-Identifier: Apache-2.0
#include "cpm/path/test_paths.hpp"

#include <cmath>
#include <numbers>
#include <sstream>

namespace cpm::path {

std::string square_diamond_circle(double side_mm, double feed_mm_min, double clearance_mm) {
  const double h = side_mm / 2, r = h / std::numbers::sqrt2;
  std::ostringstream o;
  o.precision(6);
  o << std::fixed;
  o << "%\n(square-diamond-circle contour, NAS 979 / ISO 10791-7 style, side " << side_mm << " mm)\n";
  o << "G17 G21 G90 G91.1\n";
  o << "G0 X" << -h << " Y" << -h << " Z" << clearance_mm << "\n";
  o << "G1 Z0 F" << feed_mm_min << "\n";
  o << "(square)\nG1 X" << h << "\nY" << h << "\nX" << -h << "\nY" << -h << "\n";
  o << "(to the diamond's lower vertex, and round it)\nX0\n";
  o << "X" << h << " Y0\nX0 Y" << h << "\nX" << -h << " Y0\nX0 Y" << -h << "\n";
  o << "(up into the circle, once round, and out)\nY" << -r << "\n";
  o << "G3 X0 Y" << -r << " I0 J" << r << "\n";
  o << "G1 Y" << -h << "\n";
  o << "G0 Z" << clearance_mm << "\nM2\n%\n";
  return o.str();
}

PathQueue zigzag(int segments, double step, int row, const Vec3& centre, double feed, double tolerance) {
  const double width = step * row;
  PathQueue q(centre + Vec3(-width / 2, 0, 0), tolerance);
  Vec3 p = q.start();
  for (int k = 0; k < segments; ++k) {
    const int line = k / row, at = k % row;
    const double dir = line % 2 == 0 ? 1.0 : -1.0;
    // Along the row with a 0.1 mm zigzag across it; one row 1 mm further in y each time.
    p.x() += at == row - 1 ? 0.0 : dir * step;
    p.y() = centre.y() + 1e-3 * (line % 40) + (at % 2 ? 1e-4 : 0.0) + (at == row - 1 ? 1e-3 : 0.0);
    q.line(p, feed);
  }
  return q;
}

}  // namespace cpm::path
