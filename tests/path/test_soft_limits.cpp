// SPDX-License-Identifier: Apache-2.0
// A point past cpmd's soft limits is refused with its figures: the point and
// the limit in the program's coordinates (z up from program zero) and the
// machine's, as a stroke refusal gives its figures; cpmd, which has no
// program frame, gives the machine's.
#include <gtest/gtest.h>

#include "cpm/path/gcode.hpp"
#include "cpm/path/program.hpp"
#include "path_fixtures.hpp"

namespace cpm::path {
namespace {

SoftLimits box() { return SoftLimits{Vec3(0.235, 0.235, 0.2378), Vec3(0.615, 0.615, 0.5168)}; }

TEST(SoftLimits, RefusalGivesTheFiguresInTheProgramsCoordinatesAndTheMachines) {
  const ProgramFrame frame;  // program zero at (425, 425, 300) mm, Z up
  EXPECT_EQ(soft_limit_text(frame.to_machine(Vec3(0.1, 0.0, 0.0)), box(), &frame), "");
  EXPECT_EQ(soft_limit_text(frame.to_machine(Vec3(0.195, 0.0, 0.0)), box(), &frame),
            "outside the soft limits on X: X = 195.000 mm, above the limit X 190.000 mm (machine x 615.000 mm)");
  // Z up: the machine's lowest z (237.8 mm, its top) is the program's highest Z.
  EXPECT_EQ(soft_limit_text(frame.to_machine(Vec3(0.0, 0.0, 0.070)), box(), &frame),
            "outside the soft limits on Z: Z = 70.000 mm, above the limit Z 62.200 mm (machine z 237.800 mm)");
  EXPECT_EQ(soft_limit_text(Vec3(0.425, 0.230, 0.3), box()),
            "outside the soft limits on y: y = 230.000 mm, below the limit 235.000 mm");
  EXPECT_EQ(soft_limit_text(Vec3(0.425, 0.2349999999, 0.3), box(), nullptr, 1e-9), "");
}

TEST(SoftLimits, AProgramPastThemIsRefusedWithItsLineAndTheFigures) {
  const ctl::Machine& m = test::elkady();
  ProgramOptions o;
  o.name = "p.ngc";
  o.soft = box();
  o.planner = planner_options(MachineLimits{}, m);
  try {
    (void)prepare_program("G21 G90 F3000\nG1 X10\nG1 Z70\nM2\n", m, o);
    FAIL() << "not refused";
  } catch (const ProgramError& e) {
    const std::string w = e.what();
    EXPECT_NE(w.find("p.ngc:3:"), std::string::npos) << w;
    EXPECT_NE(w.find("above the limit Z 62.200 mm (machine z 237.800 mm)"), std::string::npos) << w;
  }
}

}  // namespace
}  // namespace cpm::path
