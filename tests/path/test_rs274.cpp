// SPDX-License-Identifier: Apache-2.0
// Our canonical moves against those of Debian's rs274 (LinuxCNC's
// RS274NGC interpreter, package linuxcnc-uspace) on the programs in
// tests/path/programs: arcs in the three planes, incremental moves and
// centres, absolute centres, inch units, dwells. Skipped when rs274 is not
// installed.
#include <gtest/gtest.h>

#include <array>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <memory>
#include <regex>
#include <sstream>

#include <unistd.h>

#include "cpm/path/gcode.hpp"

namespace cpm::path::test {
namespace {

namespace fs = std::filesystem;

// One canonical call of rs274 as we read it: SI, program frame.
struct Reference {
  MoveKind kind = MoveKind::feed;
  Vec3 end = Vec3::Zero(), centre = Vec3::Zero();
  int turn = 0;
  double feed = 0.0, dwell = 0.0;
  Units units = Units::mm;
  std::string text;
};

std::string rs274() {
  for (const char* dir : {"/usr/bin", "/usr/local/bin", "/bin"})
    if (fs::exists(fs::path(dir) / "rs274")) return (fs::path(dir) / "rs274").string();
  return "";
}

// One rs274 at a time on this machine: two at once share some of its state
// and one dies with a bus error, printing no canonical call (7 of 30 started
// together here; ctest runs this file's tests two at a time).
std::string run(const std::string& exe, const std::string& file) {
  std::string out;
  const std::string lock = (fs::temp_directory_path() / "cpm-rs274.lock").string();
  const std::string cmd = "flock '" + lock + "' " + exe + " -g '" + file + "' 2>&1";
  std::unique_ptr<FILE, int (*)(FILE*)> p(popen(cmd.c_str(), "r"), pclose);
  std::array<char, 4096> buf{};
  while (p && fgets(buf.data(), static_cast<int>(buf.size()), p.get())) out += buf.data();
  return out;
}

std::vector<double> numbers(const std::string& args) {
  std::vector<double> v;
  std::stringstream ss(args);
  std::string item;
  while (std::getline(ss, item, ',')) v.push_back(std::stod(item));
  return v;
}

// ARC_FEED(first_end, second_end, first_centre, second_centre, rotation, axis_end, ...)
// with (first, second, axis) = (X, Y, Z), (Z, X, Y), (Y, Z, X) for XY, XZ, YZ.
Reference arc_feed(const std::vector<double>& a, int plane, double k) {
  static constexpr std::array<std::array<int, 3>, 3> axes{{{0, 1, 2}, {2, 0, 1}, {1, 2, 0}}};
  const auto& ax = axes[static_cast<std::size_t>(plane)];
  Reference r;
  r.kind = MoveKind::arc;
  r.end[ax[0]] = a[0] * k, r.end[ax[1]] = a[1] * k, r.end[ax[2]] = a[5] * k;
  r.centre[ax[0]] = a[2] * k, r.centre[ax[1]] = a[3] * k;
  r.turn = static_cast<int>(a[4]);
  return r;
}

std::vector<Reference> canonical(const std::string& output) {
  static const std::regex call(R"(^\s*\d+ N\S*\s+([A-Z_]+)\((.*)\)\s*$)");
  std::vector<Reference> refs;
  double k = 1e-3, feed = 0.0;  // m per program unit; m/s
  Units units = Units::mm;
  int plane = 0;
  std::istringstream in(output);
  for (std::string line; std::getline(in, line);) {
    std::smatch m;
    if (!std::regex_match(line, m, call)) continue;
    const std::string name = m[1], args = m[2];
    if (name == "USE_LENGTH_UNITS") {
      units = args.find("INCHES") != std::string::npos ? Units::inch : Units::mm;
      k = units == Units::inch ? 0.0254 : 1e-3;
    } else if (name == "SET_FEED_RATE") {
      feed = numbers(args)[0] * k / 60.0;  // in the units in force when it is set
    } else if (name == "SELECT_PLANE") {
      plane = args.find("XZ") != std::string::npos ? 1 : args.find("YZ") != std::string::npos ? 2 : 0;
    } else if (name == "STRAIGHT_TRAVERSE" || name == "STRAIGHT_FEED" || name == "ARC_FEED" || name == "DWELL") {
      const std::vector<double> a = numbers(args);
      Reference r;
      if (name == "ARC_FEED") r = arc_feed(a, plane, k);
      else if (name == "DWELL") r.kind = MoveKind::dwell, r.dwell = a[0];
      else r.kind = name == "STRAIGHT_FEED" ? MoveKind::feed : MoveKind::traverse, r.end = Vec3(a[0], a[1], a[2]) * k;
      r.feed = feed;
      r.units = units;
      r.text = line;
      refs.push_back(r);
    }
  }
  return refs;
}

std::string read_file(const fs::path& p) {
  std::ifstream f(p);
  std::stringstream ss;
  ss << f.rdbuf();
  return ss.str();
}

// rs274 prints 4 decimals of the program's unit.
void expect_same(const CanonicalMove& ours, const Reference& ref, const std::string& where) {
  const double tol = (ref.units == Units::inch ? 0.0254 : 1e-3) * 0.6e-4;
  ASSERT_EQ(static_cast<int>(ours.kind), static_cast<int>(ref.kind)) << where << ref.text;
  EXPECT_EQ(static_cast<int>(ours.units), static_cast<int>(ref.units)) << where << ref.text;
  if (ref.kind == MoveKind::dwell) {
    EXPECT_NEAR(ours.dwell, ref.dwell, 0.6e-4) << where << ref.text;
    return;
  }
  EXPECT_LT((ours.end - ref.end).cwiseAbs().maxCoeff(), tol) << where << ref.text;
  if (ref.kind != MoveKind::traverse) {
    EXPECT_NEAR(ours.feed, ref.feed, 1e-9) << where << ref.text;
  }
  if (ref.kind != MoveKind::arc) return;
  EXPECT_EQ(ours.turn, ref.turn) << where << ref.text;
  const Vec3 n = plane_normal(ours.plane);
  const Vec3 c = ours.centre - ours.centre.dot(n) * n, r = ref.centre - ref.centre.dot(n) * n;
  EXPECT_LT((c - r).cwiseAbs().maxCoeff(), tol) << where << ref.text;
}

TEST(Rs274, CanonicalMovesAgreeOnEveryTestProgram) {
  const std::string exe = rs274();
  if (exe.empty()) GTEST_SKIP() << "rs274 not found: install Debian's linuxcnc-uspace to compare with LinuxCNC";
  int programs = 0, moves = 0;
  for (const auto& entry : fs::directory_iterator(CPM_PATH_PROGRAMS)) {
    if (entry.path().extension() != ".ngc") continue;
    const std::vector<Reference> refs = canonical(run(exe, entry.path().string()));
    ReaderOptions o;
    o.name = entry.path().filename().string();
    const Program prog = read_program(read_file(entry.path()), o);
    ASSERT_EQ(prog.moves.size(), refs.size()) << o.name;
    for (std::size_t k = 0; k < refs.size(); ++k)
      expect_same(prog.moves[k], refs[k], o.name + " move " + std::to_string(k + 1) + ": ");
    ++programs;
    moves += static_cast<int>(refs.size());
  }
  EXPECT_GE(programs, 7);
  RecordProperty("programs", programs);
  RecordProperty("moves", moves);
  std::printf("rs274 agrees with the reader on %d programs, %d canonical moves\n", programs, moves);
}

TEST(Rs274, BothRefuseAnArcWhoseRadiusChanges) {
  // Near LinuxCNC's tolerance (0.0283 mm and 0.1 %) on either side.
  const std::string exe = rs274();
  if (exe.empty()) GTEST_SKIP() << "rs274 not found: install Debian's linuxcnc-uspace to compare with LinuxCNC";
  const fs::path dir = fs::temp_directory_path() / ("cpm_rs274_" + std::to_string(::getpid()));
  fs::create_directories(dir);
  struct Case {
    const char *end, *i;  // X of the end, I of the centre (mm)
  };
  for (const Case& c : {Case{"20.02", "10"}, Case{"20.03", "10"}, Case{"200.09", "100"}, Case{"200.11", "100"},
                        Case{"2.026", "1"}}) {
    const std::string text = std::string("G21 G17 G90 F100\nG0 X0 Y0 Z0\nG2 X") + c.end + " Y0 I" + c.i + " J0\nM2\n";
    std::ofstream(dir / "r.ngc") << text;
    const bool theirs = run(exe, (dir / "r.ngc").string()).find("differs") != std::string::npos;
    bool ours = false;
    try {
      (void)read_program(text);
    } catch (const ProgramError&) {
      ours = true;
    }
    EXPECT_EQ(ours, theirs) << "end X" << c.end << " about I" << c.i;
  }
  fs::remove_all(dir);
}

}  // namespace
}  // namespace cpm::path::test
