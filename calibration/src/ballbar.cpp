// SPDX-License-Identifier: Apache-2.0
#include "cpm/calibration/ballbar.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>

#include "cpm/calibration/position.hpp"

namespace cpm::cal {
namespace {

// The ball-bar frame's normals and their derivatives.
struct FrameNormals {
  Mat3 U;          // rows u_1', u_2', u_3'
  Vec3 du2_dtz;
  Vec3 du3_dtx, du3_dty;
};

FrameNormals frame_normals(double tz, double tx, double ty) {
  FrameNormals f;
  const double sz = std::sin(tz), cz = std::cos(tz);
  const double sx = std::sin(tx), cx = std::cos(tx);
  const double sy = std::sin(ty), cy = std::cos(ty);
  f.U.row(0) = Vec3(1.0, 0.0, 0.0).transpose();
  f.U.row(1) = Vec3(-sz, cz, 0.0).transpose();
  f.U.row(2) = Vec3(cx * sy, -sx, cx * cy).transpose();
  f.du2_dtz = Vec3(-cz, -sz, 0.0);
  f.du3_dtx = Vec3(-sx * sy, -cx, -sx * cy);
  f.du3_dty = Vec3(cx * cy, 0.0, -cx * sy);
  return f;
}

// The 15 numbers of the machine-frame planes (u_1, u_2, u_3, c, n) from eta.
VecX machine_plane_numbers(const VecX& eta, const Vec3& pivot_nominal) {
  const BallbarParameters b = BallbarParameters::from_vector(eta);
  const kin::KinematicModel m = ballbar_to_machine(b, pivot_nominal, kin::KinematicModel::nominal());
  VecX out(15);
  for (int i = 0; i < 3; ++i) {
    out.segment<3>(3 * i) = m.planes[i].normal;
    out[9 + i] = m.planes[i].scale;
    out[12 + i] = m.planes[i].offset;
  }
  return out;
}

std::string um(double v) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.2f µm", v * 1e6);
  return buf;
}

}  // namespace

VecX BallbarParameters::vector(bool with_dl) const {
  VecX e(10);
  e << c[0], c[1], theta_z, c[2], theta_x, theta_y, dq[0], dq[1], dq[2], dl;
  if (!with_dl) return e.head(9);
  return e;
}

BallbarParameters BallbarParameters::from_vector(const VecX& e) {
  if (e.size() != 9 && e.size() != 10) throw Error("ball-bar parameters: expected 9 or 10 values");
  BallbarParameters b;
  b.c = Vec3(e[0], e[1], e[3]);
  b.theta_z = e[2];
  b.theta_x = e[4];
  b.theta_y = e[5];
  b.dq = Vec3(e[6], e[7], e[8]);
  b.dl = e.size() == 10 ? e[9] : 0.0;
  return b;
}

std::vector<std::string> ballbar_parameter_names(bool with_dl) {
  std::vector<std::string> n{"c1", "c2", "theta_z", "c3", "theta_x", "theta_y", "dq_x", "dq_y", "dq_z"};
  if (with_dl) n.push_back("dl");
  return n;
}

std::vector<std::string> ballbar_parameter_units(bool with_dl) {
  std::vector<std::string> u{"1", "1", "rad", "1", "rad", "rad", "m", "m", "m"};
  if (with_dl) u.push_back("m");
  return u;
}

std::array<kin::LimbPlane, 3> ballbar_frame_planes(const BallbarParameters& b) {
  const FrameNormals f = frame_normals(b.theta_z, b.theta_x, b.theta_y);
  std::array<kin::LimbPlane, 3> pl;
  for (int i = 0; i < 3; ++i) {
    pl[i].normal = f.U.row(i).transpose();
    pl[i].scale = b.c[i];
    pl[i].offset = 0.0;
  }
  return pl;
}

BallbarParameters ballbar_parameters_of(const kin::KinematicModel& truth, const Vec3& pivot_true,
                                        const Vec3& pivot_nominal, double dl) {
  Mat3 U;
  Vec3 n;
  for (int i = 0; i < 3; ++i) {
    U.row(i) = truth.planes[i].normal.transpose();
    n[i] = truth.planes[i].offset;
  }
  // Origin: where the planes with zero offsets meet; axes: x along u_1,
  // z normal to u_1 and u_2 (Kim Fig. 5).
  const Vec3 o = U.partialPivLu().solve(n);
  const Vec3 x = U.row(0).transpose().normalized();
  const Vec3 z = x.cross(U.row(1).transpose()).normalized();
  const Vec3 y = z.cross(x);
  Mat3 R;
  R.row(0) = x.transpose();
  R.row(1) = y.transpose();
  R.row(2) = z.transpose();
  const Vec3 u2 = R * U.row(1).transpose();
  const Vec3 u3 = R * U.row(2).transpose();
  BallbarParameters b;
  b.c = Vec3(truth.planes[0].scale, truth.planes[1].scale, truth.planes[2].scale);
  b.theta_z = std::atan2(-u2.x(), u2.y());
  b.theta_x = std::asin(std::clamp(-u3.y(), -1.0, 1.0));
  b.theta_y = std::atan2(u3.x(), u3.z());
  b.dq = R * (pivot_true - o) - pivot_nominal;
  b.dl = dl;
  return b;
}

FrameTransform machine_frame_of(const BallbarParameters& b, const Vec3& pivot_nominal) {
  const FrameNormals f = frame_normals(b.theta_z, b.theta_x, b.theta_y);
  // Q maximising sum_i e_i^T Q u_i' = tr(Q U'^T): with U'^T = W S V^T, Q = V W^T.
  Eigen::JacobiSVD<Mat3> svd(f.U.transpose(), Eigen::ComputeFullU | Eigen::ComputeFullV);
  Mat3 V = svd.matrixV();
  if ((V * svd.matrixU().transpose()).determinant() < 0.0) V.col(2) *= -1.0;
  FrameTransform t;
  t.rotation = V * svd.matrixU().transpose();
  t.translation = pivot_nominal - t.rotation * (pivot_nominal + b.dq);
  return t;
}

kin::KinematicModel ballbar_to_machine(const BallbarParameters& b, const Vec3& pivot_nominal,
                                       const kin::KinematicModel& base) {
  const FrameTransform t = machine_frame_of(b, pivot_nominal);
  const auto pl = ballbar_frame_planes(b);
  kin::KinematicModel m = base;
  for (int i = 0; i < 3; ++i) {
    m.planes[i].normal = (t.rotation * pl[i].normal).normalized();
    m.planes[i].scale = pl[i].scale;
    m.planes[i].offset = m.planes[i].normal.dot(t.translation);
  }
  return m;
}

void ballbar_residuals(const VecX& eta, const Vec3& d0, const std::vector<Vec3>& d,
                       const std::vector<double>& lengths, const Vec3& pivot_nominal, VecX& r,
                       MatX* J) {
  const BallbarParameters b = BallbarParameters::from_vector(eta);
  const bool with_dl = eta.size() == 10;
  const FrameNormals f = frame_normals(b.theta_z, b.theta_x, b.theta_y);
  const double det = f.U.determinant();
  if (!(std::abs(det) > 1e-6)) throw Error("ball-bar calibration: the limb planes became parallel");
  const Mat3 W = f.U.inverse();
  const Vec3 q = pivot_nominal + b.dq;
  const Eigen::Index N = static_cast<Eigen::Index>(d.size());
  r.resize(N);
  if (J) J->setZero(N, eta.size());
  for (Eigen::Index j = 0; j < N; ++j) {
    const Vec3& dj = d[static_cast<std::size_t>(j)];
    const Vec3 s = (dj + d0).cwiseProduct(b.c);
    const Vec3 p = W * s;
    const Vec3 v = p - q;
    const double len = v.norm();
    r[j] = len - (lengths[static_cast<std::size_t>(j)] + b.dl);
    if (!J) continue;
    if (!(len > 0.0)) throw Error("ball-bar calibration: a pose coincides with the pivot");
    const Vec3 e = v / len;
    const Vec3 g = W.transpose() * e;  // d h / d (row-i right-hand side) = g_i
    // p = U^-1 s: dp = U^-1 (ds - dU p).
    (*J)(j, 0) = g[0] * (dj[0] + d0[0]);
    (*J)(j, 1) = g[1] * (dj[1] + d0[1]);
    (*J)(j, 2) = -g[1] * f.du2_dtz.dot(p);
    (*J)(j, 3) = g[2] * (dj[2] + d0[2]);
    (*J)(j, 4) = -g[2] * f.du3_dtx.dot(p);
    (*J)(j, 5) = -g[2] * f.du3_dty.dot(p);
    J->block<1, 3>(j, 6) = -e.transpose();
    if (with_dl) (*J)(j, 9) = -1.0;
  }
}

BallbarFit fit_ballbar(const kin::KinematicModel& start, const std::vector<Vec3>& d,
                       const std::vector<double>& lengths, const Vec3& pivot, const BallbarOptions& o) {
  if (d.size() != lengths.size())
    throw Error("ball-bar calibration: as many actuator readings as lengths needed");
  const bool with_dl = !o.length_offset_known;
  const std::size_t P = with_dl ? 10 : 9;
  for (std::size_t j = 0; j < d.size(); ++j)
    if (!d[j].allFinite() || !std::isfinite(lengths[j]))
      throw Error("ball-bar calibration: row " + std::to_string(j + 1) + " is not finite");
  if (!pivot.allFinite()) throw Error("ball-bar calibration: the pivot is not finite");
  if (d.size() < P + 1)
    throw DegeneratePoses("ball-bar calibration needs more lengths than its " + std::to_string(P) +
                          " unknowns (c1, c2, theta_z, c3, theta_x, theta_y, dq" +
                          std::string(with_dl ? ", dl" : "") + "), got " + std::to_string(d.size()) +
                          " rows; measure at least " + std::to_string(2 * P) +
                          " poses spread over the hemisphere around the pivot (Kim used 32)");
  BallbarFit fit;
  VecX eta = BallbarParameters{}.vector(with_dl);
  const Vec3 d0 = start.d0;
  const ResidualFunction f = [&](const VecX& x, VecX& r, MatX* J) {
    ballbar_residuals(x, d0, d, lengths, pivot, r, J);
  };
  // Partial: the directions of eta the poses determine, as the columns of
  // `span` (scaled), found where the model is.
  MatX span;
  if (o.partial) {
    eta = ballbar_parameters_of(start, pivot, pivot).vector(with_dl);
    VecX r;
    MatX J;
    f(eta, r, &J);
    VecX scale(J.cols());
    for (Eigen::Index j = 0; j < J.cols(); ++j) scale[j] = J.col(j).norm() > 0.0 ? 1.0 / J.col(j).norm() : 0.0;
    const Eigen::JacobiSVD<MatX> svd(J * scale.asDiagonal(), Eigen::ComputeThinV);
    const VecX& sv = svd.singularValues();
    int k = 0;
    while (k < sv.size() && sv[k] > o.refuse_relative_singular_value * sv[0]) ++k;
    span = scale.asDiagonal() * svd.matrixV().leftCols(k);
    if (k < J.cols()) {
      VecX inv(J.cols());
      for (Eigen::Index j = 0; j < J.cols(); ++j) inv[j] = scale[j] > 0.0 ? 1.0 / scale[j] : 0.0;
      fit.determined = span * svd.matrixV().leftCols(k).transpose() * inv.asDiagonal();
    }
    if (k < J.cols()) {
      const auto names = ballbar_parameter_names(with_dl);
      for (Eigen::Index c = k; c < J.cols(); ++c) {
        std::string combo;
        const VecX v = svd.matrixV().col(c);
        for (Eigen::Index j = 0; j < v.size(); ++j)
          if (std::fabs(v[j]) > 0.1) {
            char t[64];
            std::snprintf(t, sizeof t, "%s%+.2f %s", combo.empty() ? "" : " ", v[j], names[static_cast<std::size_t>(j)].c_str());
            combo += t;
          }
        fit.warnings.push_back("partial calibration: these poses cannot determine " + combo +
                               "; kept at the model's value");
      }
    }
  }
  if (o.partial && span.cols() < eta.size()) {
    if (span.cols() == 0) throw DegeneratePoses("ball-bar calibration: these poses determine no parameter");
    const VecX eta0 = eta;
    const ResidualFunction fz = [&](const VecX& z, VecX& r, MatX* J) {
      MatX Jf;
      ballbar_residuals(eta0 + span * z, d0, d, lengths, pivot, r, J ? &Jf : nullptr);
      if (J) *J = Jf * span;
    };
    VecX z = VecX::Zero(span.cols());
    fit.lm = levenberg_marquardt(fz, z, o.lm);
    eta = eta0 + span * z;
  } else {
    // Refuse a pose set whose Jacobian is singular at the start: no amount of
    // iteration will determine what it cannot see.
    VecX r;
    MatX J;
    f(eta, r, &J);
    IdentifiabilityOptions io = o.identifiability;
    io.undetermined_threshold = o.refuse_relative_singular_value;
    const Identifiability pre = analyse_identifiability(J, r, eta, ballbar_parameter_names(with_dl),
                                                        ballbar_parameter_units(with_dl), io);
    for (const WeakCombination& w : pre.weak) {
      if (!w.undetermined) continue;
      bool has_dl = false;
      for (const auto& t : w.terms) has_dl = has_dl || pre.names[t.first] == "dl";
      // With one bar length the bar offset and the machine's scale are
      // exactly degenerate at the nominal model (every modelled distance
      // equals the one radius); the machine's own errors break the tie a
      // little. Fit, and warn afterwards.
      if (has_dl) continue;
      std::vector<Vec3> dirs;
      for (std::size_t j = 0; j < d.size(); ++j) {
        Vec3 p;
        kin::forward(start, d[j], {}, p);
        dirs.push_back((p - pivot).normalized());
      }
      const PoseSpread sp = pose_spread(dirs);
      char buf[200];
      std::snprintf(buf, sizeof buf,
                    "; the directions from the pivot to the poses spread %.3f, %.3f, %.3f (RMS of "
                    "the unit vectors along their principal axes)",
                    sp.extent[0], sp.extent[1], sp.extent[2]);
      throw DegeneratePoses(
          "ball-bar calibration refused: these poses cannot determine the combination " +
          pre.describe_combination(w) + buf +
          "; spread the poses over the hemisphere around the pivot: several heights and azimuths "
          "all around it (cpm plan-poses --layout kim)");
    }
    fit.lm = levenberg_marquardt(f, eta, o.lm);
  }
  if (!fit.lm.converged)
    fit.warnings.push_back("the nonlinear least squares did not converge: " + fit.lm.reason);
  VecX r;
  MatX J;
  f(eta, r, &J);
  fit.identifiability = analyse_identifiability(J, r, eta, ballbar_parameter_names(with_dl),
                                                ballbar_parameter_units(with_dl), o.identifiability);
  const Identifiability& id = fit.identifiability;
  fit.warnings.insert(fit.warnings.end(), id.warnings.begin(), id.warnings.end());
  if (with_dl) {
    double lmin = lengths[0], lmax = lengths[0], lsum = 0.0;
    for (double l : lengths) {
      lmin = std::min(lmin, l);
      lmax = std::max(lmax, l);
      lsum += l;
    }
    const double lmean = lsum / static_cast<double>(lengths.size());
    const int k = id.index("dl");
    if (lmax - lmin < 0.1 * lmean || id.multiple_correlation[k] > 0.999) {
      char buf[480];
      std::snprintf(buf, sizeof buf,
                    "dl (the bar's length offset) cannot be determined from one bar length: the "
                    "lengths span only %.3f mm, and a bar that reads long cannot be told from a "
                    "machine that is uniformly too large (common scale of c1, c2, c3); dl = %s ± "
                    "%s. Measure at a second bar length (Kim: 100 and 150 mm), or calibrate the "
                    "bar against a length standard and set length_offset_known = true",
                    (lmax - lmin) * 1e3, um(eta[k]).c_str(), um(id.std_error[k]).c_str());
      fit.warnings.push_back(buf);
    }
  }
  if (o.sigma > 0.0 && id.dof > 0 && id.residual_sigma > 3.0 * o.sigma) {
    char buf[320];
    std::snprintf(buf, sizeof buf,
                  "the residuals (%.3f µm) are %.1f times the bar's sigma (%.3f µm): the plane "
                  "model does not explain these data; look for a kinematic effect or a bad reading",
                  id.residual_sigma * 1e6, id.residual_sigma / o.sigma, o.sigma * 1e6);
    fit.warnings.push_back(buf);
  }
  fit.params = BallbarParameters::from_vector(eta);
  fit.frame = machine_frame_of(fit.params, pivot);
  fit.model = ballbar_to_machine(fit.params, pivot, start);
  fit.model.validate();
  // Propagate the covariance of eta to the machine-frame planes (central
  // differences of a smooth map: the frame choice is not in the residuals).
  const VecX g0 = machine_plane_numbers(eta, pivot);
  MatX G(15, eta.size());
  for (Eigen::Index j = 0; j < eta.size(); ++j) {
    const double h = 1e-7;
    VecX ep = eta, em = eta;
    ep[j] += h;
    em[j] -= h;
    G.col(j) = (machine_plane_numbers(ep, pivot) - machine_plane_numbers(em, pivot)) / (2.0 * h);
  }
  const MatX C = G * id.covariance * G.transpose();
  VecX se = C.diagonal().cwiseMax(0.0).cwiseSqrt();
  for (Eigen::Index j = 0; j < eta.size(); ++j)
    if (!std::isfinite(id.std_error[j]))
      for (Eigen::Index k = 0; k < 15; ++k)
        if (std::abs(G(k, j)) > 1e-12) se[k] = INFINITY;
  for (int i = 0; i < 3; ++i) {
    fit.normal_std_error[i] = se.segment<3>(3 * i);
    fit.scale_std_error[i] = se[9 + i];
    fit.offset_std_error[i] = se[12 + i];
  }
  return fit;
}

}  // namespace cpm::cal
