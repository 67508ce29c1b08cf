// SPDX-License-Identifier: Apache-2.0
// The G-code reader: what it accepts, and every fault refused with its line
// and column before anything moves.
#include <gtest/gtest.h>

#include "cpm/path/gcode.hpp"
#include "path_fixtures.hpp"

namespace cpm::path::test {
namespace {

// The faults a program is refused with.
std::vector<Diagnostic> faults(std::string_view text) {
  try {
    (void)read_program(text);
  } catch (const ProgramError& e) {
    return e.diagnostics();
  }
  return {};
}

void expect_fault(std::string_view text, int line, int column, const std::string& words) {
  const std::vector<Diagnostic> d = faults(text);
  ASSERT_EQ(d.size(), 1u) << text;
  EXPECT_EQ(d[0].line, line) << text;
  EXPECT_EQ(d[0].column, column) << text;
  EXPECT_NE(d[0].message.find(words), std::string::npos) << d[0].message;
}

TEST(Gcode, ReadsMovesInSi) {
  const Program p = read_program("G21 G90 F600\nG0 X10 Y-5 Z2\nG1 X20\nG2 X30 Y5 I0 J10\nG4 P0.25\nM2\nG1 X99\n");
  ASSERT_EQ(p.moves.size(), 4u);
  EXPECT_TRUE(p.ended);
  EXPECT_EQ(p.moves[0].kind, MoveKind::traverse);
  EXPECT_LT((p.moves[0].end - Vec3(0.010, -0.005, 0.002)).norm(), 1e-15);
  EXPECT_EQ(p.moves[1].kind, MoveKind::feed);
  EXPECT_DOUBLE_EQ(p.moves[1].feed, 0.6 / 60);  // 600 mm/min
  EXPECT_EQ(p.moves[2].kind, MoveKind::arc);
  EXPECT_LT((p.moves[2].centre - Vec3(0.020, 0.005, 0.002)).norm(), 1e-15);
  EXPECT_EQ(p.moves[2].turn, -1);
  EXPECT_EQ(p.moves[3].kind, MoveKind::dwell);
  EXPECT_DOUBLE_EQ(p.moves[3].dwell, 0.25);
  EXPECT_EQ(p.moves[2].line, 4);
  EXPECT_EQ(p.moves[2].column, 4);  // its first axis word
}

TEST(Gcode, InchesAndTheOrderOfExecution) {
  const Program p = read_program("G20 G1 X1 F10\nF10\nG1 X2\n");
  // The block's F is read before its G20: 10 mm/min, as LinuxCNC has it.
  EXPECT_DOUBLE_EQ(p.moves[0].feed, 0.010 / 60);
  EXPECT_DOUBLE_EQ(p.moves[0].end.x(), 0.0254);
  EXPECT_DOUBLE_EQ(p.moves[1].feed, 10 * 0.0254 / 60);
}

TEST(Gcode, PathToleranceFromG64AndG61) {
  EXPECT_DOUBLE_EQ(read_program("G21 G64 P0.05\n").tolerance, 0.05e-3);
  EXPECT_DOUBLE_EQ(read_program("G61\n").tolerance, 0.0);
  EXPECT_LT(read_program("G21\n").tolerance, 0.0);
}

TEST(Gcode, UnknownWordsWithLineAndColumn) {
  expect_fault("G21 F100\nG1 X10 Q5\n", 2, 8, "unknown word Q");
  expect_fault("G21 F100\nG1 X10\nS1000\n", 3, 1, "no spindle");
  expect_fault("G21\n  G41 X1\n", 2, 3, "G41 is not supported");
  expect_fault("G21 F100\nG1 X#1\n", 2, 5, "parameters");
  expect_fault("(a comment\n", 1, 1, "not closed");
  expect_fault("G1 G0 X1\n", 1, 4, "modal group");
  expect_fault("G0 X1 X2\n", 1, 7, "twice");
  expect_fault("X1\n", 1, 1, "without a motion");
  expect_fault("G21 F100\nG17 G2 X10 K5 I5\n", 2, 12, "K is not a centre word");
}

TEST(Gcode, ArcsWhoseRadiusChangesAreRefused) {
  expect_fault("G21 F100\nG0 X0 Y0\nG2 X20.05 Y0 I10 J0\n", 3, 14, "differs from radius to its start");
  expect_fault("G21 F100\nG0 X0 Y0\nG2 X20 Y0 R5\n", 3, 11, "too small to reach");
  EXPECT_TRUE(faults("G21 F100\nG0 X0 Y0\nG2 X20.02 Y0 I10 J0\n").empty()) << "within LinuxCNC's tolerance";
}

TEST(Gcode, ZeroOrMissingFeedIsRefused) {
  expect_fault("G21\nG1 X10\n", 2, 1, "no feed");
  expect_fault("G21 F0\nG1 X10\n", 2, 1, "feed is zero");
  expect_fault("G21\nG2 X10 I5 F0\n", 2, 11, "feed is zero");
  expect_fault("G21 F100\nG94\nG1 X10\n", 3, 1, "feed is zero");  // G94 clears it
  EXPECT_TRUE(faults("G21\nG0 X10\n").empty()) << "rapids need no feed";
}

TEST(Gcode, EveryFaultOfTheProgramAtOnce) {
  const std::vector<Diagnostic> d = faults("G21\nG1 X10\nG1 X20 Q1\nG2 X35 Y0 I10 J0 F100\nG7 X1\n");
  ASSERT_EQ(d.size(), 4u);
  EXPECT_EQ(d[0].line, 2);
  EXPECT_EQ(d[1].line, 3);
  EXPECT_EQ(d[2].line, 4);
  EXPECT_EQ(d[3].line, 5);
  try {
    ReaderOptions o;
    o.name = "part.ngc";
    (void)read_program("G21\nG1 X10\n", o);
    FAIL();
  } catch (const ProgramError& e) {
    EXPECT_STREQ(e.what(), "part.ngc:2:1: no feed: set F before the first G1, G2 or G3");
  }
}

TEST(Gcode, PercentDelimitsTheProgram) {
  EXPECT_EQ(read_program("%\nG21 G0 X1\n%\nG0 X2\n").moves.size(), 1u);
  expect_fault("G0 X1\n%\n", 2, 1, "'%'");
  expect_fault("%\nG0 X1\n", 1, 1, "opens with '%'");
}

TEST(Gcode, PointsOutsideTheWorkspaceAreRefusedBeforeMotion) {
  const Program ok = read_program("G21 F1000\nG0 X-100 Y-100 Z10\nG1 Z0\nG2 X-100 Y-100 I100 J100\n");
  EXPECT_NO_THROW(check_workspace(ok, elkady(), ProgramFrame{}));
  // The circle of radius 200 mm leaves the x stroke on its far side.
  const Program out = read_program("G21 F1000\nG0 X-100 Y0\nG1 X0\n  G2 X0 Y0 I200 J0\n");
  try {
    check_workspace(out, elkady(), ProgramFrame{}, SoftLimits{}, "part.ngc");
    FAIL() << "outside the workspace";
  } catch (const ProgramError& e) {
    ASSERT_EQ(e.diagnostics().size(), 1u);
    EXPECT_EQ(e.diagnostics()[0].line, 4);
    EXPECT_EQ(e.diagnostics()[0].column, 6);
    EXPECT_NE(e.diagnostics()[0].message.find("outside the workspace"), std::string::npos);
  }
  // The planner, given it anyway, names the line too.
  try {
    (void)plan_path(to_queue(out, ProgramFrame{}, 1e-4), elkady(), PlannerOptions{});
    FAIL() << "planned outside the workspace";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("line 4"), std::string::npos) << e.what();
  }
  SoftLimits soft;
  soft.max = Vec3(0.5, 1, 1);
  EXPECT_THROW(check_workspace(ok, elkady(), ProgramFrame{}, soft), ProgramError);
}

TEST(Gcode, ProgramFrameZUpAndArcSense) {
  // A counter-clockwise quarter in the XY plane seen from +Z (up) stays
  // counter-clockwise about the machine's z, whose axis points down.
  const Program p = read_program("G21 F600\nG0 X50 Y0 Z-20\nG3 X0 Y50 I-50 J0\nG18 G2 X0 Z30 I0 K25\n");
  const ProgramFrame f;
  const PathQueue q = to_queue(p, f, 1e-4);
  ASSERT_EQ(q.segments().size(), 3u);
  EXPECT_LT((q.segments()[0].end - (f.origin + Vec3(0.05, 0, 0.02))).norm(), 1e-15);  // Z-20 is 20 mm lower: +z
  const Segment& a = q.segments()[1];
  EXPECT_NEAR(a.sweep * a.normal.z(), std::numbers::pi / 2, 1e-12);
  // The arc passes the program's (35.36, 35.36) mm.
  const Piece pc = piece_of(a, 0.0, segment_length(a));
  EXPECT_LT((pc.at(pc.length / 2).p - f.to_machine(Vec3(0.05, 0.05, -0.04) / std::sqrt(2.0) * 1.0)).head<2>().norm(),
            1e-12);
  // The G18 clockwise half turn (about program +Y) goes over the top: through Z+5 ... up in the program, -z in the machine.
  const Segment& b = q.segments()[2];
  const Piece pb = piece_of(b, 0.0, segment_length(b));
  EXPECT_NEAR(f.to_program(pb.at(pb.length / 2).p).x(), 0.025, 1e-12);
  EXPECT_NEAR(f.to_program(pb.at(pb.length / 2).p).z(), 0.005, 1e-12);
  EXPECT_DOUBLE_EQ(q.tolerance(), 1e-4);
}

TEST(Gcode, AProgramPlansEndToEnd) {
  const std::string text =
      "%\n(square with a dwell)\nG21 G17 G90 G64 P0.05\nG0 X-50 Y-50 Z0\nF3000\nG1 X50\nY50\nG3 X-50 Y50 R50\n"
      "G1 Y-50\nG4 P0.2\nG0 Z10\n%\n";
  const Program p = read_program(text);
  check_workspace(p, elkady(), ProgramFrame{});
  const PathQueue q = to_queue(p, ProgramFrame{}, 1e-3);
  EXPECT_DOUBLE_EQ(q.tolerance(), 0.05e-3);
  const Plan plan = plan_path(q, elkady(), PlannerOptions{});
  EXPECT_LT((plan.sample(plan.duration()).p - ProgramFrame{}.to_machine(Vec3(-0.05, -0.05, 0.01))).norm(), 1e-12);
  EXPECT_EQ(q.segments()[static_cast<std::size_t>(plan.sample_path(plan.duration() / 2).segment)].line >= 4, true);
}

}  // namespace
}  // namespace cpm::path::test
