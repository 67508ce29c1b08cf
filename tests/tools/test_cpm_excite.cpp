// SPDX-License-Identifier: Apache-2.0
// cpm excite as a user meets it (the built program): it writes a stream file
// that cpm stream accepts whole, at rest at both ends; a design that cannot
// fit the limits is refused naming them.
#ifdef CPM_EXE
#include <gtest/gtest.h>

#include <cmath>
#include <sstream>
#include <string>
#include <vector>

#include "tools/cpm_command.hpp"

namespace cpm {
namespace {

struct Temp : test::TempFolder {
  Temp() : test::TempFolder("excite") {}
};

TEST(CpmExcite, WritesAFileCpmStreamAcceptsWithinTheLimitsAtRestAtBothEnds) {
  Temp t;
  const std::string f = (t.dir / "exc.csv").string();
  const test::CpmResult r = test::run_cpm(
      "excite --model config/machine.yaml --out " + f + " --period 2 --periods 2 --harmonics 3 --iterations 10", t);
  ASSERT_EQ(r.status, 0) << r.out << r.err;
  EXPECT_NE(r.out.find("within cpmd's limits"), std::string::npos) << r.out;
  const test::CpmResult s = test::run_cpm("stream " + f + " --model config/machine.yaml --dry-run", t);
  EXPECT_EQ(s.status, 0) << s.out << s.err;
  // No stop appended: the file ends at rest. 2 periods of 2 s and two fades of 1 s at 1 kHz.
  EXPECT_EQ(s.out.find("a stop of"), std::string::npos) << s.out;
  EXPECT_NE(s.out.find("6001 rows, 6.000 s"), std::string::npos) << s.out;
  // The file itself: speed within the default 0.5 m/s at every row, rest at the ends.
  std::istringstream in(test::slurp(f));
  std::string line;
  std::vector<std::vector<double>> rows;
  while (std::getline(in, line)) {
    if (line.empty() || line[0] == '#' || line[0] == 't') continue;
    std::vector<double> v;
    std::istringstream ls(line);
    std::string c;
    while (std::getline(ls, c, ',')) v.push_back(std::stod(c));
    ASSERT_EQ(v.size(), 7u) << line;
    EXPECT_LE(std::sqrt(v[4] * v[4] + v[5] * v[5] + v[6] * v[6]), 0.5) << line;
    rows.push_back(v);
  }
  ASSERT_EQ(rows.size(), 6001u);
  for (int k = 4; k < 7; ++k) {
    EXPECT_EQ(rows.front()[static_cast<std::size_t>(k)], 0.0);
    EXPECT_EQ(rows.back()[static_cast<std::size_t>(k)], 0.0);
  }
}

TEST(CpmExcite, BadOptionsAreRefusedByName) {
  Temp t;
  const std::string f = (t.dir / "exc.csv").string();
  const test::CpmResult r = test::run_cpm("excite --model config/machine.yaml --out " + f + " --periods 1", t);
  EXPECT_NE(r.status, 0);
  EXPECT_NE(r.err.find("--periods"), std::string::npos) << r.err;
  const test::CpmResult s =
      test::run_cpm("excite --model config/machine.yaml --out " + f + " --separate viscous_friction:2", t);
  EXPECT_NE(s.status, 0);
}

}  // namespace
}  // namespace cpm
#endif
