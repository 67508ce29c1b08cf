// SPDX-License-Identifier: Apache-2.0
// Full-position calibration (Kim 2005, section 4.1): a 3-D instrument (laser
// tracker, CMM) measures the platform point p_j in the machine frame at
// actuator readings d_j. All 12 plane parameters are identifiable:
// per limb i the normal u_i (two tilt angles), the scale c_i and the offset n_i
// of  u_i^T p = (d~_i + d0_i) c_i + n_i  (docs/model.md, "Kinematics").
//
// Two stages:
//  1. Kim's analytic solution (eqs. 10-13), per limb, generalised from 4
//     poses to N >= 4 noisy poses by linear least squares on the pose
//     differences from their mean. Exact from 4 poses without noise.
//  2. Levenberg-Marquardt over the 12 parameters minimising the position
//     residuals p^c(d_j) - p_j (all three coordinates), analytic Jacobian.
// Displacements passed in are the effective ones d~ (the encoder readings
// when the model has no kinematic effects).
#pragma once

#include <array>
#include <string>
#include <vector>

#include "cpm/calibration/identifiability.hpp"
#include "cpm/calibration/least_squares.hpp"
#include "cpm/kinematics/plane_model.hpp"

namespace cpm::cal {

// Refusal of a pose set that cannot determine the parameters; the message
// says why and which poses to add.
class DegeneratePoses : public Error {
 public:
  using Error::Error;
};

// The plane normal of limb i from two tilt angles (rad):
//   u_i = normalise(e_i + tan(t_a) e_a + tan(t_b) e_b),
// a < b the two other machine axes. t_a is the tilt of the plane seen in the
// (i, a) plane. Regular near the nominal u_i = e_i; the ratios u_a/u_i and
// u_b/u_i are Kim's unknowns of eq. 12. `d_dt` (optional) receives du/dt_a, du/dt_b.
Vec3 normal_from_tilts(int limb, double t_a, double t_b, Eigen::Matrix<double, 3, 2>* d_dt = nullptr);
void tilts_from_normal(int limb, const Vec3& u, double& t_a, double& t_b);
// The axes a < b other than `limb` (0..2).
std::array<int, 2> other_axes(int limb);

// Spread of a cloud of points: RMS extent along its principal directions.
struct PoseSpread {
  Vec3 extent = Vec3::Zero();      // m, descending
  Mat3 directions = Mat3::Zero();  // columns: the principal directions
};
PoseSpread pose_spread(const std::vector<Vec3>& p);

struct AnalyticSolution {
  std::array<kin::LimbPlane, 3> planes{};
  Vec3 condition = Vec3::Zero();   // condition number of each limb's matrix of eq. 13 (N x 3)
  std::vector<std::string> warnings;
};

struct PositionOptions {
  LmOptions lm;
  IdentifiabilityOptions identifiability;
  double refuse_condition = 1e3;  // eq. 13's matrix worse than this: refused
  double warn_condition = 30.0;   // worse than this: a warning
  double sigma = 0.0;             // instrument's standard deviation (m), 0 = unknown
};

// Kim's eqs. 10-13 by least squares. Throws DegeneratePoses (fewer than 4
// poses, or poses that do not span three dimensions).
AnalyticSolution solve_positions_analytic(const std::vector<Vec3>& d, const std::vector<Vec3>& p,
                                          const Vec3& d0, const PositionOptions& options = {});

// Parameter order of the fit: for each limb i = 1..3: tilt a, tilt b (rad), c_i (1), n_i (m).
std::vector<std::string> position_parameter_names();
std::vector<std::string> position_parameter_units();

struct PositionFit {
  kin::KinematicModel model;        // `start` with the calibrated planes
  AnalyticSolution analytic;        // stage 1
  LmReport lm;                      // stage 2
  Identifiability identifiability;  // over the 12 parameters of stage 2
  std::array<Vec3, 3> normal_std_error{};  // standard error of each normal's components
  std::vector<std::string> warnings;       // analytic + identifiability + noise check
};

PositionFit fit_positions(const kin::KinematicModel& start, const std::vector<Vec3>& d,
                          const std::vector<Vec3>& p, const PositionOptions& options = {});

// Position residuals p^c(d_j) - p_j (3 per pose) of a plane model, and their
// Jacobian with respect to the parameters in position_parameter_names() order.
void position_residuals(const std::array<kin::LimbPlane, 3>& planes, const Vec3& d0,
                        const std::vector<Vec3>& d, const std::vector<Vec3>& p, VecX& r, MatX* J);

}  // namespace cpm::cal
