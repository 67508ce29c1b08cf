// SPDX-License-Identifier: Apache-2.0
// Calibration from files (what `cpm calibrate` runs): the model file round
// trip through the writer, and bad input refused with a clear message and
// no file written.
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <sstream>
#include <unistd.h>

#include <nlohmann/json.hpp>

#include "cpm/calibration/kim.hpp"
#include "cpm/calibration/simulate.hpp"
#include "cpm/calibration/workflow.hpp"

using namespace cpm;
using namespace cpm::cal;
namespace fs = std::filesystem;

namespace {

class CalibrationFiles : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() / ("cpm_calib_test_" + std::to_string(::getpid()) + "_" +
                                        ::testing::UnitTest::GetInstance()->current_test_info()->name());
    fs::create_directories(dir_);
    model_ = (dir_ / "machine.yaml").string();
    io::save_model_file(model_, io::ModelFile{});
    out_ = (dir_ / "calibrated.yaml").string();
  }
  void TearDown() override { fs::remove_all(dir_); }

  std::string path(const std::string& name) const { return (dir_ / name).string(); }

  // Kim's simulated ball-bar data as a file.
  std::string kim_ballbar_file() {
    KimOptions o;
    o.circular_test = false;
    const KimReproduction k = reproduce_kim(o);
    const std::string p = path("ballbar.csv");
    io::write_ballbar(p, k.data);
    return p;
  }

  static std::string read(const std::string& p) {
    std::ifstream f(p);
    std::ostringstream s;
    s << f.rdbuf();
    return s.str();
  }
  static void write(const std::string& p, const std::string& text) {
    std::ofstream f(p);
    f << text;
  }

  // Runs the calibration expecting an error that contains every `needle`, and no output file.
  void expect_refused(const std::string& data, const std::vector<std::string>& needles) {
    const std::string json = path("report.json");
    try {
      calibrate_files(model_, data, out_, json, "test");
      FAIL() << "bad input accepted: " << data;
    } catch (const Error& e) {
      for (const std::string& n : needles)
        EXPECT_NE(std::string(e.what()).find(n), std::string::npos) << "'" << n << "' not in: " << e.what();
    }
    EXPECT_FALSE(fs::exists(out_)) << "a model file was written for bad input";
    EXPECT_FALSE(fs::exists(json)) << "a JSON report was written for bad input";
  }

  fs::path dir_;
  std::string model_, out_;
};

}  // namespace

TEST_F(CalibrationFiles, BallbarCalibrationWritesAModelFileThatReadsBackTheSame) {
  const std::string data = kim_ballbar_file();
  const std::string json = path("report.json");
  const CalibrationResult r = calibrate_files(model_, data, out_, json, "cpm calibrate (test)");
  const io::ModelFile back = io::load_model_file(out_);
  for (int i = 0; i < 3; ++i) {
    EXPECT_LT((back.model.kinematics.planes[i].normal - r.model.model.kinematics.planes[i].normal).norm(), 1e-15);
    EXPECT_EQ(back.model.kinematics.planes[i].scale, r.model.model.kinematics.planes[i].scale);
    EXPECT_EQ(back.model.kinematics.planes[i].offset, r.model.model.kinematics.planes[i].offset);
  }
  // Nominal and fitted values with standard errors.
  bool found_tz = false, found_scale = false;
  for (const io::FittedParameter& p : back.fitted) {
    if (p.name == "ballbar.theta_z") {
      found_tz = true;
      EXPECT_NEAR(p.value, kim_fitted_errors().theta_z, 3.0 * p.std_error);
      EXPECT_GT(p.std_error, 0.0);
      EXPECT_EQ(p.nominal, 0.0);
    }
    if (p.name == "kinematics.limb2.scale") {
      found_scale = true;
      EXPECT_EQ(p.nominal, 1.0);
      EXPECT_GT(p.std_error, 0.0);
    }
  }
  EXPECT_TRUE(found_tz);
  EXPECT_TRUE(found_scale);
  ASSERT_EQ(back.history.size(), 1u);
  EXPECT_EQ(back.history[0].data_sha256, io::sha256_file(data));
  EXPECT_EQ(back.history[0].data_file, data);
  // The JSON names what the issue asks for, every parameter with a number.
  const auto js = nlohmann::json::parse(read(json));
  EXPECT_EQ(js["kind"], "ballbar");
  EXPECT_EQ(js["residual_rms"].get<double>(), r.residual_rms()) << "the JSON reads back exactly";
  for (const char* name : {"gamma1", "gamma3", "theta_z", "theta_x", "theta_y", "dq_x", "dq_z", "dl"}) {
    ASSERT_TRUE(js["parameters"].contains(name)) << name;
    EXPECT_TRUE(js["parameters"][name]["value"].is_number()) << name;
    EXPECT_TRUE(js["parameters"][name].contains("stderr")) << name;
  }
  for (const auto& [name, p] : js["parameters"].items()) EXPECT_FALSE(p["value"].is_null()) << name;
  EXPECT_TRUE(js["warnings"].is_array());
  EXPECT_TRUE(js["identifiability"]["singular_values"].is_array());
  EXPECT_EQ(js["identifiability"]["correlation"].size(), js["identifiability"]["names"].size());
  // Calibrating again from the calibrated model gives the same planes: the
  // fit starts from the data, not from the input's planes.
  const std::string out2 = path("again.yaml");
  const CalibrationResult r2 = calibrate_files(out_, data, out2, std::nullopt, "test");
  for (int i = 0; i < 3; ++i)
    EXPECT_LT((r2.model.model.kinematics.planes[i].normal - r.model.model.kinematics.planes[i].normal).norm(), 1e-12);
  const io::ModelFile back2 = io::load_model_file(out2);
  EXPECT_EQ(back2.history.size(), 2u);
  int n_tz = 0;
  for (const auto& p : back2.fitted) n_tz += p.name == "ballbar.theta_z";
  EXPECT_EQ(n_tz, 1) << "the earlier calibration's entries are replaced, not duplicated";
}

TEST_F(CalibrationFiles, PositionCalibrationFromAFile) {
  const ctl::MachineModel truth = kim_true_machine();
  std::vector<Vec3> cmd;
  for (double x : {0.30, 0.55})
    for (double y : {0.30, 0.55})
      for (double z : {0.28, 0.48}) cmd.emplace_back(x, y, z);
  cmd.emplace_back(0.42, 0.43, 0.38);
  const io::PositionData pd = simulate_positions(truth, ctl::MachineModel::elkady(), cmd,
                                                 {NoiseShape::gaussian, 2e-6, 9});
  const std::string data = path("position.csv");
  io::write_position(data, pd);
  const std::string json = path("p.json");
  const CalibrationResult r = calibrate_files(model_, data, out_, json, "test");
  EXPECT_EQ(r.kind, "position");
  // Within the reported standard errors (4 sigma: 9 components).
  for (int i = 0; i < 3; ++i)
    for (int k = 0; k < 3; ++k)
      EXPECT_LE(std::abs(r.model.model.kinematics.planes[i].normal[k] - truth.kinematics.planes[i].normal[k]),
                4.0 * r.position->normal_std_error[i][k] + 1e-12)
          << "limb " << i + 1 << " component " << k;
  const auto js = nlohmann::json::parse(read(json));
  EXPECT_EQ(js["kind"], "position");
  for (const char* name : {"c1", "n3", "u1", "u3"}) EXPECT_TRUE(js["parameters"].contains(name)) << name;
  EXPECT_EQ(js["parameters"]["u1"]["value"].size(), 3u);
}

TEST_F(CalibrationFiles, RefusesToOverwriteItsInput) {
  const std::string data = kim_ballbar_file();
  const std::string before = read(model_);
  EXPECT_THROW(calibrate_files(model_, data, model_, std::nullopt, "test"), Error);
  EXPECT_EQ(read(model_), before);
}

TEST_F(CalibrationFiles, MissingColumnIsNamed) {
  const std::string good = read(kim_ballbar_file());
  std::string bad = good;
  const auto h = bad.find("d1,d2,d3,length");
  ASSERT_NE(h, std::string::npos) << good.substr(0, 400);
  bad.replace(h, 15, "d1,d2,d3,len");
  write(path("bad.csv"), bad);
  expect_refused(path("bad.csv"), {"length"});
}

TEST_F(CalibrationFiles, NaNIsRefusedWithItsLineAndColumn) {
  std::string text = read(kim_ballbar_file());
  // Third data row's length becomes nan.
  std::istringstream is(text);
  std::string line, out;
  int data_row = 0, line_no = 0, bad_line = 0;
  bool header = false;
  while (std::getline(is, line)) {
    ++line_no;
    if (!line.empty() && line[0] != '#') {
      if (!header) {
        header = true;
      } else if (++data_row == 3) {
        line = line.substr(0, line.rfind(',')) + ",nan";
        bad_line = line_no;
      }
    }
    out += line + "\n";
  }
  write(path("nan.csv"), out);
  expect_refused(path("nan.csv"), {":" + std::to_string(bad_line), "length"});
}

TEST_F(CalibrationFiles, PoseOutsideTheStrokeIsRefused) {
  io::BallbarData b = io::read_ballbar(kim_ballbar_file());
  b.d[4].z() = 0.35;  // actuator 3's stroke ends at 0.300 m
  io::write_ballbar(path("stroke.csv"), b);
  expect_refused(path("stroke.csv"), {"d3", "stroke", ":" + std::to_string(io::read_ballbar(path("stroke.csv")).info.line_of_row[4])});
}

TEST_F(CalibrationFiles, TooFewRowsAreRefused) {
  io::BallbarData b = io::read_ballbar(kim_ballbar_file());
  b.d.resize(6);
  b.length.resize(6);
  io::write_ballbar(path("few.csv"), b);
  expect_refused(path("few.csv"), {"got 6 rows"});
}

TEST_F(CalibrationFiles, APivotNoPoseCanReachIsRefused) {
  io::BallbarData b = io::read_ballbar(kim_ballbar_file());
  b.pivot = Vec3(1.5, 1.5, 1.5);
  io::write_ballbar(path("pivot.csv"), b);
  expect_refused(path("pivot.csv"), {"no pose reaches the pivot", "pivot"});
}

TEST_F(CalibrationFiles, OneInconsistentRowIsNamed) {
  io::BallbarData b = io::read_ballbar(kim_ballbar_file());
  b.length[7] += 0.02;
  io::write_ballbar(path("row.csv"), b);
  expect_refused(path("row.csv"), {":" + std::to_string(io::read_ballbar(path("row.csv")).info.line_of_row[7]), "bad row"});
}

TEST_F(CalibrationFiles, AMotionLogIsNotACalibrationFile) {
  io::MotionData m;
  m.t = {0.0, 0.001};
  m.d = {Vec3(0.1, 0.1, 0.1), Vec3(0.1, 0.1, 0.1)};
  m.v = m.f = {Vec3::Zero(), Vec3::Zero()};
  io::write_motion(path("motion.csv"), m);
  expect_refused(path("motion.csv"), {"motion log cannot calibrate"});
}
