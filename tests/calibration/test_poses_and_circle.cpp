// SPDX-License-Identifier: Apache-2.0
// Pose planning and the circular test: Kim's layout, the D-optimal set, the
// CSV, and the ISO 230-4 figures against closed forms.
#include <gtest/gtest.h>

#include <numbers>

#include "cpm/calibration/circular_test.hpp"
#include "cpm/calibration/kim.hpp"
#include "cpm/calibration/poses.hpp"

using namespace cpm;
using namespace cpm::cal;

namespace {
const Vec3 kPivot(0.430, 0.430, 0.530);
}

TEST(PosePlanning, KimsLayoutIs32ReachablePointsOnTwoUpperHemispheres) {
  const ctl::MachineModel m = ctl::MachineModel::elkady();
  const auto poses = kim_ballbar_poses(m, kPivot);
  ASSERT_EQ(poses.size(), 32u);
  int r100 = 0, r150 = 0;
  for (const PlannedPose& p : poses) {
    const double r = (p.p - kPivot).norm();
    r100 += std::abs(r - 0.100) < 1e-12;
    r150 += std::abs(r - 0.150) < 1e-12;
    EXPECT_LT(p.p.z(), kPivot.z());  // the upper side (z is down)
    EXPECT_TRUE(kin::check_pose(m.kinematics, m.strokes, p.p, {}).ok());
    EXPECT_NEAR(p.radius, r, 1e-15);
  }
  EXPECT_EQ(r100, 16);
  EXPECT_EQ(r150, 16);
}

TEST(PosePlanning, APivotNoPoseCanReachIsRefused) {
  const ctl::MachineModel m = ctl::MachineModel::elkady();
  try {
    kim_ballbar_poses(m, Vec3(1.2, 1.2, 1.3));
    FAIL();
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("no pose can reach this pivot"), std::string::npos) << e.what();
  }
  EXPECT_THROW(optimal_ballbar_poses(m, Vec3(1.2, 1.2, 1.3), {0.1, 0.15}, 32, true), Error);
}

TEST(PosePlanning, OptimalSetIsMoreObservableThanKimsAndReachable) {
  const ctl::MachineModel m = ctl::MachineModel::elkady();
  const auto kim = kim_ballbar_poses(m, kPivot);
  const auto opt = optimal_ballbar_poses(m, kPivot, {0.100, 0.150}, 32, true);
  ASSERT_EQ(opt.size(), 32u);
  for (const PlannedPose& p : opt) EXPECT_TRUE(kin::check_pose(m.kinematics, m.strokes, p.p, {}).ok());
  EXPECT_GT(ballbar_observability(m, kPivot, opt, true), ballbar_observability(m, kPivot, kim, true));
}

TEST(PosePlanning, CsvRoundTrip) {
  const ctl::MachineModel m = ctl::MachineModel::elkady();
  const auto poses = kim_ballbar_poses(m, kPivot);
  const std::string csv = poses_csv(poses, {{"kind", "poses"}, {"pivot", "0.43 0.43 0.53"}}, true);
  const std::vector<Vec3> back = parse_poses_csv(csv, "mem");
  ASSERT_EQ(back.size(), poses.size());
  for (std::size_t k = 0; k < back.size(); ++k) EXPECT_EQ(back[k], poses[k].p);
  try {
    parse_poses_csv("px,py\n0.1,0.2\n", "bad.csv");
    FAIL();
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("bad.csv:1: missing required column 'pz'"), std::string::npos) << e.what();
  }
}

TEST(CircularTest, APerfectModelDrawsAPerfectCircle) {
  CircularTestSpec s;
  s.closed_loop = false;
  const ctl::MachineModel m = kim_true_machine();
  const CircularTestResult r = run_circular_test(m, m, s);
  EXPECT_LT(r.max_abs_error, 1e-12);
  EXPECT_LT(r.G_bidirectional, 1e-12);
  EXPECT_LT(r.H, 1e-12);
}

TEST(CircularTest, SquarenessErrorGivesTheClosedFormEllipse) {
  // Limb 2's plane turned by theta_z: y_true = y + theta_z x, a shear whose
  // radial deviation is (R theta_z / 2) sin 2 phi: G = R theta_z, F = +-R theta_z / 2,
  // peaks at 45 degrees, no hysteresis.
  BallbarParameters b;
  b.theta_z = 1e-3;
  ctl::MachineModel truth = ctl::MachineModel::elkady();
  truth.kinematics.planes = ballbar_frame_planes(b);
  CircularTestSpec s;
  s.closed_loop = false;
  const CircularTestResult r = run_circular_test(truth, ctl::MachineModel::elkady(), s);
  const double R = s.radius;
  EXPECT_NEAR(r.ccw_metrics.G, R * 1e-3, 0.01 * R * 1e-3);
  EXPECT_NEAR(r.F_max, R * 1e-3 / 2, 0.01 * R * 1e-3);
  EXPECT_NEAR(r.F_min, -R * 1e-3 / 2, 0.01 * R * 1e-3);
  EXPECT_LT(r.H, 1e-9);
  // Peak at 45 degrees.
  std::size_t kmax = 0;
  for (std::size_t k = 0; k < r.ccw.angle.size(); ++k)
    if (r.ccw.deviation[k] > r.ccw.deviation[kmax]) kmax = k;
  const double a = std::fmod(r.ccw.angle[kmax], std::numbers::pi);
  EXPECT_NEAR(a, std::numbers::pi / 4, 0.01);
}

TEST(CircularTest, BacklashShowsAsHysteresisOfTheBacklash) {
  // Backlash b on axis x: the platform lags by b/2 against the motion, so
  // CCW and CW differ radially by b |cos phi|: H = b.
  ctl::MachineModel truth = ctl::MachineModel::elkady();
  truth.kinematics.effects[0].backlash = 20e-6;
  CircularTestSpec s;
  s.closed_loop = false;
  const CircularTestResult r = run_circular_test(truth, ctl::MachineModel::elkady(), s);
  EXPECT_NEAR(r.H, 20e-6, 1e-6);
  EXPECT_GT(r.H, 10 * 1e-9);
}

TEST(CircularTest, ClosedLoopAfterCalibrationIsNearlyPerfect) {
  // Short circle (r = 50 mm at 50 mm/s) with the servo in the loop: before
  // calibration the shear of Kim's machine, after it only the servo's few µm.
  CircularTestSpec s;
  s.radius = 0.050;
  s.feed = 0.05;
  s.overshoot_time = 0.3;
  const ctl::MachineModel truth = kim_true_machine();
  ctl::MachineModel calibrated = truth;  // the exact calibration
  const CircularTestResult before = run_circular_test(truth, ctl::MachineModel::elkady(), s);
  const CircularTestResult after = run_circular_test(truth, calibrated, s);
  EXPECT_NEAR(before.G_bidirectional, s.radius * kim_fitted_errors().theta_z, 5e-6);
  EXPECT_LT(after.G_bidirectional, 3e-6);
  EXPECT_GT(after.servo_rms, 0.0);
  EXPECT_LT(after.servo_rms, 20e-6);
  const std::string svg = circular_test_svg(after, "test");
  EXPECT_EQ(svg.rfind("<svg", 0), 0u);
  EXPECT_NE(svg.find("</svg>"), std::string::npos);
  EXPECT_NE(svg.find("µm"), std::string::npos);
  std::size_t n = 0, pos = 0;
  while ((pos = svg.find("<polyline", pos)) != std::string::npos) ++n, ++pos;
  EXPECT_EQ(n, 2u);
}

TEST(KimExperiment, CalibrationCutsTheCircularErrorToTheNoise) {
  KimOptions o;
  o.circle.closed_loop = false;
  const KimReproduction k = reproduce_kim(o);
  EXPECT_TRUE(k.all_within_3sigma) << k.report();
  // Before: the shear of theta_z = 0.113 deg over R = 150 mm, R theta_z / 2 = 148 µm.
  EXPECT_NEAR(k.before.max_abs_error, 0.150 * kim_fitted_errors().theta_z / 2, 3e-6);
  EXPECT_LT(k.after.max_abs_error, 1e-6);
}
