// SPDX-License-Identifier: Apache-2.0
#include "cpm/kinematics/plane_model.hpp"

#include <cmath>
#include <numbers>
#include <sstream>

namespace cpm::kin {
namespace {

constexpr double kTwoPi = 2.0 * std::numbers::pi;

// Plane offset added by the limb-twist effect at the elbow angles of p.
Status twist_offsets(const KinematicModel& m, const Vec3& p, Vec3& out) noexcept {
  out.setZero();
  if (!m.has_twist()) return {};
  LimbPose pose;
  LimbGeometry g = m.limbs;
  g.singularity_margin = 0.0;  // the workspace check reports singularity; here we only need phi
  if (Status s = solve_limbs(g, p, pose); !s) return s;
  for (int i = 0; i < 3; ++i) out[i] = m.effects[i].twist * m.limbs.L2 * pose.sin_elbow[i];
  return {};
}

}  // namespace

bool LimbKinematicEffects::any() const noexcept {
  return backlash != 0.0 || cyclic_amplitude != 0.0 || guide_ka != 0.0 || guide_kb != 0.0 ||
         twist != 0.0 || thermal_expansion != 0.0 || actuator_scale != 0.0 || !pitch_table.empty();
}

KinematicModel KinematicModel::nominal() {
  KinematicModel m;
  for (int i = 0; i < 3; ++i) m.planes[i].normal = Vec3::Unit(i);
  return m;
}

bool KinematicModel::has_twist() const noexcept {
  return effects[0].twist != 0.0 || effects[1].twist != 0.0 || effects[2].twist != 0.0;
}

void KinematicModel::validate() const {
  auto fail = [](int i, const std::string& what) {
    throw Error("kinematic model, limb " + std::to_string(i + 1) + ": " + what);
  };
  for (int i = 0; i < 3; ++i) {
    const LimbPlane& pl = planes[i];
    if (!pl.normal.allFinite() || !std::isfinite(pl.scale) || !std::isfinite(pl.offset))
      fail(i, "plane parameters must be finite numbers");
    if (std::abs(pl.normal.norm() - 1.0) > 1e-9) {
      std::ostringstream os;
      os << "plane normal u must be a unit vector, its length is " << pl.normal.norm();
      fail(i, os.str());
    }
    if (!(pl.scale > 0.5 && pl.scale < 1.5)) {
      std::ostringstream os;
      os << "scale c = " << pl.scale << " is outside (0.5, 1.5): not a plausible calibration";
      fail(i, os.str());
    }
    if (!(pl.normal[i] > 0.5))
      fail(i, "plane normal must point along its own actuator axis (u_i[i] > 0.5)");
    const LimbKinematicEffects& e = effects[i];
    const double vals[] = {e.backlash,         e.cyclic_amplitude,      e.cyclic_wavelength,
                           e.cyclic_phase,     e.guide_ka,              e.guide_kb,
                           e.twist,            e.thermal_expansion,     e.thermal_time_constant,
                           e.actuator_scale};
    for (double v : vals)
      if (!std::isfinite(v)) fail(i, "kinematic effect parameters must be finite numbers");
    if (e.backlash < 0.0) fail(i, "backlash b must be >= 0");
    if (e.cyclic_amplitude != 0.0) {
      if (!(e.cyclic_wavelength > 0.0)) fail(i, "cyclic_error needs a wavelength lambda > 0");
      if (std::abs(e.cyclic_amplitude) * kTwoPi / e.cyclic_wavelength >= 0.5)
        fail(i, "cyclic_error slope 2*pi*a/lambda must be < 0.5 (the axis would run backwards)");
    }
    if (e.thermal_expansion != 0.0 && !(e.thermal_time_constant > 0.0))
      fail(i, "thermal_drift needs a time constant tau > 0");
    if (!(e.actuator_scale > -0.5 && e.actuator_scale < 0.5))
      fail(i, "actuator_scale s must be within (-0.5, 0.5)");
    if (std::abs(e.twist) > 0.1) fail(i, "limb_twist alpha must be small (|alpha| <= 0.1 rad)");
    try {
      e.pitch_table.validate();
    } catch (const Error& err) {
      fail(i, err.what());
    }
  }
  Mat3 U;
  for (int i = 0; i < 3; ++i) U.row(i) = planes[i].normal.transpose();
  const double det = U.determinant();
  if (!(std::abs(det) > 0.5))
    throw Error("kinematic model: the three limb planes are (nearly) parallel, det(U) = " +
                std::to_string(det));
  if (!d0.allFinite()) throw Error("kinematic model: d0 must be finite");
}

double effective_displacement(const LimbKinematicEffects& e, double d, int dir, double t,
                              double* d_dd) noexcept {
  double dt = d;
  double slope = 1.0;
  if (e.actuator_scale != 0.0) {
    dt *= 1.0 + e.actuator_scale;
    slope *= 1.0 + e.actuator_scale;
  }
  if (e.thermal_expansion != 0.0) {
    const double grow = 1.0 + e.thermal_expansion * (1.0 - std::exp(-t / e.thermal_time_constant));
    dt *= grow;
    slope *= grow;
  }
  if (e.cyclic_amplitude != 0.0) {
    const double arg = kTwoPi * d / e.cyclic_wavelength + e.cyclic_phase;
    dt += e.cyclic_amplitude * std::sin(arg);
    slope += e.cyclic_amplitude * kTwoPi / e.cyclic_wavelength * std::cos(arg);
  }
  if (!e.pitch_table.empty()) {
    double de = 0.0;
    dt += e.pitch_table(d, &de);
    slope += de;
  }
  if (e.backlash != 0.0) dt -= 0.5 * e.backlash * (dir >= 0 ? 1.0 : -1.0);
  if (d_dd) *d_dd = slope;
  return dt;
}

Vec3 effective_normal(const LimbKinematicEffects& e, int limb, const Vec3& u, double d,
                      Vec3* du_dd) noexcept {
  if (e.guide_ka == 0.0 && e.guide_kb == 0.0) {
    if (du_dd) du_dd->setZero();
    return u;
  }
  // The two machine axes other than the limb's own, in increasing order.
  const int a = limb == 0 ? 1 : 0;
  const int b = limb == 2 ? 1 : 2;
  Vec3 k = Vec3::Zero();
  k[a] = e.guide_ka;
  k[b] = e.guide_kb;
  const Vec3 v = u + d * k;
  const double n = v.norm();
  const Vec3 ut = v / n;
  if (du_dd) *du_dd = (k - ut * ut.dot(k)) / n;
  return ut;
}

Status forward(const KinematicModel& m, const Vec3& d, const KinematicInputs& in,
               Vec3& p) noexcept {
  if (!all_finite(d) || !std::isfinite(in.t)) return Status::failure(Fault::not_finite);
  Mat3 U;
  Vec3 rhs;
  for (int i = 0; i < 3; ++i) {
    const LimbPlane& pl = m.planes[i];
    const LimbKinematicEffects& e = m.effects[i];
    U.row(i) = effective_normal(e, i, pl.normal, d[i]).transpose();
    rhs[i] = (effective_displacement(e, d[i], in.dir[i], in.t) + m.d0[i]) * pl.scale + pl.offset;
  }
  const double det = U.determinant();
  if (!(std::abs(det) > 1e-6)) return Status::failure(Fault::singular_planes, -1, det, 1e-6);
  const Mat3 Uinv = U.inverse();
  p = Uinv * rhs;
  if (!m.has_twist()) return {};
  // The twist offset depends on p through the elbow angles: iterate.
  Vec3 tw;
  for (int it = 0; it < 20; ++it) {
    if (Status s = twist_offsets(m, p, tw); !s) return s;
    const Vec3 next = Uinv * (rhs + tw);
    const double step = (next - p).norm();
    p = next;
    if (step < 1e-13) return {};
  }
  return Status::failure(Fault::no_convergence);
}

Status inverse(const KinematicModel& m, const Vec3& p, const KinematicInputs& in,
               Vec3& d, Mat3* J_inv) noexcept {
  if (!all_finite(p) || !std::isfinite(in.t)) return Status::failure(Fault::not_finite);
  Vec3 tw;
  if (Status s = twist_offsets(m, p, tw); !s) return s;
  // d(plane_i)/dp and d(plane_i)/dd_i at the solution, for J_inv = diag^-1 A.
  Mat3 A;
  Vec3 diag;
  for (int i = 0; i < 3; ++i) {
    const LimbPlane& pl = m.planes[i];
    const LimbKinematicEffects& e = m.effects[i];
    // Kim eq. 7 gives d~; the effects then need a scalar Newton solve.
    double di = (pl.normal.dot(p) - pl.offset - tw[i]) / pl.scale - m.d0[i];
    const bool needs_newton = e.guide_ka != 0.0 || e.guide_kb != 0.0 ||
                              e.cyclic_amplitude != 0.0 || e.thermal_expansion != 0.0 ||
                              e.actuator_scale != 0.0 || !e.pitch_table.empty();
    if (!needs_newton) {
      // Nothing or only backlash: d~ = d - (b/2) dir inverts directly.
      d[i] = di + 0.5 * e.backlash * (in.dir[i] >= 0 ? 1.0 : -1.0);
      A.row(i) = pl.normal.transpose();
      diag[i] = pl.scale;
      continue;
    }
    bool converged = false;
    for (int it = 0; it < 30; ++it) {
      double ddt;
      Vec3 du;
      const Vec3 u = effective_normal(e, i, pl.normal, di, &du);
      const double dt = effective_displacement(e, di, in.dir[i], in.t, &ddt);
      const double g = u.dot(p) - (dt + m.d0[i]) * pl.scale - pl.offset - tw[i];
      const double dg = du.dot(p) - pl.scale * ddt;
      if (!(std::abs(dg) > 1e-9)) return Status::failure(Fault::no_convergence, i);
      const double step = g / dg;
      di -= step;
      A.row(i) = u.transpose();
      diag[i] = -dg;
      if (std::abs(step) < 1e-14) {
        converged = true;
        break;
      }
    }
    if (!converged) return Status::failure(Fault::no_convergence, i);
    d[i] = di;
  }
  if (!all_finite(d)) return Status::failure(Fault::not_finite);
  if (J_inv) {
    // The twist makes A depend on p through the elbows: the full differentials.
    if (m.has_twist()) return inverse_jacobian(m, d, p, in, *J_inv);
    for (int i = 0; i < 3; ++i)
      if (!(std::abs(diag[i]) > 1e-12)) return Status::failure(Fault::singular_planes, i, diag[i], 1e-12);
    *J_inv = diag.cwiseInverse().asDiagonal() * A;
  }
  return {};
}

namespace {
// Differentiate u~_i(d_i)^T p = (d~_i(d_i) + d0_i) c_i + n_i + alpha_i L2 sin phi_i(p):
// A dp = diag(c_i d~_i' - u~_i'^T p) dd, with A = U~ - T.
Status plane_differentials(const KinematicModel& m, const Vec3& d, const Vec3& p, const KinematicInputs& in,
                           Mat3& A, Vec3& diag) noexcept {
  if (!all_finite(d) || !all_finite(p)) return Status::failure(Fault::not_finite);
  for (int i = 0; i < 3; ++i) {
    const LimbPlane& pl = m.planes[i];
    const LimbKinematicEffects& e = m.effects[i];
    Vec3 du;
    double ddt;
    A.row(i) = effective_normal(e, i, pl.normal, d[i], &du).transpose();
    effective_displacement(e, d[i], in.dir[i], in.t, &ddt);
    diag[i] = pl.scale * ddt - du.dot(p);
  }
  if (m.has_twist()) {
    LimbGeometry g = m.limbs;
    g.singularity_margin = 0.0;
    LimbPose pose;
    Mat3 grad;
    if (Status s = solve_limbs(g, p, pose); !s) return s;
    if (Status s = elbow_gradient(g, p, grad); !s) return s;
    for (int i = 0; i < 3; ++i)
      A.row(i) -= m.effects[i].twist * m.limbs.L2 * pose.cos_elbow[i] * grad.row(i);
  }
  const double det = A.determinant();
  if (!(std::abs(det) > 1e-6)) return Status::failure(Fault::singular_planes, -1, det, 1e-6);
  return {};
}
}  // namespace

Status jacobian(const KinematicModel& m, const Vec3& d, const Vec3& p, const KinematicInputs& in,
                Mat3& J) noexcept {
  Mat3 A;
  Vec3 diag;
  if (Status s = plane_differentials(m, d, p, in, A, diag); !s) return s;
  J = A.inverse() * diag.asDiagonal();
  return {};
}

Status inverse_jacobian(const KinematicModel& m, const Vec3& d, const Vec3& p, const KinematicInputs& in,
                        Mat3& J_inv) noexcept {
  Mat3 A;
  Vec3 diag;
  if (Status s = plane_differentials(m, d, p, in, A, diag); !s) return s;
  for (int i = 0; i < 3; ++i)
    if (!(std::abs(diag[i]) > 1e-12)) return Status::failure(Fault::singular_planes, i, diag[i], 1e-12);
  J_inv = diag.cwiseInverse().asDiagonal() * A;
  return {};
}

}  // namespace cpm::kin
