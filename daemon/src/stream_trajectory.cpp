// SPDX-License-Identifier: Apache-2.0
#include "cpm/daemon/stream_trajectory.hpp"

#include <algorithm>
#include <cmath>
#include <string>

namespace cpm::daemon {

StreamTrajectory::StreamTrajectory(int n, const double* t, const double (*p)[3], const double (*v)[3]) {
  if (n < 2 || n > kMaxPoints)
    throw Error("stream: count must be 2.." + std::to_string(kMaxPoints) + ", got " + std::to_string(n));
  for (int i = 0; i < n; ++i) {
    const std::string where = "stream: point " + std::to_string(i) + ": ";
    if (!std::isfinite(t[i])) throw Error(where + "time is not finite");
    for (int j = 0; j < 3; ++j)
      if (!std::isfinite(p[i][j]) || !std::isfinite(v[i][j]))
        throw Error(where + "position or velocity is not finite");
    if (i == 0 && t[0] != 0.0) throw Error(where + "time must be 0 at the first point");
    if (i > 0 && !(t[i] > t[i - 1]))
      throw Error(where + "time " + std::to_string(t[i]) + " s is not after the previous point's");
    t_[i] = t[i];
    p_[i] = Vec3(p[i][0], p[i][1], p[i][2]);
    v_[i] = Vec3(v[i][0], v[i][1], v[i][2]);
  }
  n_ = n;
}

ctl::TrajectorySample StreamTrajectory::sample(double t) const noexcept {
  ctl::TrajectorySample s;
  if (n_ == 0) return s;
  // At t = 0 the chunk's first point with its own velocity (a stream goes
  // on through its chunks' boundaries); before it, the start at rest.
  if (!(t >= 0.0)) {
    s.p = p_[0];
    return s;
  }
  if (t >= t_[n_ - 1]) {
    s.p = p_[n_ - 1];
    return s;
  }
  const int i = static_cast<int>(std::upper_bound(t_.begin(), t_.begin() + n_, t) - t_.begin()) - 1;
  const double h = t_[i + 1] - t_[i];
  const double u = (t - t_[i]) / h;
  // Cubic Hermite basis and its derivatives in u.
  const double u2 = u * u, u3 = u2 * u;
  const double h00 = 2 * u3 - 3 * u2 + 1, h10 = u3 - 2 * u2 + u, h01 = -2 * u3 + 3 * u2, h11 = u3 - u2;
  const double d00 = 6 * u2 - 6 * u, d10 = 3 * u2 - 4 * u + 1, d01 = -6 * u2 + 6 * u, d11 = 3 * u2 - 2 * u;
  const double e00 = 12 * u - 6, e10 = 6 * u - 4, e01 = -12 * u + 6, e11 = 6 * u - 2;
  const Vec3& p0 = p_[i];
  const Vec3& p1 = p_[i + 1];
  const Vec3 m0 = v_[i] * h, m1 = v_[i + 1] * h;
  s.p = h00 * p0 + h10 * m0 + h01 * p1 + h11 * m1;
  s.v = (d00 * p0 + d10 * m0 + d01 * p1 + d11 * m1) / h;
  s.a = (e00 * p0 + e10 * m0 + e01 * p1 + e11 * m1) / (h * h);
  return s;
}

}  // namespace cpm::daemon
