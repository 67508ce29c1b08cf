// SPDX-License-Identifier: Apache-2.0
// cpm run as a user meets it (the built program, in its own process):
// --dry-run's figures are the planner's own (path::prepare_program on the
// same text, model and options), and a bad program is refused with its
// line and column before cpm even opens LCM, so nothing is sent.
#ifdef CPM_EXE
#include <gtest/gtest.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <regex>
#include <sstream>
#include <string>

#include "cpm/io/model_file.hpp"
#include "cpm/path/program.hpp"
#include "cpm/path/test_paths.hpp"

#include "tools/cpm_command.hpp"

namespace cpm {
namespace {

namespace fs = std::filesystem;

using Result = test::CpmResult;
using test::slurp;

struct Temp : test::TempFolder {
  Temp() : test::TempFolder("run") {}
};

Result cpm(const std::string& args, const Temp& t) { return test::run_cpm(args, t); }

const char* kModel = "config/machine.yaml";  // the tests run in the source folder

TEST(CpmRun, DryRunFiguresAreThePlannersOwn) {
  Temp t;
  const ctl::Machine machine(io::load_model_file(kModel).model);
  std::vector<fs::path> programs;
  for (const auto& e : fs::directory_iterator(CPM_PATH_PROGRAMS))
    if (e.path().extension() == ".ngc") programs.push_back(e.path());
  std::ofstream(t.dir / "sdc.ngc") << path::square_diamond_circle(250.0, 12000.0);
  programs.push_back(t.dir / "sdc.ngc");
  ASSERT_GE(programs.size(), 8u);
  for (const fs::path& prog : programs) {
    SCOPED_TRACE(prog.string());
    const Result r = cpm("run " + prog.string() + " --dry-run --model " + kModel + " --json " +
                             (t.dir / "plan.json").string(), t);
    ASSERT_EQ(r.status, 0) << r.err;
    // The same text, model and options (cpm's defaults: program zero at the
    // middle of the workspace, 0.05 mm, the default limits) through cpm_path.
    path::ProgramOptions o;
    o.name = prog.string();
    o.planner = path::planner_options(path::MachineLimits{}, machine);
    const path::PreparedProgram p = path::prepare_program(slurp(prog), machine, o);
    const path::PlanSummary& s = p.plan->summary();
    const auto j = nlohmann::json::parse(slurp(t.dir / "plan.json"));
    EXPECT_EQ(j["segments"].get<std::size_t>(), p.queue.segments().size());
    EXPECT_EQ(j["moves"].get<std::size_t>(), p.program.moves.size());
    EXPECT_EQ(j["duration_s"].get<double>(), s.duration);
    EXPECT_EQ(j["length_m"].get<double>(), s.length);
    EXPECT_EQ(j["peak_speed_m_s"].get<double>(), s.peak_speed);
    for (int i = 0; i < 3; ++i) {
      EXPECT_EQ(j["peak_actuator_speed_m_s"][i].get<double>(), s.peak_actuator_speed[i]);
      EXPECT_EQ(j["peak_actuator_acceleration_m_s2"][i].get<double>(), s.peak_actuator_acceleration[i]);
      EXPECT_EQ(j["peak_actuator_force_n"][i].get<double>(), s.peak_actuator_force[i]);
    }
    EXPECT_TRUE(j["actuators_within_limits"].get<bool>());
    ASSERT_EQ(j["limited"].size(), s.limited.size());
    for (std::size_t k = 0; k < s.limited.size(); ++k) {
      EXPECT_EQ(j["limited"][k]["line"].get<int>(), path::line_of(*p.plan, s.limited[k].segment));
      EXPECT_EQ(j["limited"][k]["by"].get<std::string>(), path::limit_name(s.limited[k].by));
      EXPECT_EQ(j["limited"][k]["slowest_m_s"].get<double>(), s.limited[k].speed);
    }
    // The screen says the same, in mm and s.
    char line[64];
    std::snprintf(line, sizeof line, "planned time %.3f s, length %.1f mm", s.duration, s.length * 1e3);
    EXPECT_NE(r.out.find(line), std::string::npos) << r.out;
    std::snprintf(line, sizeof line, "%-18s %10.1f %10.1f %10.1f", "peak force", s.peak_actuator_force.x(),
                  s.peak_actuator_force.y(), s.peak_actuator_force.z());
    EXPECT_NE(r.out.find(line), std::string::npos) << r.out;
  }
}

TEST(CpmRun, BadProgramsAreRefusedWithLineAndColumnBeforeAnythingIsSent) {
  Temp t;
  // A URL no LCM can open: had cpm made its client, it would say so.
  const std::string url = " --url bogus://nowhere --model " + std::string(kModel);
  const Result good = cpm(std::string("run ") + CPM_PATH_PROGRAMS + "/arcs_xy.ngc" + url, t);
  EXPECT_NE(good.status, 0);
  EXPECT_NE(good.err.find("lcm"), std::string::npos) << good.err;
  struct Bad {
    const char* file;
    const char* where;
  };
  for (const Bad& b : {Bad{"unknown_word.ngc", ":4:11: "}, Bad{"inconsistent_radius.ngc", ":5:13: "},
                       Bad{"outside_workspace.ngc", ":5:4: "}, Bad{"zero_feed.ngc", ":5:1: "}}) {
    const std::string file = std::string(CPM_PATH_PROGRAMS) + "/bad/" + b.file;
    const Result r = cpm("run " + file + url, t);
    EXPECT_EQ(r.status, 1) << b.file << r.err;
    EXPECT_NE(r.err.find(file + b.where), std::string::npos) << r.err;
    EXPECT_NE(r.err.find("nothing sent"), std::string::npos) << r.err;
    EXPECT_EQ(r.err.find("lcm"), std::string::npos) << r.err;
    EXPECT_EQ(r.out, "");
  }
}

// Without --config the dry run checks cpmd's soft limits from the shipped
// config (config/cpmd.yaml: the tests run in the source folder), and says
// so; a program inside the strokes but past a soft limit is refused with the
// figures in the program's coordinates and the machine's.
TEST(CpmRun, DryRunChecksCpmdsSoftLimitsAndGivesTheFigures) {
  Temp t;
  std::ofstream(t.dir / "past_soft.ngc") << "G21 G90 G17 F3000\nG1 X10 Y10\nG1 X195 Y10\nM2\n";
  const Result r = cpm("run " + (t.dir / "past_soft.ngc").string() + " --dry-run", t);
  EXPECT_EQ(r.status, 1) << r.out << r.err;
  EXPECT_NE(r.err.find("past_soft.ngc:3:"), std::string::npos) << r.err;
  EXPECT_TRUE(std::regex_search(r.err, std::regex("outside the soft limits on X: X = 19[0-5]\\.[0-9]{3} mm, above the "
                                                  "limit X 190\\.000 mm \\(machine x 615\\.000 mm\\)")))
      << r.err;
  const Result ok = cpm(std::string("run ") + CPM_PATH_PROGRAMS + "/arcs_xy.ngc --dry-run", t);
  ASSERT_EQ(ok.status, 0) << ok.err;
  EXPECT_NE(ok.out.find("soft limits (cpmd's, config/cpmd.yaml; machine frame): x 235.0..615.0, y 235.0..615.0, z "
                        "237.8..516.8 mm"),
            std::string::npos)
      << ok.out;
}

// The "held by feed" table lists no stretch shorter than 1 mm but the stops;
// the short ones (a corner's blend a few % under the feed) are counted.
TEST(CpmRun, DryRunListsNoSubMillimetreStretches) {
  Temp t;
  int shorter = 0;
  for (const char* prog : {"incremental.ngc", "inch.ngc", "arcs_xy.ngc"}) {
    SCOPED_TRACE(prog);
    const Result r = cpm(std::string("run ") + CPM_PATH_PROGRAMS + "/" + prog + " --dry-run --json " +
                             (t.dir / "plan.json").string(), t);
    ASSERT_EQ(r.status, 0) << r.err;
    const auto j = nlohmann::json::parse(slurp(t.dir / "plan.json"));
    for (const auto& l : j["limited"])
      if (l["by"] != "stop") {
        EXPECT_GE(l["to_m"].get<double>() - l["from_m"].get<double>(), 1e-3) << l.dump();
      }
    shorter += j["short_limited"].get<int>();
    if (j["short_limited"].get<int>() > 0) {
      EXPECT_NE(r.out.find("shorter than 1 mm, not listed"), std::string::npos) << r.out;
    }
  }
  EXPECT_GT(shorter, 0);  // these programs had them (0.0-0.2 mm stretches at each corner)
}

}  // namespace
}  // namespace cpm
#endif
