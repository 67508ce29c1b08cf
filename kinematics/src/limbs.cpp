// SPDX-License-Identifier: Apache-2.0
#include "cpm/kinematics/limbs.hpp"

#include <cmath>
#include <numbers>

namespace cpm::kin {
namespace {

using Vec2 = Eigen::Vector2d;
using Mat23 = Eigen::Matrix<double, 2, 3>;

// Each limb lives in a plane of two machine axes (a, b). The first link's
// direction is u = (cos alpha, sin alpha) with alpha = sign * theta + offset,
// which folds docs/model.md's three parametrisations into one.
struct LimbFrame {
  int axis_a, axis_b;   // machine axes spanning the limb's plane
  double sign;          // d alpha / d theta
  double offset;        // alpha at theta = 0
};

constexpr LimbFrame kFrames[3] = {
    {1, 2, +1.0, 0.0},                     // limb 1: (y, z), u = (cos t, sin t)
    {0, 2, -1.0, std::numbers::pi / 2.0},  // limb 2: (x, z), u = (sin t, cos t)
    {0, 1, -1.0, 0.0},                     // limb 3: (x, y), u = (cos t, -sin t)
};

inline double cross2(const Vec2& a, const Vec2& b) { return a.x() * b.y() - a.y() * b.x(); }

// B_i - A_i in the limb's plane.
Vec2 platform_joint(const LimbGeometry& g, int i, const Vec3& p) {
  switch (i) {
    case 0: return {p.y() - g.L, p.z()};
    case 1: return {p.x() - g.L, p.z()};
    default: return {p.x(), p.y() + g.L - g.D};
  }
}

Mat23 selector(int i) {
  Mat23 P = Mat23::Zero();
  P(0, kFrames[i].axis_a) = 1.0;
  P(1, kFrames[i].axis_b) = 1.0;
  return P;
}

// One limb at p: the link directions and the quantities derived from them.
struct LimbSolution {
  double cos_theta, sin_theta, cos_elbow, sin_elbow;
  Vec2 u, u_perp, w;  // first link direction, its d/d alpha, M->B
  double den;         // d(w.w)/d theta / (-2): theta_dot = (w . B_dot) / den
};

Status solve_one(const LimbGeometry& g, int i, const Vec3& p, LimbSolution& s) {
  const LimbFrame& f = kFrames[i];
  const Vec2 r = platform_joint(g, i, p);
  const double rho = r.norm();
  if (!(rho > 0.0)) return Status::failure(Fault::limb_unreachable, i, rho, g.L1 + g.L2);
  const double k = (rho * rho + g.L1 * g.L1 - g.L2 * g.L2) / (2.0 * g.L1);
  const double c = k / rho;
  if (c > 1.0 || c < -1.0) {
    // Out of reach (too far: rho > L1 + L2, too close: rho < |L1 - L2|).
    const double limit = rho > g.L1 ? g.L1 + g.L2 : std::abs(g.L1 - g.L2);
    return Status::failure(Fault::limb_unreachable, i, rho, limit);
  }
  // u = rotation of r/rho by +-acos(c), without calling acos, cos or sin.
  const Vec2 r_hat = r / rho;
  const double sn = g.mode[i] * std::sqrt(std::max(0.0, 1.0 - c * c));
  s.u = Vec2(c * r_hat.x() - sn * r_hat.y(), c * r_hat.y() + sn * r_hat.x());
  s.u_perp = Vec2(-s.u.y(), s.u.x());
  s.w = r - g.L1 * s.u;
  // u = (cos alpha, sin alpha), alpha = sign * theta + offset (offset 0 or pi/2).
  if (f.offset == 0.0) {
    s.cos_theta = s.u.x();
    s.sin_theta = f.sign * s.u.y();
  } else {
    s.cos_theta = s.u.y();
    s.sin_theta = -f.sign * s.u.x();
  }
  const double wn = s.w.norm();  // = L2 when the limb is assembled
  s.cos_elbow = s.u.dot(s.w) / wn;
  s.sin_elbow = f.sign * cross2(s.u, s.w) / wn;
  s.den = g.L1 * f.sign * s.w.dot(s.u_perp);
  // Near straight or folded: |sin phi| < sin(margin). |sin phi| >= margin
  // already means clear of it (asin x >= x); only near it is the angle needed.
  if (std::abs(s.sin_elbow) < g.singularity_margin) {
    const double elbow = std::atan2(s.sin_elbow, s.cos_elbow);
    const double straightness = std::min(std::abs(elbow), std::numbers::pi - std::abs(elbow));
    if (straightness < g.singularity_margin)
      return Status::failure(Fault::near_singularity, i, straightness, g.singularity_margin);
  }
  return {};
}

void store(const LimbSolution& s, int i, LimbPose& out) {
  out.cos_theta[i] = s.cos_theta;
  out.sin_theta[i] = s.sin_theta;
  out.cos_elbow[i] = s.cos_elbow;
  out.sin_elbow[i] = s.sin_elbow;
}

}  // namespace

Vec3 LimbPose::theta() const noexcept {
  return Vec3(std::atan2(sin_theta[0], cos_theta[0]), std::atan2(sin_theta[1], cos_theta[1]),
              std::atan2(sin_theta[2], cos_theta[2]));
}

Vec3 LimbPose::elbow() const noexcept {
  return Vec3(std::atan2(sin_elbow[0], cos_elbow[0]), std::atan2(sin_elbow[1], cos_elbow[1]),
              std::atan2(sin_elbow[2], cos_elbow[2]));
}

LimbGeometry LimbGeometry::elkady() {
  LimbGeometry g;
  g.mode = default_assembly_modes(g);
  return g;
}

std::array<int, 3> default_assembly_modes(const LimbGeometry& base) {
  constexpr double deg = std::numbers::pi / 180.0;
  const Vec3 p_ref(0.600, 0.425, 0.300);
  const double theta_ref[3] = {89.41 * deg, 19.17 * deg, 2.89 * deg};
  std::array<int, 3> modes{};
  for (int i = 0; i < 3; ++i) {
    double best = 1e9;
    for (int m : {+1, -1}) {
      LimbGeometry g = base;
      g.mode[i] = m;
      g.singularity_margin = 0.0;
      LimbSolution s{};
      if (!solve_one(g, i, p_ref, s)) continue;
      const double theta = std::atan2(s.sin_theta, s.cos_theta);
      const double err = std::abs(std::remainder(theta - theta_ref[i], 2.0 * std::numbers::pi));
      if (err < best) {
        best = err;
        modes[i] = m;
      }
    }
    if (best > 0.01 * deg * 10)  // docs/model.md gives the angles to 0.01 deg
      throw Error("limb " + std::to_string(i + 1) +
                  ": no assembly mode reproduces docs/model.md's reference angle; is the geometry right?");
  }
  return modes;
}

Status solve_limbs(const LimbGeometry& g, const Vec3& p, LimbPose& out) noexcept {
  if (!all_finite(p)) return Status::failure(Fault::not_finite);
  for (int i = 0; i < 3; ++i) {
    LimbSolution s{};
    if (Status st = solve_one(g, i, p, s); !st) return st;
    store(s, i, out);
    out.Gamma.row(i) = (selector(i).transpose() * s.w).transpose() / s.den;
  }
  return {};
}

Status solve_limb_motion(const LimbGeometry& g, const Vec3& p, const Vec3& p_dot,
                         LimbMotion& out) noexcept {
  if (!all_finite(p) || !all_finite(p_dot)) return Status::failure(Fault::not_finite);
  for (int i = 0; i < 3; ++i) {
    LimbSolution s{};
    if (Status st = solve_one(g, i, p, s); !st) return st;
    // The limb's plane holds machine axes a and b: Gamma's row has w there and
    // 0 on the third axis (index arithmetic, not 2x3 selector products).
    const int a = kFrames[i].axis_a, b = kFrames[i].axis_b;
    const double sign = kFrames[i].sign;
    const double inv_den = 1.0 / s.den;
    const double ga = s.w.x() * inv_den, gb = s.w.y() * inv_den;
    const double theta_dot = ga * p_dot[a] + gb * p_dot[b];
    // w = B - A - L1 u(theta): differentiate in time.
    const double k = g.L1 * sign * theta_dot;
    const Vec2 w_dot(p_dot[a] - k * s.u_perp.x(), p_dot[b] - k * s.u_perp.y());
    // den = L1 sign (w . u_perp), and d u_perp / d theta = -sign u.
    const double den_dot = g.L1 * sign * (w_dot.dot(s.u_perp) - sign * s.w.dot(s.u) * theta_dot);
    const double r = den_dot * inv_den;
    store(s, i, out.pose);
    out.pose.Gamma.row(i).setZero();
    out.pose.Gamma(i, a) = ga;
    out.pose.Gamma(i, b) = gb;
    out.theta_dot[i] = theta_dot;
    out.Gamma_dot.row(i).setZero();
    out.Gamma_dot(i, a) = w_dot.x() * inv_den - ga * r;
    out.Gamma_dot(i, b) = w_dot.y() * inv_den - gb * r;
  }
  return {};
}

Status elbow_gradient(const LimbGeometry& g, const Vec3& p, Mat3& out) noexcept {
  if (!all_finite(p)) return Status::failure(Fault::not_finite);
  for (int i = 0; i < 3; ++i) {
    LimbSolution s{};
    if (Status st = solve_one(g, i, p, s); !st) return st;
    const Mat23 P = selector(i);
    const double sign = kFrames[i].sign;
    const Vec3 gamma = P.transpose() * s.w / s.den;
    const Vec2 w_perp(-s.w.y(), s.w.x());
    // phi = sign * (angle(w) - alpha) and alpha_dot = sign * theta_dot, so
    // phi_dot = sign * (w x w_dot) / |w|^2 - theta_dot.
    const Vec3 dangle_w =
        (P.transpose() * w_perp - g.L1 * sign * cross2(s.w, s.u_perp) * gamma) / s.w.squaredNorm();
    out.row(i) = (sign * dangle_w - gamma).transpose();
  }
  return {};
}

}  // namespace cpm::kin
