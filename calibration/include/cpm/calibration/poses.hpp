// SPDX-License-Identifier: Apache-2.0
// Measurement poses: where to put the platform for a calibration. Every pose
// is a commanded platform point (machine frame, m) checked against the
// workspace of the model that will command it (kin::check_pose: strokes,
// limb reach, singularity distance).
//
//  * Kim's layout (section 5): 32 points on two hemispheres of radius 0.100
//    and 0.150 m about the pivot, on the reachable side (z smaller, up):
//    per hemisphere two rings of 8 at 30 and 65 degrees from the pole,
//    the rings and the hemispheres turned against each other so that no
//    two poses share an azimuth.
//  * A set chosen to maximise an observability index: D-optimal selection
//    (greedy, then exchange passes) from a pool of reachable candidates -
//    points on the spheres of the bar lengths (ball-bar) or a grid over the
//    workspace (full position) - maximising O1 = det(J^T J)^(1/2P) / sqrt(N)
//    (Borm and Menq's index: the geometric mean of the singular values of J
//    per measurement), with J the Jacobian of the measurements with respect
//    to the calibration parameters at the nominal machine.
#pragma once

#include <string>
#include <vector>

#include "cpm/calibration/least_squares.hpp"
#include "cpm/control/machine.hpp"

namespace cpm::cal {

struct PlannedPose {
  Vec3 p = Vec3::Zero();   // commanded platform point (m)
  Vec3 d = Vec3::Zero();   // encoder targets through the model (m)
  double radius = 0.0;     // ball-bar: distance to the pivot (m); 0 for position sets
};

// Kim's 32 points. Throws Error naming each pose the model cannot reach and why.
std::vector<PlannedPose> kim_ballbar_poses(const ctl::MachineModel& model, const Vec3& pivot,
                                           const std::vector<double>& radii = {0.100, 0.150});

// D-optimal ball-bar poses on spheres of the given radii about the pivot.
// Throws Error when no candidate (or too few) is reachable.
std::vector<PlannedPose> optimal_ballbar_poses(const ctl::MachineModel& model, const Vec3& pivot,
                                               const std::vector<double>& radii, int count,
                                               bool length_offset_known);

// D-optimal full-position poses from a grid over the workspace.
std::vector<PlannedPose> optimal_position_poses(const ctl::MachineModel& model, int count);

// O1 of a pose set (m per unit parameter, see above).
double ballbar_observability(const ctl::MachineModel& model, const Vec3& pivot,
                             const std::vector<PlannedPose>& poses, bool length_offset_known);
double position_observability(const ctl::MachineModel& model, const std::vector<PlannedPose>& poses);
double observability_index(const MatX& J);

// Throws Error naming the first pose outside the model's workspace.
void check_poses(const ctl::MachineModel& model, const std::vector<Vec3>& poses);

// CSV of commanded positions: `px,py,pz,d1,d2,d3[,radius]` (m), with
// `# key = value` metadata lines (kind = poses, layout, pivot, ...).
std::string poses_csv(const std::vector<PlannedPose>& poses,
                      const std::vector<std::pair<std::string, std::string>>& metadata,
                      bool with_radius);

// Read the commanded points (columns px, py, pz) of such a CSV (other
// columns ignored). Throws Error naming the file, line and column.
std::vector<Vec3> read_poses_csv(const std::string& path);
std::vector<Vec3> parse_poses_csv(const std::string& text, const std::string& name);

}  // namespace cpm::cal
