// SPDX-License-Identifier: Apache-2.0
// The G-code reader's pieces: lexing a line into words, and the arc centres.
#pragma once

#include <string_view>
#include <vector>

#include "cpm/path/gcode.hpp"

namespace cpm::path::detail {

struct Word {
  char letter = 0;    // upper case
  double value = 0.0;
  int column = 0;     // 1-based, of the letter
};

struct Block {
  int line = 0;
  std::vector<Word> words;
};

// Split one line into words, dropping comments and blanks. Appends a
// diagnostic and returns false on a syntax fault.
bool lex(std::string_view text, int line, Block& out, std::vector<Diagnostic>& errors);

// What an arc needs, in the plane's own coordinates (a, b: first and
// second axis as rs274 orders them; m).
struct ArcInput {
  double a0 = 0, b0 = 0;  // start
  double a1 = 0, b1 = 0;  // end
  double i = 0, j = 0;    // centre offsets (or absolute centre)
  bool absolute = false;  // G90.1
  double r = 0;           // R form when has_r
  bool has_r = false;
  bool inch = false;      // for the tolerances, which LinuxCNC sets per unit
  bool clockwise = false;
};

// The centre (ca, cb) of an arc, or false with why in `error`. The
// tolerances are those of the LinuxCNC interpreter Debian ships: a centre
// arc is refused when its end radius differs from its start radius by more
// than 0.0283 mm (0.00283 in) and by more than 0.1 %; an R arc when the
// radius falls short of half the chord by more than 0.00127 mm (0.00005 in).
bool arc_centre(const ArcInput& in, double& ca, double& cb, std::string& error);

}  // namespace cpm::path::detail
