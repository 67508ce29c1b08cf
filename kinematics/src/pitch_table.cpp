// SPDX-License-Identifier: Apache-2.0
#include "cpm/kinematics/pitch_table.hpp"

#include <algorithm>
#include <cmath>
#include <sstream>

#include "cpm/kinematics/types.hpp"

namespace cpm::kin {

double interpolate_held(const double* x, const double* y, int n, double at, double* slope) noexcept {
  if (slope) *slope = 0.0;
  if (n <= 0) return 0.0;
  if (n == 1 || at <= x[0]) return y[0];
  if (at >= x[n - 1]) return y[n - 1];
  // First node above `at`: the segment [k-1, k] holds it (the right one at a node).
  const int k = static_cast<int>(std::upper_bound(x, x + n, at) - x);
  const double s = (y[k] - y[k - 1]) / (x[k] - x[k - 1]);
  if (slope) *slope = s;
  return y[k - 1] + s * (at - x[k - 1]);
}

double PitchTable::operator()(double d, double* slope) const noexcept {
  return interpolate_held(node.data(), error.data(), size, d, slope);
}

void PitchTable::validate() const {
  if (size == 0) return;
  std::ostringstream os;
  if (size < 2 || size > kCapacity) {
    os << "pitch_table: needs 2 to " << kCapacity << " nodes, has " << size;
    throw Error(os.str());
  }
  for (int k = 0; k < size; ++k) {
    if (!std::isfinite(node[k]) || !std::isfinite(error[k])) {
      os << "pitch_table: node " << k << " is not a finite number";
      throw Error(os.str());
    }
    if (k > 0 && !(node[k] > node[k - 1])) {
      os << "pitch_table: nodes must be strictly increasing; node " << k << " (" << node[k]
         << " m) is not above node " << k - 1 << " (" << node[k - 1] << " m)";
      throw Error(os.str());
    }
    // The inverse kinematics' Newton solve needs d~ to grow with d.
    if (k > 0 && std::abs((error[k] - error[k - 1]) / (node[k] - node[k - 1])) >= 0.5) {
      os << "pitch_table: the error changes by more than half the travel between nodes " << k - 1
         << " and " << k << " (|de/dd| >= 0.5): not a pitch error";
      throw Error(os.str());
    }
  }
}

}  // namespace cpm::kin
