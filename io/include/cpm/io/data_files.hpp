// SPDX-License-Identifier: Apache-2.0
// Readers and writers for the measurement files of docs/data-formats.md
// (a published interface: read exactly as written there).
//
// Common rules (docs/data-formats.md): UTF-8, one header line of column names,
// comma separated; column order free; unknown columns ignored with a warning
// (in `warnings`); a missing required column is an error naming it; `#` lines
// are comments, `# key = value` is metadata; SI units; a non-numeric, NaN or
// infinite value is an error naming the line and column; rows are never
// silently dropped.
//
// Every reader throws cpm::Error with a message of the form
//   "FILE:LINE: column 'd2': 'abc' is not a number"
// and never returns partial data.
#pragma once

#include <array>
#include <cstdint>
#include <map>
#include <string>
#include <variant>
#include <vector>

#include "cpm/kinematics/types.hpp"

namespace cpm::io {

enum class DataKind { ballbar, position, motion };
const char* kind_name(DataKind k) noexcept;  // "ballbar", "position", "motion"

// Columns every kind may carry (empty vectors when the column is absent).
struct CommonColumns {
  std::vector<double> t;                          // s
  std::vector<std::array<std::int8_t, 3>> dir;    // -1 or +1 per axis (dir1..dir3, all three or none)
  std::vector<long> run;                          // test run of each row
};

struct FileInfo {
  std::string path;
  std::map<std::string, std::string> metadata;    // every `# key = value`
  std::vector<std::string> warnings;              // e.g. unknown columns
  std::vector<int> line_of_row;                   // file line number of each data row (1-based)
};

struct BallbarData {
  FileInfo info;
  Vec3 pivot = Vec3::Zero();         // nominal fixed-ball position (m), metadata `pivot` (required)
  bool length_offset_known = true;   // metadata `length_offset_known` (default true)
  std::vector<Vec3> d;               // actuator displacements (m)
  std::vector<double> length;        // measured bar length (m)
  CommonColumns extra;
};

struct PositionData {
  FileInfo info;
  double sigma = 0.0;                // metadata `sigma` (m); 0 when absent
  std::vector<Vec3> d;               // actuator displacements (m)
  std::vector<Vec3> p;               // measured platform point (m), machine frame
  CommonColumns extra;
};

struct MotionData {
  FileInfo info;
  double rate = 0.0;                 // metadata `rate` (Hz); 0 when absent
  std::vector<double> t;             // s (required for motion)
  std::vector<Vec3> d;               // m
  std::vector<Vec3> v;               // m/s
  std::vector<Vec3> f;               // commanded actuator forces (N)
  std::vector<Vec3> a;               // m/s^2, empty unless a1..a3 were in the file
  std::vector<long> run;
};

using DataSet = std::variant<BallbarData, PositionData, MotionData>;

// Read any of the three kinds, chosen by the `# kind = ...` metadata.
DataSet read_data_file(const std::string& path);
// Read one kind; an error names the kind the file declares when it differs.
BallbarData read_ballbar(const std::string& path);
PositionData read_position(const std::string& path);
MotionData read_motion(const std::string& path);
// The same from text already in memory (`name` is used in messages).
DataSet parse_data(const std::string& text, const std::string& name);

// Writers (for the simulator and tests): the same layouts, full precision,
// written atomically (temporary file, fsync, rename).
void write_ballbar(const std::string& path, const BallbarData& data);
void write_position(const std::string& path, const PositionData& data);
void write_motion(const std::string& path, const MotionData& data);
// Whichever kind `data` holds.
void write_data_file(const std::string& path, const DataSet& data);
// The text the writers write (`name` is used in messages), e.g. for
// parse_data round trips in memory.
std::string render_ballbar(const BallbarData& data, const std::string& name = "ballbar data");
std::string render_position(const PositionData& data, const std::string& name = "position data");
std::string render_motion(const MotionData& data, const std::string& name = "motion data");

// The kind a DataSet holds, and its number of samples (rows).
DataKind kind_of(const DataSet& data) noexcept;
std::size_t sample_count(const DataSet& data) noexcept;

}  // namespace cpm::io
