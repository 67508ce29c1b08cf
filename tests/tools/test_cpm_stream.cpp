// SPDX-License-Identifier: Apache-2.0
// cpm stream as a user meets it (the built program, in its own process):
// the whole file is checked against cpmd's limits before anything is sent.
// The files are generated here from closed forms (a multi-sine and its
// derivative), apart from the checker: the row where the speed first goes
// over the limit is known before cpm reads the file.
#ifdef CPM_EXE
#include <gtest/gtest.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include "tools/stream_files.hpp"

#include "tools/cpm_command.hpp"

namespace cpm {
namespace {

namespace fs = std::filesystem;
using test::kStep;
using test::MultiSine;

using Result = test::CpmResult;
using test::slurp;

struct Temp : test::TempFolder {
  Temp() : test::TempFolder("stream") {}
};

Result cpm(const std::string& args, const Temp& t) { return test::run_cpm(args, t); }

const char* kModel = "config/machine.yaml";
constexpr int kRows = 30001;  // 30 s
constexpr double kLimit = 0.5;        // m/s, the default limits.velocity
constexpr double kAccelLimit = 5.0;   // m/s^2, the default limits.acceleration
TEST(CpmStream, AFileOverTheSpeedLimitAtRow9802IsRefusedBeforeAnythingIsSent) {
  Temp t;
  const MultiSine m = test::over_at(9802, kLimit);
  ASSERT_GT(m.k, 0) << "no phase puts a speed record at row 9802";
  // The test's own premises: under the limits up to that row, over it there.
  double amax = 0;
  for (int r = 0; r < 9801; ++r) {
    double p[3], v[3], acc[3];
    m.at(r * kStep, p, v, acc);
    amax = std::max(amax, std::sqrt(acc[0] * acc[0] + acc[1] * acc[1] + acc[2] * acc[2]));
    ASSERT_LE(m.speed(r), kLimit) << r;
  }
  ASSERT_LT(amax, kAccelLimit);
  ASSERT_GT(m.speed(9801), kLimit);
  const fs::path f = t.dir / "multisine.csv";
  m.write(f, kRows);
  // --dry-run, and a real run with the daemon's config (whose limits are the
  // defaults' speed and acceleration): refused before cpmd is even reached
  // (there is none here), naming the row, the figure and the limit.
  for (const std::string mode : {"--dry-run", "--config config/sim.yaml"}) {
    SCOPED_TRACE(mode);
    const Result r = cpm("stream " + f.string() + " --model " + kModel + " " + mode, t);
    EXPECT_EQ(r.status, 1) << r.out << r.err;
    EXPECT_NE(r.err.find("row 9802 (line 9803), the stretch from t = 9.8010 s to 9.8020 s"), std::string::npos) << r.err;
    EXPECT_NE(r.err.find("speed 0.50025"), std::string::npos) << r.err;
    EXPECT_NE(r.err.find("exceeds the limit 0.5 m/s"), std::string::npos) << r.err;
    EXPECT_NE(r.err.find("nothing sent"), std::string::npos) << r.err;
    EXPECT_EQ(r.out.find("setpoints sent"), std::string::npos) << r.out;
    EXPECT_EQ(r.out.find("approach"), std::string::npos) << r.out;
  }
  // The same file cut before that row passes.
  m.write(f, 9801);
  const Result ok = cpm("stream " + f.string() + " --model " + kModel + " --dry-run", t);
  EXPECT_EQ(ok.status, 0) << ok.err;
}

TEST(CpmStream, AFileEndingAtSpeedGetsAStopAppendedAndChecked) {
  Temp t;
  MultiSine m;
  m.k = 0.5;  // well within the limits
  const fs::path f = t.dir / "at_speed.csv";
  m.write(f, 4001);
  const double v_end = m.speed(4000);
  ASSERT_GT(v_end, 0.02);
  const Result r = cpm("stream " + f.string() + " --model " + kModel + " --dry-run", t);
  ASSERT_EQ(r.status, 0) << r.err;
  char want[64];
  std::snprintf(want, sizeof want, "ends at %.1f mm/s", v_end * 1e3);
  EXPECT_NE(r.out.find(want), std::string::npos) << r.out;
  // Half the acceleration limit from v_end to rest: T = v / 2.5 m/s^2, on the file's step.
  const double T = std::max(2.0, std::ceil(v_end / (0.5 * kAccelLimit) / kStep)) * kStep;
  std::snprintf(want, sizeof want, "a stop of %.3f s", T);
  EXPECT_NE(r.out.find(want), std::string::npos) << r.out;

  // A file that ends at speed toward the soft limit, too close to stop
  // within it: refused, naming the stop.
  std::ofstream(f) << "t,x,y,z,vx,vy,vz\n0,0.57,0.425,0.3,0,0,0\n0.1,0.59,0.425,0.3,0.4,0,0\n";
  const Result near = cpm("stream " + f.string() + " --model " + kModel + " --dry-run", t);
  EXPECT_EQ(near.status, 1) << near.out;
  EXPECT_NE(near.err.find("the stop appended after the last row"), std::string::npos) << near.err;
}

}  // namespace
}  // namespace cpm
#endif
