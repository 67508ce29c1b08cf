// SPDX-License-Identifier: Apache-2.0
// cpm compare and diagnose with --validate as a user runs them (the built
// cpm, logs made by cpm sim): a log with nothing missing and one with 2 N of
// Coulomb friction on axis 2 the model lacks. compare: the fit per axis and
// the residual's autocorrelation inside its 99 % band without the effect,
// outside with it; diagnose --validate: the effect found on one log, judged
// on the other, leaves a white residual there.
#ifdef CPM_EXE
#include <gtest/gtest.h>

#include <regex>
#include <string>

#include "tools/cpm_command.hpp"

namespace cpm {
namespace {

struct Temp : test::TempFolder {
  Temp() : test::TempFolder("compare") {}
};

// "axis N: autocorrelation outside the band at K of 20 lags" in `text` from `from` on.
int outside(const std::string& text, std::size_t from, int axis) {
  std::smatch m;
  const std::string rest = text.substr(from);
  const std::regex re("axis " + std::to_string(axis) + ": autocorrelation outside the band at ([0-9]+) of 20 lags");
  if (!std::regex_search(rest, m, re)) return -1;
  return std::stoi(m[1]);
}

TEST(CpmCompare, ValidateShowsTheFitAndTheResidualCorrelationOfBothLogs) {
  Temp t;
  const std::string sim = "sim --trajectory circle --time 20 --radius 0.1 --encoder-noise 1e-6 --velocity-noise 2e-4 ";
  const std::string clean = (t.dir / "clean.csv").string(), fric = (t.dir / "fric.csv").string(),
                    fric2 = (t.dir / "fric2.csv").string();
  ASSERT_EQ(test::run_cpm(sim + "--seed 3 --log " + clean, t).status, 0);
  ASSERT_EQ(test::run_cpm(sim + "--seed 4 --truth-effect coulomb_friction:2:2.0 --log " + fric, t).status, 0);
  ASSERT_EQ(test::run_cpm(sim + "--seed 5 --truth-effect coulomb_friction:2:2.0 --log " + fric2, t).status, 0);

  const auto r = test::run_cpm("compare --data " + clean + " --validate " + fric + " --report " +
                                   (t.dir / "c.html").string(), t);
  ASSERT_EQ(r.status, 0) << r.err;
  const std::size_t val = r.out.find("validation: ");
  ASSERT_NE(val, std::string::npos) << r.out;
  std::printf("%s", r.out.substr(r.out.find("residual correlation")).c_str());
  for (int axis = 1; axis <= 3; ++axis) {
    EXPECT_LE(outside(r.out, 0, axis), 1) << axis << r.out;  // nothing missing: inside the band
    if (axis != 2) {
      EXPECT_LE(outside(r.out, val, axis), 1) << axis << r.out;
    }
  }
  EXPECT_GE(outside(r.out, val, 2), 15) << r.out;  // the friction the model lacks
  EXPECT_NE(r.out.find("the residual is not white", val), std::string::npos);
  EXPECT_NE(r.out.find("within half a sample period"), std::string::npos) << r.out;  // the alignment, explained
  std::smatch m;
  ASSERT_TRUE(std::regex_search(r.out, m, std::regex("fit \\(%\\): on [^ ]+ ([0-9.]+), ([0-9.]+), ([0-9.]+); on [^ ]+ "
                                                     "\\(validation\\) ([0-9.]+), ([0-9.]+), ([0-9.]+)")))
      << r.out;
  EXPECT_GT(std::stod(m[2]), 80.0);
  EXPECT_LT(std::stod(m[5]), 40.0);
  const std::string html = test::slurp(t.dir / "c.html");
  EXPECT_NE(html.find("Measured against model"), std::string::npos);
  EXPECT_NE(html.find("Residual correlation"), std::string::npos);

  const auto d = test::run_cpm("diagnose --data " + fric + " --validate " + fric2, t);
  ASSERT_EQ(d.status, 0) << d.err;
  const std::size_t dv = d.out.find("validation on ");
  ASSERT_NE(dv, std::string::npos) << d.out;
  std::printf("%s", d.out.substr(dv).c_str());
  for (int axis = 1; axis <= 3; ++axis) EXPECT_LE(outside(d.out, dv, axis), 1) << axis << d.out;
}

}  // namespace
}  // namespace cpm
#endif
