// SPDX-License-Identifier: Apache-2.0
#include "cpm/io/linuxcnc_comp.hpp"

#include <cmath>
#include <cstdio>
#include <sstream>

#include "cpm/kinematics/types.hpp"

namespace cpm::io {

CompUnits comp_units(const std::string& name) {
  if (name == "mm") return {1000.0, "mm"};
  if (name == "inch") return {1.0 / 0.0254, "inch"};
  throw Error("machine units '" + name + "': expected mm or inch (LinuxCNC's LINEAR_UNITS)");
}

std::string render_linuxcnc_comp(const kin::PitchTable& t, int type, const CompUnits& u) {
  if (type != 0 && type != 1) throw Error("COMP_FILE_TYPE must be 0 or 1");
  if (t.size < 2) throw Error("no pitch table on this axis");
  if (t.size > kLinuxcncCompSize)
    throw Error("LinuxCNC keeps at most " + std::to_string(kLinuxcncCompSize) + " lines per joint");
  std::string out;
  char line[128];
  for (int k = 0; k < t.size; ++k) {
    const double nominal = t.node[k] * u.per_metre;
    const double error = t.error[k] * u.per_metre;
    // Type 0: where the axis is; type 1: the trim LinuxCNC adds, nominal - actual.
    const double a = type == 0 ? nominal + error : -error;  // 12 digits: 1e-12 m over a metre
    std::snprintf(line, sizeof line, "%.12g %.12g %.12g\n", nominal + 0.0, a + 0.0, a + 0.0);  // + 0.0: no "-0"
    out += line;
  }
  return out;
}

ImportedComp parse_linuxcnc_comp(const std::string& text, const std::string& name, int type, const CompUnits& u) {
  if (type != 0 && type != 1) throw Error("COMP_FILE_TYPE must be 0 or 1");
  ImportedComp out;
  std::istringstream is(text);
  std::string line;
  int number = 0, blank_after = 0;
  std::vector<double> nom, err;
  double previous = 0.0;  // the last nominal, in the file's units
  while (std::getline(is, line)) {
    ++number;
    double n = 0, f = 0, r = 0;
    char rest = 0;
    const int got = std::sscanf(line.c_str(), "%lf %lf %lf %c", &n, &f, &r, &rest);
    if (line.find_first_not_of(" \t\r") == std::string::npos) {
      ++blank_after;
      continue;
    }
    const std::string where = name + ":" + std::to_string(number) + ": ";
    if (blank_after > 0)
      throw Error(where + "a line after a blank one: LinuxCNC's loader stops at the blank line");
    if (got != 3) throw Error(where + "expected three numbers 'nominal forward reverse' (LinuxCNC's loader stops here)");
    if (!std::isfinite(n) || !std::isfinite(f) || !std::isfinite(r)) throw Error(where + "not a finite number");
    if (!nom.empty() && !(n > previous))
      throw Error(where + "nominal positions must increase (LinuxCNC refuses the entry)");
    if (nom.size() >= static_cast<std::size_t>(kLinuxcncCompSize))
      throw Error(where + "more than " + std::to_string(kLinuxcncCompSize) + " lines (LinuxCNC keeps no more)");
    // The error e of the effective displacement: actual - nominal.
    const double ef = type == 0 ? f - n : -f, er = type == 0 ? r - n : -r;
    previous = n;
    nom.push_back(n / u.per_metre);
    err.push_back(0.5 * (ef + er) / u.per_metre);
    out.max_direction_difference = std::max(out.max_direction_difference, std::abs(ef - er) / u.per_metre);
  }
  if (nom.size() < 2) throw Error(name + ": fewer than 2 lines of 'nominal forward reverse'");
  if (nom.size() > static_cast<std::size_t>(kin::PitchTable::kCapacity))
    throw Error(name + ": " + std::to_string(nom.size()) + " lines; a pitch_table holds at most " +
                std::to_string(kin::PitchTable::kCapacity));
  out.table.size = static_cast<int>(nom.size());
  for (std::size_t k = 0; k < nom.size(); ++k) {
    out.table.node[k] = nom[k];
    out.table.error[k] = err[k];
  }
  out.table.validate();
  if (out.max_direction_difference > 0.0) {
    std::ostringstream os;
    os << "forward and reverse differ by up to " << out.max_direction_difference * 1e6
       << " µm: a direction-dependent error (backlash); the pitch_table keeps their mean (add backlash for the rest)";
    out.notes.push_back(os.str());
  }
  return out;
}

}  // namespace cpm::io
