// SPDX-License-Identifier: Apache-2.0
// The measurement files of docs/data-formats.md: round trips of the
// three layouts, every error rule with the line/column its message names,
// real-world formatting (CRLF, BOM, spaces, quotes), and atomic writes.
#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <sys/resource.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <csignal>
#include <cmath>
#include <limits>
#include <random>

#include "cpm/io/data_files.hpp"
#include "io_test_util.hpp"

namespace cpm::io {
namespace {

using test::error_of;
using test::same_bits;
using test::ScratchDir;
using test::write_text;
using ::testing::HasSubstr;

// Values that stress a printer: thirds, tiny and huge magnitudes, negative zero.
double awkward(std::mt19937_64& rng, int i) {
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  switch (i % 6) {
    case 0: return u(rng) / 3.0;
    case 1: return u(rng) * 1e-300;
    case 2: return u(rng) * 1e12;
    case 3: return -0.0;
    case 4: return 0.1 + u(rng) * 1e-17;
    default: return std::nextafter(u(rng), 2.0);
  }
}
Vec3 awkward3(std::mt19937_64& rng, int i) { return {awkward(rng, i), awkward(rng, i + 1), awkward(rng, i + 2)}; }

TEST(DataFiles, BallbarRoundTripIsBitExactWithEveryOptionalColumn) {
  ScratchDir dir;
  std::mt19937_64 rng(11);
  BallbarData b;
  b.pivot = Vec3(0.43, 0.43, 1.0 / 3.0);
  b.length_offset_known = false;
  b.info.metadata["instrument"] = "QC10 s/n 1234";
  for (int i = 0; i < 97; ++i) {
    b.d.push_back(awkward3(rng, i));
    b.length.push_back(0.1 + std::abs(awkward(rng, i)) * 1e-6 + 1e-9);
    b.extra.t.push_back(awkward(rng, i + 3));
    b.extra.dir.push_back({static_cast<std::int8_t>(i % 2 ? 1 : -1), 1, -1});
    b.extra.run.push_back(i / 10 - 3);
  }
  const std::string path = dir.path("bb.csv");
  write_ballbar(path, b);
  const BallbarData r = read_ballbar(path);
  EXPECT_TRUE(same_bits(r.pivot, b.pivot));
  EXPECT_FALSE(r.length_offset_known);
  EXPECT_EQ(r.info.metadata.at("instrument"), "QC10 s/n 1234");
  // The only warning is the unit check (some displacements are 1e12 m).
  for (const auto& w : r.info.warnings) EXPECT_THAT(w, HasSubstr("millimetres"));
  ASSERT_EQ(r.d.size(), b.d.size());
  ASSERT_EQ(r.extra.t.size(), b.d.size());
  for (std::size_t i = 0; i < b.d.size(); ++i) {
    EXPECT_TRUE(same_bits(r.d[i], b.d[i])) << i;
    EXPECT_TRUE(same_bits(r.length[i], b.length[i])) << i;
    EXPECT_TRUE(same_bits(r.extra.t[i], b.extra.t[i])) << i;
    EXPECT_EQ(r.extra.dir[i], b.extra.dir[i]) << i;
    EXPECT_EQ(r.extra.run[i], b.extra.run[i]) << i;
  }
  // The file's own line numbers: 4 metadata lines, the header, then rows.
  EXPECT_EQ(r.info.line_of_row.front(), 6);
  EXPECT_EQ(r.info.line_of_row.back(), 6 + 96);
  // Writing what was read gives the same bytes.
  const std::string path2 = dir.path("bb2.csv");
  write_ballbar(path2, r);
  EXPECT_EQ(test::read_text(path), test::read_text(path2));
}

TEST(DataFiles, PositionRoundTripWithAndWithoutOptionalColumns) {
  ScratchDir dir;
  std::mt19937_64 rng(12);
  for (bool optional : {false, true}) {
    PositionData p;
    p.sigma = optional ? 2.5e-6 : 0.0;
    for (int i = 0; i < 40; ++i) {
      p.d.push_back(awkward3(rng, i));
      p.p.push_back(awkward3(rng, i + 1));
      if (optional) {
        p.extra.t.push_back(0.001 * i);
        p.extra.dir.push_back({1, static_cast<std::int8_t>(i % 3 ? 1 : -1), 1});
      }
    }
    const std::string path = dir.path("pos.csv");
    write_position(path, p);
    const DataSet any = read_data_file(path);
    ASSERT_TRUE(std::holds_alternative<PositionData>(any));
    const PositionData& r = std::get<PositionData>(any);
    EXPECT_TRUE(same_bits(r.sigma, p.sigma));
    EXPECT_EQ(r.extra.t.size(), p.extra.t.size());
    EXPECT_EQ(r.extra.dir, p.extra.dir);
    EXPECT_TRUE(r.extra.run.empty());
    for (std::size_t i = 0; i < p.d.size(); ++i) {
      EXPECT_TRUE(same_bits(r.d[i], p.d[i]));
      EXPECT_TRUE(same_bits(r.p[i], p.p[i]));
      if (optional) {
        EXPECT_TRUE(same_bits(r.extra.t[i], p.extra.t[i]));
      }
    }
  }
}

TEST(DataFiles, MotionRoundTripWithAccelerationAndRuns) {
  ScratchDir dir;
  std::mt19937_64 rng(13);
  for (bool optional : {false, true}) {
    MotionData m;
    m.rate = 1000.0;
    for (int i = 0; i < 500; ++i) {
      m.t.push_back(i * 1e-3);
      m.d.push_back(awkward3(rng, i));
      m.v.push_back(awkward3(rng, i + 1));
      m.f.push_back(awkward3(rng, i + 2));
      if (optional) {
        m.a.push_back(awkward3(rng, i + 3));
        m.run.push_back(i / 100);
      }
    }
    const std::string path = dir.path("motion.csv");
    write_motion(path, m);
    const MotionData r = read_motion(path);
    EXPECT_EQ(r.rate, 1000.0);
    ASSERT_EQ(r.t.size(), m.t.size());
    EXPECT_EQ(r.a.size(), m.a.size());
    EXPECT_EQ(r.run, m.run);
    for (std::size_t i = 0; i < m.t.size(); ++i) {
      EXPECT_TRUE(same_bits(r.t[i], m.t[i]));
      EXPECT_TRUE(same_bits(r.d[i], m.d[i]));
      EXPECT_TRUE(same_bits(r.v[i], m.v[i]));
      EXPECT_TRUE(same_bits(r.f[i], m.f[i]));
      if (optional) {
        EXPECT_TRUE(same_bits(r.a[i], m.a[i]));
      }
    }
  }
}

// --- Reading what real files contain ------------------------------------

TEST(DataFiles, ReadsCrlfBomSpacesQuotesCommentsAndTrailingBlankLines) {
  const std::string text =
      "\xEF\xBB\xBF# exported by the tracker software\r\n"
      "#  kind =  position \r\n"
      "# sigma = 1e-6\r\n"
      "# operator = A. N. Other\r\n"
      " px , \"py\",pz, d1 ,d2,d3 , temperature\r\n"
      " 0.5, 0.4 ,0.3 ,0.1,0.2,+0.3, 21.5\r\n"
      "# a comment between rows\r\n"
      "0.51,0.41,0.31,0.11,0.21,0.31,\"21.6\"\r\n"
      "\r\n"
      "  \r\n";
  const DataSet ds = parse_data(text, "tracker.csv");
  const auto& p = std::get<PositionData>(ds);
  ASSERT_EQ(p.d.size(), 2u);
  EXPECT_EQ(p.d[0], Vec3(0.1, 0.2, 0.3));
  EXPECT_EQ(p.p[0], Vec3(0.5, 0.4, 0.3));
  EXPECT_EQ(p.p[1], Vec3(0.51, 0.41, 0.31));
  EXPECT_EQ(p.sigma, 1e-6);
  EXPECT_EQ(p.info.metadata.at("operator"), "A. N. Other");
  EXPECT_EQ(p.info.line_of_row, (std::vector<int>{6, 8}));
  ASSERT_EQ(p.info.warnings.size(), 1u);
  EXPECT_THAT(p.info.warnings[0], HasSubstr("tracker.csv:5: column 'temperature'"));
  EXPECT_THAT(p.info.warnings[0], HasSubstr("ignored"));
}

TEST(DataFiles, ColumnOrderIsFree) {
  const auto a = std::get<BallbarData>(parse_data(
      "# kind = ballbar\n# pivot = 1 2 3\nlength,d3,d2,d1\n0.1,3,2,1\n", "a.csv"));
  EXPECT_EQ(a.d[0], Vec3(1, 2, 3));
  EXPECT_EQ(a.length[0], 0.1);
  EXPECT_EQ(a.pivot, Vec3(1, 2, 3));
  EXPECT_TRUE(a.length_offset_known);  // the default of docs/data-formats.md
}

// --- Error rules of docs/data-formats.md -------------------------------------

const std::string kBallbarHead = "# kind = ballbar\n# pivot = 0.43 0.43 0.53\n";

TEST(DataFiles, MissingRequiredColumnIsNamed) {
  const std::string e = error_of([&] { parse_data(kBallbarHead + "d1,d2,length\n0,0,0.1\n", "f.csv"); });
  EXPECT_THAT(e, HasSubstr("f.csv:3: required column 'd3' is missing"));
  const std::string m = error_of([&] {
    parse_data("# kind = motion\nd1,d2,d3,v1,v2,v3,f1,f2,f3\n0,0,0,0,0,0,0,0,0\n", "m.csv");
  });
  EXPECT_THAT(m, HasSubstr("m.csv:2: required column 't' is missing"));
}

TEST(DataFiles, NonNumericNanAndInfinityNameLineAndColumn) {
  const std::string head = kBallbarHead + "d1,d2,d3,length\n0.1,0.1,0.1,0.1\n";
  EXPECT_EQ(error_of([&] { parse_data(head + "0.1,abc,0.1,0.1\n", "f.csv"); }),
            "f.csv:5: column 'd2': 'abc' is not a number");
  EXPECT_THAT(error_of([&] { parse_data(head + "0.1,0.1,NaN,0.1\n", "f.csv"); }),
              HasSubstr("f.csv:5: column 'd3': 'NaN' is not a finite number"));
  EXPECT_THAT(error_of([&] { parse_data(head + "0.1,0.1,0.1,0.1\n-inf,0.1,0.1,0.1\n", "f.csv"); }),
              HasSubstr("f.csv:6: column 'd1': '-inf' is not a finite number"));
  EXPECT_THAT(error_of([&] { parse_data(head + "0.1,,0.1,0.1\n", "f.csv"); }),
              HasSubstr("f.csv:5: column 'd2': empty value"));
  EXPECT_THAT(error_of([&] { parse_data(head + "0.1,0.1 0.2,0.1,0.1\n", "f.csv"); }),
              HasSubstr("f.csv:5: column 'd2': '0.1 0.2' is not a number"));
  // A bad value in an ignored column is not an error (it is not read).
  EXPECT_EQ(error_of([&] { parse_data(kBallbarHead + "d1,d2,d3,length,note\n0,0,0,0.1,x\n", "f.csv"); }), "");
}

TEST(DataFiles, KindIsRequiredAndChecked) {
  EXPECT_THAT(error_of([] { parse_data("d1,d2,d3,length\n0,0,0,0.1\n", "f.csv"); }),
              HasSubstr("f.csv: no '# kind = ...' line"));
  EXPECT_THAT(error_of([] { parse_data("# kind = ballbars\nd1\n", "f.csv"); }),
              HasSubstr("f.csv:1: metadata 'kind': 'ballbars' is not one of ballbar, position, motion"));
  ScratchDir dir;
  write_text(dir.path("p.csv"), "# kind = position\nd1,d2,d3,px,py,pz\n0,0,0,0,0,0\n");
  const std::string e = error_of([&] { read_ballbar(dir.path("p.csv")); });
  EXPECT_THAT(e, HasSubstr("p.csv:1: metadata 'kind': this is a position file, but a ballbar file was expected"));
  EXPECT_THAT(error_of([&] { read_motion(dir.path("p.csv")); }), HasSubstr("this is a position file"));
  EXPECT_EQ(error_of([&] { read_position(dir.path("p.csv")); }), "");
  EXPECT_THAT(error_of([&] { read_position(dir.path("absent.csv")); }), HasSubstr("absent.csv: cannot read"));
}

TEST(DataFiles, BallbarPivotAndLengthOffsetMetadata) {
  const std::string rows = "d1,d2,d3,length\n0,0,0,0.1\n";
  EXPECT_THAT(error_of([&] { parse_data("# kind = ballbar\n" + rows, "f.csv"); }),
              HasSubstr("f.csv: no '# pivot = x y z' line"));
  EXPECT_THAT(error_of([&] { parse_data("# kind = ballbar\n# pivot = 0.43 0.43\n" + rows, "f.csv"); }),
              HasSubstr("f.csv:2: metadata 'pivot': expected 3 numbers 'x y z' (m), got 2"));
  EXPECT_THAT(error_of([&] { parse_data("# kind = ballbar\n# pivot = 0.43 x 0.5\n" + rows, "f.csv"); }),
              HasSubstr("f.csv:2: metadata 'pivot': 'x' is not a finite number"));
  EXPECT_THAT(error_of([&] { parse_data("# kind = ballbar\n# pivot = 0.43 nan 0.5\n" + rows, "f.csv"); }),
              HasSubstr("'nan' is not a finite number"));
  const auto b = std::get<BallbarData>(parse_data(
      "# kind = ballbar\n# pivot =  0.43\t0.44   0.53 \n# length_offset_known = False\n" + rows, "f.csv"));
  EXPECT_EQ(b.pivot, Vec3(0.43, 0.44, 0.53));
  EXPECT_FALSE(b.length_offset_known);
  EXPECT_THAT(error_of([&] {
                parse_data(kBallbarHead + "# length_offset_known = maybe\n" + rows, "f.csv");
              }),
              HasSubstr("f.csv:3: metadata 'length_offset_known': 'maybe' must be true or false"));
  EXPECT_THAT(error_of([&] { parse_data(kBallbarHead + "d1,d2,d3,length\n0,0,0,-0.1\n", "f.csv"); }),
              HasSubstr("f.csv:4: column 'length': '-0.1' is not a bar length"));
}

TEST(DataFiles, SigmaAndRateMetadata) {
  EXPECT_THAT(error_of([] {
                parse_data("# kind = position\n# sigma = -1e-6\nd1,d2,d3,px,py,pz\n0,0,0,0,0,0\n", "f.csv");
              }),
              HasSubstr("f.csv:2: metadata 'sigma': a standard deviation must be >= 0 m"));
  EXPECT_THAT(error_of([] {
                parse_data("# kind = motion\n# rate = fast\nt,d1,d2,d3,v1,v2,v3,f1,f2,f3\n0,0,0,0,0,0,0,0,0,0\n",
                           "f.csv");
              }),
              HasSubstr("f.csv:2: metadata 'rate': 'fast' is not a number"));
  const auto m = std::get<MotionData>(
      parse_data("# kind = motion\nt,d1,d2,d3,v1,v2,v3,f1,f2,f3\n0,0,0,0,0,0,0,0,0,0\n", "f.csv"));
  EXPECT_EQ(m.rate, 0.0);  // absent
  EXPECT_THAT(error_of([] {
                parse_data("# kind = position\n# sigma = 1e-6\n# sigma = 2e-6\nd1,d2,d3,px,py,pz\n0,0,0,0,0,0\n",
                           "f.csv");
              }),
              HasSubstr("f.csv:3: metadata 'sigma' given twice with different values (first on line 2"));
}

TEST(DataFiles, DirectionColumnsComeTogetherAndAreSigns) {
  const std::string head = kBallbarHead + "d1,d2,d3,length,dir1,dir2,dir3\n";
  EXPECT_THAT(error_of([&] { parse_data(head + "0,0,0,0.1,1,-1,0\n", "f.csv"); }),
              HasSubstr("f.csv:4: column 'dir3': '0' is not a direction (must be -1 or +1)"));
  EXPECT_THAT(error_of([&] { parse_data(head + "0,0,0,0.1,1,-1,0.5\n", "f.csv"); }),
              HasSubstr("column 'dir3': '0.5' is not a direction"));
  const auto b = std::get<BallbarData>(parse_data(head + "0,0,0,0.1,+1,-1,1.0\n", "f.csv"));
  EXPECT_EQ(b.extra.dir[0], (std::array<std::int8_t, 3>{1, -1, 1}));
  EXPECT_THAT(error_of([&] { parse_data(kBallbarHead + "d1,d2,d3,length,dir1,dir3\n0,0,0,0.1,1,1\n", "f.csv"); }),
              HasSubstr("f.csv:3: column 'dir2' is missing: dir1..dir3 come all three or not at all"));
  EXPECT_THAT(error_of([] {
                parse_data("# kind = motion\nt,d1,d2,d3,v1,v2,v3,f1,f2,f3,a1,a2\n0,0,0,0,0,0,0,0,0,0,0,0\n", "m.csv");
              }),
              HasSubstr("m.csv:2: column 'a3' is missing"));
  EXPECT_THAT(error_of([&] { parse_data(kBallbarHead + "d1,d2,d3,length,run\n0,0,0,0.1,1.5\n", "f.csv"); }),
              HasSubstr("f.csv:4: column 'run': '1.5' is not an integer"));
}

TEST(DataFiles, RowsWithTooManyOrTooFewFieldsNameTheLine) {
  const std::string head = kBallbarHead + "d1,d2,d3,length\n0,0,0,0.1\n";
  EXPECT_EQ(error_of([&] { parse_data(head + "0,0,0\n", "f.csv"); }),
            "f.csv:5: 3 fields, but the header (line 3) has 4 columns");
  EXPECT_EQ(error_of([&] { parse_data(head + "0,0,0,0.1,7\n", "f.csv"); }),
            "f.csv:5: 5 fields, but the header (line 3) has 4 columns");
  EXPECT_EQ(error_of([&] { parse_data(head + "0,0,0,0.1,\n", "f.csv"); }),
            "f.csv:5: 5 fields, but the header (line 3) has 4 columns");
}

TEST(DataFiles, RepeatedHeaderIsRefusedWithItsLine) {
  const std::string e = error_of([] {
    parse_data(kBallbarHead + "d1,d2,d3,length\n0,0,0,0.1\n# second file\nd1,d2,d3,length\n0,0,0,0.1\n", "f.csv");
  });
  EXPECT_THAT(e, HasSubstr("f.csv:6: the header line is repeated here (first on line 3)"));
}

TEST(DataFiles, EmptyFilesAndHeaderWithoutRowsAreRefused) {
  EXPECT_THAT(error_of([] { parse_data("", "e.csv"); }), HasSubstr("e.csv: no '# kind"));
  EXPECT_THAT(error_of([] { parse_data("# kind = ballbar\n# pivot = 0 0 0\n\n", "e.csv"); }),
              HasSubstr("e.csv: empty file: no header line"));
  EXPECT_THAT(error_of([] { parse_data(kBallbarHead + "d1,d2,d3,length\n\n\n", "e.csv"); }),
              HasSubstr("e.csv:3: no data: the header is not followed by any row"));
  EXPECT_THAT(error_of([] { parse_data(kBallbarHead + "0.1,0.2,0.3,0.1\n0,0,0,0.1\n", "e.csv"); }),
              HasSubstr("e.csv:3: this line holds numbers, not column names"));
  EXPECT_THAT(error_of([] { parse_data(kBallbarHead + "d1,d2,,length\n0,0,0,0\n", "e.csv"); }),
              HasSubstr("e.csv:3: column 3 of the header has no name"));
  EXPECT_THAT(error_of([] { parse_data(kBallbarHead + "d1,d2,d3,d1,length\n0,0,0,0,0.1\n", "e.csv"); }),
              HasSubstr("e.csv:3: column 'd1' appears twice"));
}

TEST(DataFiles, NoRowIsDroppedAndMillimetresAreFlagged) {
  std::string text = kBallbarHead + "d1,d2,d3,length\n";
  for (int i = 0; i < 1000; ++i) text += "100,200,150,100.5\n# note\n";
  const auto b = std::get<BallbarData>(parse_data(text, "mm.csv"));
  EXPECT_EQ(b.d.size(), 1000u);
  EXPECT_EQ(b.info.line_of_row[999], 4 + 2 * 999);
  ASSERT_EQ(b.info.warnings.size(), 2u);
  EXPECT_THAT(b.info.warnings[0], HasSubstr("millimetres"));
}

// --- Writers --------------------------------------------------------------

TEST(DataFiles, WritersRefuseWhatTheReaderWouldRefuse) {
  ScratchDir dir;
  BallbarData b;
  b.d = {Vec3(0, 0, 0), Vec3(0, 0, 0)};
  b.length = {0.1};
  EXPECT_THAT(error_of([&] { write_ballbar(dir.path("b.csv"), b); }),
              HasSubstr("column 'length' has 1 values but there are 2 rows"));
  b.length = {0.1, std::numeric_limits<double>::quiet_NaN()};
  EXPECT_THAT(error_of([&] { write_ballbar(dir.path("b.csv"), b); }), HasSubstr("row 2"));
  b.length = {0.1, 0.2};
  b.extra.dir = {{1, 1, 1}, {1, 0, 1}};
  EXPECT_THAT(error_of([&] { write_ballbar(dir.path("b.csv"), b); }), HasSubstr("'dir2' is 0"));
  EXPECT_THAT(error_of([&] { write_motion(dir.path("m.csv"), MotionData{}); }), HasSubstr("no rows"));
  EXPECT_EQ(dir.entries(), 0);  // nothing written, no temporary left behind
}

BallbarData small_ballbar(double length) {
  BallbarData b;
  b.pivot = Vec3(0.43, 0.43, 0.53);
  b.d = {Vec3(0.1, 0.2, 0.3)};
  b.length = {length};
  return b;
}

TEST(DataFiles, FailedRenameLeavesTheTargetAndNoTemporary) {
  ScratchDir dir;
  // The target is a directory: rename() fails after the temporary is written.
  std::filesystem::create_directory(dir.path("target.csv"));
  write_text(dir.path("target.csv/inside"), "keep");
  const std::string e = error_of([&] { write_ballbar(dir.path("target.csv"), small_ballbar(0.1)); });
  EXPECT_THAT(e, HasSubstr("cannot rename"));
  EXPECT_TRUE(std::filesystem::is_directory(dir.path("target.csv")));
  EXPECT_EQ(test::read_text(dir.path("target.csv/inside")), "keep");
  EXPECT_EQ(dir.entries(), 1);
  // A directory that does not exist: nothing can be created.
  EXPECT_THAT(error_of([&] { write_ballbar(dir.path("no/such/dir.csv"), small_ballbar(0.1)); }),
              HasSubstr("cannot create a temporary file"));
}

TEST(DataFiles, WriteThatFailsHalfwayLeavesTheOldFileIntact) {
  ScratchDir dir;
  const std::string path = dir.path("log.csv");
  write_ballbar(path, small_ballbar(0.1));
  const std::string before = test::read_text(path);
  // A child process writes a large file with a 4 KiB file-size limit: the
  // write fails half way (EFBIG), as on a full disk.
  BallbarData big = small_ballbar(0.2);
  for (int i = 0; i < 2000; ++i) {
    big.d.push_back(Vec3(0.1, 0.2, 0.3 + i * 1e-6));
    big.length.push_back(0.2);
  }
  const pid_t pid = ::fork();
  ASSERT_GE(pid, 0);
  if (pid == 0) {
    std::signal(SIGXFSZ, SIG_IGN);
    rlimit lim{4096, 4096};
    ::setrlimit(RLIMIT_FSIZE, &lim);
    int code = 0;
    try {
      write_ballbar(path, big);
      code = 1;  // it should not have succeeded
    } catch (const Error& e) {
      code = std::string(e.what()).find("cannot write") != std::string::npos ? 0 : 2;
    }
    ::_exit(code);
  }
  int status = 0;
  ::waitpid(pid, &status, 0);
  ASSERT_TRUE(WIFEXITED(status));
  EXPECT_EQ(WEXITSTATUS(status), 0);
  EXPECT_EQ(test::read_text(path), before);
  EXPECT_EQ(dir.entries(), 1);  // the temporary file was removed
  // And without the limit the same write succeeds, replaces the file and
  // keeps its permissions.
  ASSERT_EQ(::chmod(path.c_str(), 0600), 0);
  write_ballbar(path, big);
  EXPECT_EQ(read_ballbar(path).d.size(), big.d.size());
  EXPECT_EQ(std::filesystem::status(path).permissions(),
            std::filesystem::perms::owner_read | std::filesystem::perms::owner_write);
}

}  // namespace
}  // namespace cpm::io

namespace cpm::io {
namespace {

TEST(DataFiles, RenderParseInMemoryAndGenericWriter) {
  PositionData p;
  p.d = {Vec3(0.1, 0.2, 0.3), Vec3(0.2, 0.2, 0.2)};
  p.p = {Vec3(0.3, 0.4, 0.5), Vec3(0.4, 0.4, 0.4)};
  const DataSet back = parse_data(render_position(p), "mem");
  EXPECT_EQ(kind_of(back), DataKind::position);
  EXPECT_EQ(sample_count(back), 2u);
  EXPECT_EQ(std::get<PositionData>(back).p[1], p.p[1]);
  ScratchDir dir;
  write_data_file(dir.path("x.csv"), back);
  EXPECT_EQ(test::read_text(dir.path("x.csv")), render_position(p));
}

TEST(DataFiles, TimeGoingBackwardsInARunIsWarnedAbout) {
  const std::string head = "# kind = motion\nt,d1,d2,d3,v1,v2,v3,f1,f2,f3,run\n";
  const auto m = std::get<MotionData>(parse_data(head +
                                                 "0,0,0,0,0,0,0,0,0,0,1\n"
                                                 "0.001,0,0,0,0,0,0,0,0,0,1\n"
                                                 "0,0,0,0,0,0,0,0,0,0,2\n"       // a new run may restart t
                                                 "0.001,0,0,0,0,0,0,0,0,0,2\n"
                                                 "0.001,0,0,0,0,0,0,0,0,0,2\n",  // not within a run
                                                 "m.csv"));
  ASSERT_EQ(m.info.warnings.size(), 1u);
  EXPECT_THAT(m.info.warnings[0], HasSubstr("m.csv:7: t does not increase (0.001 s, then 0.001 s) within a run; 1 such"));
  EXPECT_EQ(m.t.size(), 5u);  // warned about, not dropped
}

}  // namespace
}  // namespace cpm::io

namespace cpm::io {
namespace {

TEST(DataFiles, HeaderUnitsAreAcceptedWhenSiAndRefusedOtherwise) {
  const auto m = std::get<MotionData>(parse_data(
      "# kind = motion\nt (s),d1 [m],d2 (m),d3(m),v1 (m/s),v2,v3,f1 (N),f2,f3,a1 (m/s^2),a2 (m/s²),a3 [m/s2]\n"
      "0.5,1,2,3,4,5,6,7,8,9,10,11,12\n",
      "u.csv"));
  EXPECT_EQ(m.t[0], 0.5);
  EXPECT_EQ(m.d[0], Vec3(1, 2, 3));
  EXPECT_EQ(m.a[0], Vec3(10, 11, 12));
  EXPECT_TRUE(m.info.warnings.empty());
  EXPECT_EQ(error_of([] { parse_data(kBallbarHead + "d1 (mm),d2,d3,length\n1,2,3,100\n", "u.csv"); }),
            "u.csv:3: column 'd1 (mm)': the unit 'mm' is not d1's SI unit (m); these files are in SI "
            "units, convert the column");
  EXPECT_THAT(error_of([] { parse_data(kBallbarHead + "d1 (m),d1,d2,d3,length\n1,1,2,3,0.1\n", "u.csv"); }),
              HasSubstr("u.csv:3: column 'd1' appears twice"));
}

TEST(DataFiles, CommonHeaderMistakesAreExplained) {
  EXPECT_THAT(error_of([] { parse_data(kBallbarHead + "d1;d2;d3;length\n1;2;3;0.1\n", "s.csv"); }),
              HasSubstr("s.csv:3: the header is not comma separated (it holds ';')"));
  EXPECT_THAT(error_of([] { parse_data(kBallbarHead + "D1,d2,d3,length\n1,2,3,0.1\n", "s.csv"); }),
              HasSubstr("s.csv:3: required column 'd1' is missing (the header has 'D1': column names are lower case)"));
}

}  // namespace
}  // namespace cpm::io
