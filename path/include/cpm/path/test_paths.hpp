// SPDX-License-Identifier: Apache-2.0
// Standard paths for tests, benchmarks and reports.
//
// Units: G-code text in mm and mm/min (what a machinist would write);
// queues in the machine frame (m, m/s).
#pragma once

#include <string>

#include "cpm/path/path.hpp"

namespace cpm::path {

// The square-diamond-circle contour of the NAS 979 / ISO 10791-7 test
// piece, scaled: a square of side `side_mm` centred on program zero,
// counter-clockwise from its lower left corner; along its lower side to the
// diamond inscribed in it (vertices at the square's mid-sides); round the
// diamond; then up into the circle inscribed in the diamond, once round
// counter-clockwise, and back out. All at `feed_mm_min`, in the plane Z0,
// between a rapid in and a rapid out at Z `clearance_mm`.
std::string square_diamond_circle(double side_mm, double feed_mm_min, double clearance_mm = 5.0);

// A polyline of `segments` lines of `step` (m) each, as CAM output makes
// of a surface: a zigzag raster in the XY plane around `centre` (m), rows
// of `row` segments stepping 1 mm in y between them, at `feed` (m/s).
PathQueue zigzag(int segments, double step, int row, const Vec3& centre, double feed, double tolerance);

}  // namespace cpm::path
