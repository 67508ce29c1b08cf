// SPDX-License-Identifier: Apache-2.0
// LinuxCNC's screw-compensation file (io/linuxcnc_comp.hpp), checked line by
// line against its documented format and against what its loader and motion
// module do with it (usrmotLoadComp: fgets + sscanf("%lf %lf %lf") until the
// first line that is not three numbers; type 0 stores nominal - forward as the
// trim; the motion module adds the trim, linear between entries, held beyond
// them, to the commanded joint position).
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <sstream>

#include "cpm/io/linuxcnc_comp.hpp"
#include "cpm/kinematics/types.hpp"

namespace cpm::io {
namespace {

struct Entry {
  double nominal, fwd_trim, rev_trim;
};

// The loader's reading, written from its documented behaviour.
std::vector<Entry> linuxcnc_load(const std::string& text, int type) {
  std::vector<Entry> out;
  std::istringstream is(text);
  std::string line;
  while (std::getline(is, line)) {
    double nom, fwd, rev;
    if (3 != std::sscanf(line.c_str(), "%lf %lf %lf", &nom, &fwd, &rev)) break;
    if (type == 0) out.push_back({nom, nom - fwd, nom - rev});
    else out.push_back({nom, fwd, rev});
  }
  return out;
}

// The trim at commanded position x: linear between entries, held beyond them.
double linuxcnc_trim(const std::vector<Entry>& c, double x) {
  if (x <= c.front().nominal) return c.front().fwd_trim;
  if (x >= c.back().nominal) return c.back().fwd_trim;
  std::size_t k = 1;
  while (c[k].nominal < x) ++k;
  const double s = (x - c[k - 1].nominal) / (c[k].nominal - c[k - 1].nominal);
  return c[k - 1].fwd_trim + s * (c[k].fwd_trim - c[k - 1].fwd_trim);
}

kin::PitchTable screw() {
  // A pitch error growing along the stroke, 0 to 24 um over 400 mm, slightly curved.
  kin::PitchTable t;
  t.size = 21;
  for (int k = 0; k < t.size; ++k) {
    const double d = 0.02 * k;
    t.node[k] = d;
    t.error[k] = 40e-6 * d + 50e-6 * d * d;
  }
  return t;
}

TEST(LinuxcncComp, EveryLineIsANominalForwardReverseTripletInMillimetres) {
  const kin::PitchTable t = screw();
  for (int type : {0, 1}) {
    const std::string text = render_linuxcnc_comp(t, type, comp_units("mm"));
    const std::vector<Entry> c = linuxcnc_load(text, type);
    ASSERT_EQ(c.size(), static_cast<std::size_t>(t.size)) << "the loader must read every line:\n" << text;
    EXPECT_EQ(std::count(text.begin(), text.end(), '\n'), t.size);  // nothing else in the file
    for (int k = 0; k < t.size; ++k) {
      EXPECT_NEAR(c[k].nominal, t.node[k] * 1e3, 1e-9);
      if (k > 0) {
        EXPECT_GT(c[k].nominal, c[k - 1].nominal);  // the motion module refuses otherwise
      }
      EXPECT_NEAR(c[k].fwd_trim, -t.error[k] * 1e3, 1e-9);     // mm: nominal - actual
      EXPECT_EQ(c[k].fwd_trim, c[k].rev_trim);
    }
  }
  // e(20 mm) = 40e-6 * 0.02 + 50e-6 * 0.02^2 m = 0.82 um: where the axis is, in mm.
  EXPECT_EQ(render_linuxcnc_comp(t, 0, comp_units("mm")).substr(0, 27), "0 0 0\n20 20.00082 20.00082\n");
}

TEST(LinuxcncComp, LinuxcncsCompensationCancelsThePitchError) {
  // Commanded to x, LinuxCNC drives the joint to x + trim(x); the axis is then
  // at (x + trim) + e(x + trim), which must be x again within the second order.
  const kin::PitchTable t = screw();
  const std::vector<Entry> c = linuxcnc_load(render_linuxcnc_comp(t, 0, comp_units("mm")), 0);
  double worst = 0.0, uncompensated = 0.0;
  for (double x = 0.0; x <= 0.4; x += 0.0013) {
    const double cmd = x + linuxcnc_trim(c, x * 1e3) * 1e-3;
    worst = std::max(worst, std::abs(cmd + t(cmd) - x));
    uncompensated = std::max(uncompensated, std::abs(t(x)));
  }
  std::printf("[ figures  ] pitch error up to %.2f um; after LinuxCNC's compensation %.4f um\n", uncompensated * 1e6,
              worst * 1e6);
  EXPECT_GT(uncompensated, 20e-6);
  EXPECT_LT(worst, 0.01e-6);
}

TEST(LinuxcncComp, ImportInvertsExportInBothTypesAndUnits) {
  const kin::PitchTable t = screw();
  for (const char* units : {"mm", "inch"})
    for (int type : {0, 1}) {
      const CompUnits u = comp_units(units);
      const ImportedComp back = parse_linuxcnc_comp(render_linuxcnc_comp(t, type, u), "f.comp", type, u);
      ASSERT_EQ(back.table.size, t.size);
      for (int k = 0; k < t.size; ++k) {
        EXPECT_NEAR(back.table.node[k], t.node[k], 1e-11) << units << " type " << type;
        EXPECT_NEAR(back.table.error[k], t.error[k], 1e-11) << units << " type " << type;
      }
      EXPECT_TRUE(back.notes.empty());
    }
}

TEST(LinuxcncComp, ImportKeepsTheMeanOfADirectionDependentFileAndSaysSo) {
  const ImportedComp c = parse_linuxcnc_comp("0 0.001 -0.001\n100 100.003 99.999\n", "b.comp", 0, comp_units("mm"));
  EXPECT_NEAR(c.table.error[1], 1e-6, 1e-15);
  EXPECT_NEAR(c.max_direction_difference, 4e-6, 1e-15);
  ASSERT_EQ(c.notes.size(), 1u);
  EXPECT_NE(c.notes[0].find("backlash"), std::string::npos);
}

TEST(LinuxcncComp, ImportRefusesWhatLinuxcncWouldReadDifferently) {
  auto refusal = [](const std::string& text) {
    try {
      (void)parse_linuxcnc_comp(text, "x.comp", 0, comp_units("mm"));
    } catch (const Error& e) {
      return std::string(e.what());
    }
    return std::string();
  };
  EXPECT_EQ(refusal("# pitch\n0 0 0\n100 100 100\n"),
            "x.comp:1: expected three numbers 'nominal forward reverse' (LinuxCNC's loader stops here)");
  EXPECT_EQ(refusal("0 0 0\n100 100 100\n50 50 50\n"),
            "x.comp:3: nominal positions must increase (LinuxCNC refuses the entry)");
  EXPECT_EQ(refusal("0 0 0\n\n100 100 100\n"), "x.comp:3: a line after a blank one: LinuxCNC's loader stops at the blank line");
  std::string many;
  for (int k = 0; k <= 256; ++k) many += std::to_string(k) + " " + std::to_string(k) + " " + std::to_string(k) + "\n";
  EXPECT_EQ(refusal(many), "x.comp:257: more than 256 lines (LinuxCNC keeps no more)");
}

}  // namespace
}  // namespace cpm::io
