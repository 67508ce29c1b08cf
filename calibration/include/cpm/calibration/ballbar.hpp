// SPDX-License-Identifier: Apache-2.0
// Ball-bar calibration (Kim 2005, section 4.2). A ball-bar measures the
// distance between a ball on the platform (at P) and a fixed ball (the pivot)
// at actuator readings d_j. Distances do not see the frame: its origin and
// orientation are free, so the 12 plane parameters reduce to 6 in the
// ball-bar frame of docs/calibration.md:
//   u_1 = (1, 0, 0), u_2 = (-sin tz, cos tz, 0),
//   u_3 = (cos tx sin ty, -sin tx, cos tx cos ty),  n_i = 0,
// with the scales c_i used directly where Kim has cos(gamma_i). Unknowns
// eta = (c1, c2, theta_z, c3, theta_x, theta_y, dq_x, dq_y, dq_z[, dl]):
//   h_j = | p'(d_j) - (q + dq) | - (l_j + dl)     (Kim eqs. 15-17)
// with q the nominal pivot and dl the bar's length offset (fitted only when
// the bar's length is not known).
//
// What the data can determine: the 6 shape parameters and dq from poses
// spread over a hemisphere; dl only together with the common scale of
// c1..c3 - one bar length cannot tell a bar that reads long from a machine
// that is uniformly too large. Two bar lengths (Kim's 100 and 150 mm) or a
// calibrated bar separate them.
//
// From ball-bar frame to machine frame (the controller's model). Two choices
// fix the gauge the ball-bar cannot see:
//  * orientation: the rotation Q that best aligns the three fitted limb
//    normals with the machine axes (least squares, sum |Q u_i' - e_i|^2):
//    the machine's axes are the best compromise of its three actuators,
//    squareness errors shared rather than all put on limbs 2 and 3;
//  * origin: the fitted pivot q + dq lands on the nominal pivot q, the
//    position the user declared for it. The calibrated machine is registered
//    to the pivot: commanding the platform to q puts the ball on the pivot.
// Then p = Q p' + t with t = q - Q (q + dq), u_i = Q u_i', n_i = u_i^T t.
#pragma once

#include <array>
#include <string>
#include <vector>

#include "cpm/calibration/identifiability.hpp"
#include "cpm/calibration/least_squares.hpp"
#include "cpm/kinematics/plane_model.hpp"

namespace cpm::cal {

struct BallbarParameters {
  Vec3 c = Vec3::Ones();  // scales c1, c2, c3 (1)
  double theta_z = 0.0;   // rad
  double theta_x = 0.0;   // rad
  double theta_y = 0.0;   // rad
  Vec3 dq = Vec3::Zero(); // pivot error in the ball-bar frame (m)
  double dl = 0.0;        // bar length offset (m): true length = reading + dl

  // eta in Kim's order; dl last, only when `with_dl`.
  [[nodiscard]] VecX vector(bool with_dl) const;
  static BallbarParameters from_vector(const VecX& eta);  // size 9 (dl = 0) or 10
};

std::vector<std::string> ballbar_parameter_names(bool with_dl);
std::vector<std::string> ballbar_parameter_units(bool with_dl);

// The three planes in the ball-bar frame (n_i = 0).
std::array<kin::LimbPlane, 3> ballbar_frame_planes(const BallbarParameters& b);

// What a perfect fit would find for a machine `truth` (planes in any frame)
// with the pivot really at `pivot_true` (same frame): the ball-bar-frame
// parameters, with dq relative to `pivot_nominal`.
BallbarParameters ballbar_parameters_of(const kin::KinematicModel& truth, const Vec3& pivot_true,
                                        const Vec3& pivot_nominal, double dl = 0.0);

// p_machine = rotation * p' + translation.
struct FrameTransform {
  Mat3 rotation = Mat3::Identity();
  Vec3 translation = Vec3::Zero();
};
FrameTransform machine_frame_of(const BallbarParameters& b, const Vec3& pivot_nominal);
// `base` with its planes replaced by the ball-bar fit, in the machine frame.
kin::KinematicModel ballbar_to_machine(const BallbarParameters& b, const Vec3& pivot_nominal,
                                       const kin::KinematicModel& base);

// Residuals h_j and their Jacobian with respect to eta (analytic).
void ballbar_residuals(const VecX& eta, const Vec3& d0, const std::vector<Vec3>& d,
                       const std::vector<double>& lengths, const Vec3& pivot_nominal, VecX& r,
                       MatX* J);

struct BallbarOptions {
  LmOptions lm;
  IdentifiabilityOptions identifiability;
  bool length_offset_known = true;  // false: fit dl
  double refuse_relative_singular_value = 1e-8;  // at the start: refuse the pose set below this
  // Instead of refusing a pose set that cannot determine every parameter (a
  // circle in one plane: the out-of-plane tilt, scale and pivot height), fit
  // the combinations it determines, starting from `start`'s own parameters,
  // and keep the others at those values; the warnings name what was kept.
  bool partial = false;
  double sigma = 0.0;  // the bar's standard deviation (m) when known, for a consistency check
};

struct BallbarFit {
  BallbarParameters params;           // in the ball-bar frame
  // Partial fits only (BallbarOptions::partial, poses that cannot determine
  // every parameter): the projector onto what they determine, in eta's units
  // (a change d of eta moves the fit by determined * d). Empty otherwise.
  MatX determined;
  LmReport lm;
  Identifiability identifiability;    // over eta
  FrameTransform frame;               // ball-bar frame -> machine frame
  kin::KinematicModel model;          // calibrated, machine frame
  // Standard errors of the machine-frame planes, propagated from eta.
  std::array<Vec3, 3> normal_std_error{};
  Vec3 scale_std_error = Vec3::Zero();
  Vec3 offset_std_error = Vec3::Zero();
  std::vector<std::string> warnings;
};

// Throws DegeneratePoses when the pose set cannot determine eta, Error on bad input.
BallbarFit fit_ballbar(const kin::KinematicModel& start, const std::vector<Vec3>& d,
                       const std::vector<double>& lengths, const Vec3& pivot_nominal,
                       const BallbarOptions& options = {});

}  // namespace cpm::cal
