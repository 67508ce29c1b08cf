// SPDX-License-Identifier: Apache-2.0
// Plots for the path report: the path coloured by contour error, and line
// charts, as inline SVG (one self-contained HTML page, no scripts).
#pragma once

#include <string>
#include <vector>

namespace cpm::path::report {

struct Line {
  std::vector<double> x, y;
  std::string colour, label;
};

// A line chart with axes, ticks and labels.
std::string chart(const std::string& title, const std::string& xlabel, const std::string& ylabel,
                  const std::vector<Line>& lines, double width = 700, double height = 260);

// The path in the XY plane, each stretch coloured by its value on a scale
// from 0 (blue) to `top` (red), over the programmed path in grey.
struct ColouredPath {
  std::vector<double> x, y, value;       // the run, mm and µm
  std::vector<double> px, py;            // the programmed path, mm
  double top = 0.0;                      // value at the red end
  std::string title, unit;
};
std::string coloured_path(const ColouredPath& c, double size = 560);

}  // namespace cpm::path::report
