// SPDX-License-Identifier: Apache-2.0
// LinuxCNC's screw-compensation file (the [JOINT_n] COMP_FILE of its INI,
// read by usrmotLoadComp in its src/emc/motion/usrmotintf.cc) for a
// pitch_table (docs/effects.md, "Effects you add"):
//   one triplet "nominal forward reverse" per line, separated by spaces, in
//   machine units (mm on a metric machine, inch on an imperial one); nominal
//   strictly increasing, at most 256 lines (EMCMOT_COMP_SIZE).
//   COMP_FILE_TYPE = 0: forward and reverse are where the axis really is
//     when commanded to `nominal`, moving forward and in reverse;
//   COMP_FILE_TYPE = 1: they are the trims nominal - where it really is.
// LinuxCNC adds the trim to the command, interpolated linearly between
// lines and held beyond the first and last. Its loader stops at the first
// line that is not three numbers, so the file carries no comment.
//
// Our pitch table says d~ = d + e(d): commanded to d the axis is at d + e(d),
// so forward = reverse = d + e(d) (type 0) or trim = -e(d) (type 1). A file
// whose forward and reverse differ holds a direction-dependent error
// (backlash): reading it keeps their mean and says how far apart they were.
#pragma once

#include <string>
#include <vector>

#include "cpm/kinematics/pitch_table.hpp"

namespace cpm::io {

inline constexpr int kLinuxcncCompSize = 256;  // EMCMOT_COMP_SIZE

struct CompUnits {
  double per_metre = 1000.0;  // machine units per m: 1000 (mm), 1 / 0.0254 (inch)
  const char* name = "mm";
};
// "mm" or "inch"; throws Error otherwise.
CompUnits comp_units(const std::string& name);

// The file's text. Throws Error when the table is empty or has more lines than LinuxCNC keeps.
std::string render_linuxcnc_comp(const kin::PitchTable& table, int type, const CompUnits& units);

struct ImportedComp {
  kin::PitchTable table;
  double max_direction_difference = 0.0;  // m: largest |forward - reverse| position
  std::vector<std::string> notes;
};
// Read a file as LinuxCNC reads it (`name` in messages), but refuse instead
// of stopping silently: a line that is not three numbers (blank lines at the
// end excepted), nominal not increasing, more than 256 lines, fewer than 2.
ImportedComp parse_linuxcnc_comp(const std::string& text, const std::string& name, int type, const CompUnits& units);

}  // namespace cpm::io
