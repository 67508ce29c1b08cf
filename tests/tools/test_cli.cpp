// SPDX-License-Identifier: Apache-2.0
// The frame of the cpm command line (tools/cpm/cli.hpp): where the default
// model is looked for, in order, in a temporary folder layout; the JSON text
// (shortest round-trip numbers, null for non-finite ones, escaping); the
// effect names and the message for an unknown one; and what the completion
// offers after each kind of word.
#include <gtest/gtest.h>
#include <unistd.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include "cli.hpp"
#include "cpm/control/effects.hpp"
#include "cpm/kinematics/kinematic_effects.hpp"

namespace cpm::cli {
namespace {

namespace fs = std::filesystem;

struct TempDir {
  fs::path path = fs::temp_directory_path() / ("cpm-cli-" + std::to_string(getpid()));
  TempDir() { fs::create_directories(path); }
  ~TempDir() { fs::remove_all(path); }
  fs::path touch(const fs::path& rel) const {
    fs::create_directories((path / rel).parent_path());
    std::ofstream(path / rel) << "cpmd_model: 1\n";
    return fs::weakly_canonical(path / rel);
  }
};

TEST(DefaultModel, LookedForInOrder) {
  TempDir t;
  const fs::path cwd = t.path / "work", tree_exe = t.path / "src/build/bin/cpm", prefix_exe = t.path / "opt/bin/cpm";
  const fs::path system_file = t.path / "etc/cpmd/machine.yaml";
  fs::create_directories(cwd);
  t.touch("src/build/bin/cpm");  // the programs: ".." from their folders needs the folders
  t.touch("opt/bin/cpm");
  // None anywhere: the published relative path, so that the error names it.
  EXPECT_EQ(find_default_model(cwd, tree_exe, system_file), "config/machine.yaml");
  // The system-wide file, whatever the program's path.
  t.touch("etc/cpmd/machine.yaml");
  EXPECT_EQ(find_default_model(cwd, tree_exe, system_file), system_file.string());
  EXPECT_EQ(find_default_model(cwd, "", system_file), system_file.string());
  // Beside the install prefix of the program, before the system-wide file.
  const fs::path beside_prefix = t.touch("opt/etc/cpmd/machine.yaml");
  EXPECT_EQ(find_default_model(cwd, prefix_exe, system_file), beside_prefix.string());
  EXPECT_EQ(find_default_model(cwd, tree_exe, system_file), system_file.string());
  // The build tree's source folder (build/bin/cpm -> config/machine.yaml).
  const fs::path in_tree = t.touch("src/config/machine.yaml");
  EXPECT_EQ(find_default_model(cwd, tree_exe, system_file), in_tree.string());
  // The current folder first of all.
  t.touch("work/config/machine.yaml");
  EXPECT_EQ(find_default_model(cwd, tree_exe, system_file), "config/machine.yaml");
}

TEST(Json, NumbersAreShortestRoundTrip) {
  EXPECT_EQ(json_text(Json(0.6), -1), "0.6");
  EXPECT_EQ(json_text(Json(0.0027), -1), "0.0027");
  EXPECT_EQ(json_text(Json(0.1 + 0.2), -1), "0.30000000000000004");  // the double that is not 0.3
  EXPECT_EQ(std::stod(json_text(Json(1.0 / 3.0), -1)), 1.0 / 3.0);
  EXPECT_EQ(json_text(Json(1e-300), -1), "1e-300");
}

TEST(Json, NonFiniteNumbersAreNull) {
  const Json j{{"rms", std::nan("")}, {"max", INFINITY}, {"list", {1.5, -INFINITY}}};
  EXPECT_EQ(json_text(j, -1), R"({"rms":null,"max":null,"list":[1.5,null]})");
}

TEST(Json, KeysKeepTheirOrderAndStringsAreEscaped) {
  const Json j{{"z", 1}, {"a", "say \"hi\"\\\n\t"}, {"bytes", std::string("\xff ok")}};
  EXPECT_EQ(json_text(j, -1), "{\"z\":1,\"a\":\"say \\\"hi\\\"\\\\\\n\\t\",\"bytes\":\"\xef\xbf\xbd ok\"}");
  EXPECT_EQ(Json::parse(json_text(j, 2))["a"], "say \"hi\"\\\n\t");
}

TEST(Effects, NamesComeFromBothLibraryTables) {
  const auto names = effect_names();
  ASSERT_EQ(names.size(), static_cast<std::size_t>(ctl::kDynamicEffectTypes + kin::kKinematicEffectTypes));
  EXPECT_EQ(names.front(), ctl::info(static_cast<ctl::DynamicEffectType>(0)).name);
  EXPECT_EQ(names.back(), kin::info(static_cast<kin::KinematicEffectType>(kin::kKinematicEffectTypes - 1)).name);
}

TEST(Effects, AnUnknownNameListsTheValidOnes) {
  std::string spec = "coulomb_friction:2";
  EXPECT_EQ(effect_name()(spec), "");
  spec = "backlash";
  EXPECT_EQ(effect_name()(spec), "");
  spec = "gremlins:1:3";
  const std::string why = effect_name()(spec);
  EXPECT_NE(why.find("unknown effect 'gremlins'"), std::string::npos) << why;
  for (const auto& n : effect_names()) EXPECT_NE(why.find(n), std::string::npos) << n << " missing from: " << why;
}

// A command line like cpm's: one subcommand with an effect option, a file
// option, a choice, a flag and a positional.
class Completion : public ::testing::Test {
 protected:
  void SetUp() override {
    CLI::App* fit = app.add_subcommand("fit", "fit")->group("Commands");
    fit->add_option("--add", adds)->type_name("EFFECT[:AXIS]")->allow_extra_args(false);
    fit->add_option("--data", data)->type_name("FILE.csv");
    add_choice(*fit, "--plane", plane, {"xy", "yz", "zx"}, "plane");
    fit->add_flag("--quiet", quiet);
    fit->add_option("ACTION", action)->type_name("check|show");
    app.add_subcommand("sim", "sim")->group("Commands");
    app.add_subcommand("__hidden", "")->group("");
  }
  std::vector<std::string> complete_(const std::vector<std::string>& words) const { return complete(app, words); }
  static bool has(const std::vector<std::string>& v, const std::string& s) {
    return std::find(v.begin(), v.end(), s) != v.end();
  }
  CLI::App app{"test", "cpm"};
  std::vector<std::string> adds;
  std::string data, plane = "xy", action;
  bool quiet = false;
};

TEST_F(Completion, SubcommandsButNotHiddenOnes) {
  EXPECT_EQ(complete_({""}), (std::vector<std::string>{"fit", "sim"}));
}

TEST_F(Completion, OptionsOfTheSubcommand) {
  const auto c = complete_({"fit", "--"});
  for (const char* o : {"--add", "--data", "--plane", "--quiet", "--help"}) EXPECT_TRUE(has(c, o)) << o;
}

TEST_F(Completion, ValuesByTheirKind) {
  EXPECT_EQ(complete_({"fit", "--add", "cou"}), effect_names());
  EXPECT_EQ(complete_({"fit", "--data", ""}), std::vector<std::string>{"__files__"});
  EXPECT_EQ(complete_({"fit", "--plane", ""}), (std::vector<std::string>{"xy", "yz", "zx"}));
  EXPECT_TRUE(has(complete_({"fit", "--plane=y"}), "--plane=yz"));
  // After a flag or an option's value comes the positional.
  EXPECT_EQ(complete_({"fit", "--quiet", ""}), (std::vector<std::string>{"check", "show"}));
  EXPECT_EQ(complete_({"fit", "--data", "x.csv", "s"}), (std::vector<std::string>{"check", "show"}));
  // A second positional the command does not have: nothing.
  EXPECT_TRUE(complete_({"fit", "check", ""}).empty());
  EXPECT_TRUE(complete_({"nosuch", ""}).empty());
}

}  // namespace
}  // namespace cpm::cli
