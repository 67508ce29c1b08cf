// SPDX-License-Identifier: Apache-2.0
// The one-page ball-bar report: the error sources of a simulated circular
// test with planted backlash and squareness, read back from the report's
// JSON, and the tolerance file.
#include <gtest/gtest.h>

#include <cstdio>
#include <fstream>
#include <map>
#include <nlohmann/json.hpp>

#include "cpm/calibration/ballbar.hpp"
#include "cpm/calibration/circular_report.hpp"
#include "cpm/control/machine.hpp"

namespace cpm::cal {
namespace {

// The generator: the true machine with backlash b on x and a squareness
// theta_z (y_true = y + theta_z x), followed kinematically (no servo error).
CircularTestResult planted_circle(double backlash, double theta_z) {
  BallbarParameters p;
  p.theta_z = theta_z;
  ctl::MachineModel truth = ctl::MachineModel::elkady();
  truth.kinematics.planes = ballbar_frame_planes(p);
  truth.kinematics.effects[0].backlash = backlash;
  CircularTestSpec s;
  s.closed_loop = false;
  return run_circular_test(truth, ctl::MachineModel::elkady(), s);
}

std::string write_temp(const std::string& name, const std::string& text) {
  const std::string path = ::testing::TempDir() + name;
  std::ofstream(path) << text;
  return path;
}

TEST(BallbarReport, EachPlantedErrorIsListedWithinTenPercentOfItsMicrons) {
  const double b = 20e-6, theta = 1e-4;  // 20 µm backlash; 100 µrad = 15 µm over R = 150 mm
  const CircularTestResult r = planted_circle(b, theta);
  const BallbarReport rep = make_ballbar_report(r, {});
  const auto j = nlohmann::json::parse(ballbar_report_json(rep));
  std::map<std::string, nlohmann::json> by_key;
  double share_sum = 0.0;
  for (const auto& e : j["errors"]) {
    by_key[e["key"].get<std::string>()] = e;
    share_sum += e["share_percent"].get<double>();
  }
  ASSERT_TRUE(by_key.count("backlash_x"));
  ASSERT_TRUE(by_key.count("squareness"));
  const double R = r.spec.radius;
  EXPECT_NEAR(by_key["backlash_x"]["contribution_um"].get<double>(), b * 1e6, 0.1 * b * 1e6);
  EXPECT_NEAR(by_key["backlash_x"]["value"].get<double>(), b, 0.1 * b);
  EXPECT_NEAR(by_key["squareness"]["contribution_um"].get<double>(), theta * R * 1e6, 0.1 * theta * R * 1e6);
  EXPECT_NEAR(by_key["squareness"]["value"].get<double>(), theta, 0.1 * theta);
  // What was not planted stays far below: under 5 % of the smaller plant.
  EXPECT_LT(by_key["backlash_y"]["contribution_um"].get<double>(), 0.05 * theta * R * 1e6);
  EXPECT_LT(by_key["scale_mismatch"]["contribution_um"].get<double>(), 0.05 * theta * R * 1e6);
  EXPECT_FALSE(by_key.count("servo_mismatch"));  // kinematic only: no servo to judge
  // The two plants carry nearly all of the circularity between them.
  EXPECT_GT(by_key["backlash_x"]["share_percent"].get<double>() + by_key["squareness"]["share_percent"].get<double>(), 85.0);
  EXPECT_NEAR(share_sum, 100.0, 1e-9);
  // Largest first: the backlash (20 µm) before the squareness (15 µm).
  EXPECT_EQ(j["errors"][0]["key"], "backlash_x");
  EXPECT_EQ(j["errors"].back()["key"], "not_explained");
}

TEST(BallbarReport, SwappedPlantsSwapTheList) {
  // Backlash on y and the opposite shear: the fit tells the axes and the sign apart.
  BallbarParameters p;
  p.theta_z = -2e-4;
  ctl::MachineModel truth = ctl::MachineModel::elkady();
  truth.kinematics.planes = ballbar_frame_planes(p);
  truth.kinematics.effects[1].backlash = 10e-6;
  CircularTestSpec s;
  s.closed_loop = false;
  const auto e = diagnose_circular_test(run_circular_test(truth, ctl::MachineModel::elkady(), s));
  std::map<std::string, BallbarError> k;
  for (const auto& v : e) k[v.key] = v;
  EXPECT_NEAR(k["squareness"].value, -2e-4, 2e-5);
  EXPECT_NEAR(k["backlash_y"].value, 10e-6, 1e-6);
  EXPECT_LT(k["backlash_x"].contribution, 0.5e-6);
}

TEST(BallbarReport, TolerancesFromTheFileJudgeEachFigure) {
  const CircularTestResult r = planted_circle(20e-6, 1e-4);
  const std::string path = write_temp("tol.yaml",
                                      "circularity_um: 10\n"
                                      "backlash_um: 25\n"
                                      "squareness_um_per_m: 150\n");
  const BallbarTolerances t = load_ballbar_tolerances(path);
  const BallbarReport rep = make_ballbar_report(r, t, 5.0);
  std::map<std::string, bool> pass;
  for (const auto& c : rep.checks) pass[c.what] = c.pass;
  EXPECT_FALSE(pass.at("circularity G (both runs)"));  // G > 20 µm
  EXPECT_TRUE(pass.at("backlash x"));
  EXPECT_TRUE(pass.at("backlash y"));
  EXPECT_TRUE(pass.at("squareness xy"));                // 100 µm/m against 150
  EXPECT_FALSE(rep.pass);
  EXPECT_EQ(rep.checks.size(), 4u);
  const std::string html = ballbar_report_html(rep, "test");
  for (const char* id : {"id=\"polar\"", "id=\"figures\"", "id=\"errors\"", "id=\"tolerances\"", "@page { size: A4"})
    EXPECT_NE(html.find(id), std::string::npos) << id;
  EXPECT_NE(html.find("+5 µm"), std::string::npos);  // the chosen magnification's rings
}

TEST(BallbarReport, ABadToleranceFileSaysWhichKeyAndLine) {
  try {
    load_ballbar_tolerances(write_temp("bad1.yaml", "circularity_um: 10\nbacklash: 3\n"));
    FAIL();
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("bad1.yaml:2: unknown tolerance 'backlash'"), std::string::npos) << e.what();
  }
  try {
    load_ballbar_tolerances(write_temp("bad2.yaml", "hysteresis_um: -1\n"));
    FAIL();
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("bad2.yaml:1: tolerance 'hysteresis_um' must be a number >= 0"),
              std::string::npos)
        << e.what();
  }
}

}  // namespace
}  // namespace cpm::cal
