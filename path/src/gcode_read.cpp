// SPDX-License-Identifier: Apache-2.0
// Reading a program: modal state, the order of execution within a block,
// and the canonical moves (gcode.hpp).
#include <array>
#include <cmath>
#include <optional>
#include <sstream>

#include "gcode_internal.hpp"

namespace cpm::path {
namespace {

using detail::Block;
using detail::Word;

constexpr double kInch = 0.0254;  // m

struct State {
  int motion = -1;  // 0..3 for G0..G3; -1: none yet
  Plane plane = Plane::xy;
  Units units = Units::mm;
  bool incremental = false;   // G91
  bool arc_absolute = false;  // G90.1
  double feed = 0.0;          // m/s
  bool feed_set = false;
  Vec3 pos = Vec3::Zero();    // m, program frame
  double scale() const { return units == Units::inch ? kInch : 1e-3; }
};

// A block's words by letter, each at most once (G and M apart).
struct Words {
  std::array<const Word*, 26> by{};
  std::vector<const Word*> g, m;
  [[nodiscard]] const Word* get(char c) const { return by[static_cast<std::size_t>(c - 'A')]; }
  [[nodiscard]] bool has(char c) const { return get(c) != nullptr; }
};

class Reader {
 public:
  Reader(const ReaderOptions& o, Program& p) : opt_(o), prog_(p) { st_.pos = o.start; }
  void block(const Block& b);
  std::vector<Diagnostic> errors;
  bool ended = false;

 private:
  void fail(int column, const std::string& why) { errors.push_back(Diagnostic{line_, column, why}); }
  bool classify(const Block& b, Words& w);
  bool check_letter(const Word& wd);
  bool g_codes(const Words& w, std::optional<int>& motion, bool& dwell);
  void modes(const Words& w);
  void dwell(const Words& w, const Word& g4);
  void motion(const Words& w, int mode, const Word* mode_word);
  Vec3 end_point(const Words& w) const;
  bool feed_ok(const Word& at);
  bool arc(const Words& w, int mode, CanonicalMove& mv);

  const ReaderOptions& opt_;
  Program& prog_;
  State st_;
  int line_ = 0;
  int first_column_ = 0;
};

bool Reader::check_letter(const Word& wd) {
  switch (wd.letter) {
    case 'G': case 'M': case 'F': case 'N': case 'P': case 'X': case 'Y': case 'Z':
    case 'I': case 'J': case 'K': case 'R':
      return true;
    case 'S': fail(wd.column, "unknown word S: this machine has no spindle"); return false;
    case 'T': fail(wd.column, "unknown word T: this machine has no tool changer"); return false;
    case 'A': case 'B': case 'C': case 'U': case 'V': case 'W':
      fail(wd.column, std::string("unknown word ") + wd.letter + ": this machine has only the axes X, Y and Z");
      return false;
    default:
      fail(wd.column, std::string("unknown word ") + wd.letter);
      return false;
  }
}

bool Reader::classify(const Block& b, Words& w) {
  bool ok = true;
  for (const Word& wd : b.words) {
    if (!check_letter(wd)) {
      ok = false;
      continue;
    }
    if (wd.letter == 'G') w.g.push_back(&wd);
    else if (wd.letter == 'M') w.m.push_back(&wd);
    else if (w.has(wd.letter)) fail(wd.column, std::string("word ") + wd.letter + " given twice in one block"), ok = false;
    else w.by[static_cast<std::size_t>(wd.letter - 'A')] = &wd;
  }
  if (w.m.size() > 1) fail(w.m[1]->column, "one M word per block"), ok = false;
  for (const Word* m : w.m)
    if (m->value != 2.0 && m->value != 30.0) {
      std::ostringstream o;
      o << "unknown word M" << m->value << " (M2 and M30 end a program; nothing else is supported)";
      fail(m->column, o.str());
      ok = false;
    }
  return ok;
}

// Modal group of a G code (x10: G90.1 is 901), -1 when not supported.
int group_of(int code) {
  switch (code) {
    case 0: case 10: case 20: case 30: return 1;                // motion
    case 40: return 0;                                           // dwell, non-modal
    case 170: case 180: case 190: return 2;                      // plane
    case 200: case 210: return 6;                                // units
    case 900: case 910: return 3;                                // distance
    case 901: case 911: return 4;                                // arc distance
    case 610: case 640: return 13;                               // path control
    case 400: case 490: case 540: case 800: case 940: return 100;  // restate what is in force
    default: return -1;
  }
}

bool Reader::g_codes(const Words& w, std::optional<int>& motion, bool& dwell) {
  std::array<const Word*, 101> seen{};
  bool ok = true;
  for (const Word* g : w.g) {
    const int code = static_cast<int>(std::lround(g->value * 10.0));
    const int grp = std::abs(g->value * 10.0 - code) < 1e-6 ? group_of(code) : -1;
    if (grp < 0) {
      std::ostringstream o;
      o << "G" << g->value << " is not supported";
      fail(g->column, o.str());
      ok = false;
      continue;
    }
    if (grp != 100 && seen[static_cast<std::size_t>(grp)]) {
      fail(g->column, "two G codes of one modal group in a block");
      ok = false;
    }
    seen[static_cast<std::size_t>(grp)] = g;
    if (grp == 1) motion = code / 10;
    if (grp == 0) dwell = true;
  }
  return ok;
}

// Feed, plane, units, path control and distance modes, in the RS274NGC order.
void Reader::modes(const Words& w) {
  for (const Word* g : w.g)
    if (std::lround(g->value * 10.0) == 940) st_.feed = 0.0, st_.feed_set = true;  // G94 clears the feed, as LinuxCNC does
  if (const Word* f = w.get('F')) {
    if (f->value < 0.0) fail(f->column, "a feed must not be negative");
    st_.feed = f->value * st_.scale() / 60.0;  // units/min in the units before this block's G20/G21
    st_.feed_set = true;
  }
  for (const Word* g : w.g) {
    const int code = static_cast<int>(std::lround(g->value * 10.0));
    if (code == 170) st_.plane = Plane::xy;
    if (code == 180) st_.plane = Plane::zx;
    if (code == 190) st_.plane = Plane::yz;
    if (code == 200 || code == 210) {
      const Units u = code == 200 ? Units::inch : Units::mm;
      st_.units = u;
    }
    if (code == 610) prog_.tolerance = 0.0;
    if (code == 640 && w.has('P')) prog_.tolerance = std::abs(w.get('P')->value) * st_.scale();
    if (code == 900 || code == 910) st_.incremental = code == 910;
    if (code == 901 || code == 911) st_.arc_absolute = code == 901;
  }
}

void Reader::dwell(const Words& w, const Word& g4) {
  const Word* p = w.get('P');
  if (!p || p->value < 0.0) {
    fail(g4.column, "G4 needs P, the dwell in seconds (>= 0)");
    return;
  }
  CanonicalMove mv;
  mv.kind = MoveKind::dwell;
  mv.line = line_;
  mv.column = g4.column;
  mv.start = mv.end = st_.pos;
  mv.dwell = p->value;
  mv.units = st_.units;
  prog_.moves.push_back(mv);
}

Vec3 Reader::end_point(const Words& w) const {
  Vec3 e = st_.pos;
  const char axes[3] = {'X', 'Y', 'Z'};
  for (int k = 0; k < 3; ++k)
    if (const Word* a = w.get(axes[k])) e[k] = (st_.incremental ? st_.pos[k] : 0.0) + a->value * st_.scale();
  return e;
}

bool Reader::feed_ok(const Word& at) {
  if (st_.feed > 0.0) return true;
  fail(at.column, st_.feed_set ? "the feed is zero: set F > 0 before a G1, G2 or G3"
                               : "no feed: set F before the first G1, G2 or G3");
  return false;
}

// A plane's axes in rs274's order (first, second, normal) and its centre
// words (first, second, and the one it refuses).
constexpr std::array<std::array<int, 3>, 3> kAxes{{{0, 1, 2}, {2, 0, 1}, {1, 2, 0}}};
constexpr std::array<std::array<char, 3>, 3> kCentre{{{'I', 'J', 'K'}, {'K', 'I', 'J'}, {'J', 'K', 'I'}}};
constexpr std::array<const char*, 3> kPlaneName{"XY plane (G17)", "ZX plane (G18)", "YZ plane (G19)"};

// Column of the first of the given words present, else `fallback`.
int column_of(const Words& w, std::string_view letters, int fallback) {
  int col = 0;
  for (char c : letters)
    if (const Word* wd = w.get(c); wd && (col == 0 || wd->column < col)) col = wd->column;
  return col ? col : fallback;
}

bool arc_words_ok(const Words& w, Plane plane, bool absolute, int col, std::vector<Diagnostic>& errors, int line) {
  const auto& c = kCentre[static_cast<std::size_t>(plane)];
  const auto fail = [&](const Word* at, const std::string& why) {
    errors.push_back(Diagnostic{line, at ? at->column : col, why});
    return false;
  };
  if (w.has(c[2]))
    return fail(w.get(c[2]), std::string(1, c[2]) + " is not a centre word of an arc in the " +
                                 kPlaneName[static_cast<std::size_t>(plane)]);
  const bool centre = w.has(c[0]) || w.has(c[1]);
  if (w.has('R') && centre) return fail(w.get('R'), "an arc takes R or I, J, K, not both");
  if (!w.has('R') && !centre) return fail(nullptr, "an arc needs its centre (I, J, K) or its radius (R)");
  if (absolute && centre && !(w.has(c[0]) && w.has(c[1])))
    return fail(nullptr, std::string("with G90.1 an arc needs both ") + c[0] + " and " + c[1]);
  if (const Word* p = w.get('P'); p && (p->value < 1.0 || p->value != std::floor(p->value)))
    return fail(p, "an arc's P (turns) must be a whole number >= 1");
  return true;
}

bool Reader::arc(const Words& w, int mode, CanonicalMove& mv) {
  const auto pl = static_cast<std::size_t>(st_.plane);
  if (!arc_words_ok(w, st_.plane, st_.arc_absolute, mv.column, errors, line_)) return false;
  const auto& ax = kAxes[pl];
  const auto& c = kCentre[pl];
  detail::ArcInput in;
  in.a0 = mv.start[ax[0]], in.b0 = mv.start[ax[1]], in.a1 = mv.end[ax[0]], in.b1 = mv.end[ax[1]];
  in.i = w.has(c[0]) ? w.get(c[0])->value * st_.scale() : 0.0;
  in.j = w.has(c[1]) ? w.get(c[1])->value * st_.scale() : 0.0;
  in.absolute = st_.arc_absolute;
  in.has_r = w.has('R');
  in.r = in.has_r ? w.get('R')->value * st_.scale() : 0.0;
  in.inch = st_.units == Units::inch;
  in.clockwise = mode == 2;
  double ca = 0.0, cb = 0.0;
  std::string why;
  if (!detail::arc_centre(in, ca, cb, why)) {
    fail(column_of(w, in.has_r ? std::string_view("R") : std::string_view(c.data(), 2), mv.column), why);
    return false;
  }
  mv.kind = MoveKind::arc;
  mv.plane = st_.plane;
  mv.centre = mv.start;
  mv.centre[ax[0]] = ca;
  mv.centre[ax[1]] = cb;
  const int turns = w.has('P') ? static_cast<int>(w.get('P')->value) : 1;
  mv.turn = (mode == 3 ? 1 : -1) * turns;
  return true;
}

void Reader::motion(const Words& w, int mode, const Word* mode_word) {
  CanonicalMove mv;
  mv.line = line_;
  mv.column = column_of(w, "XYZ", mode_word ? mode_word->column : first_column_);
  mv.units = st_.units;
  mv.start = st_.pos;
  mv.end = end_point(w);
  st_.pos = mv.end;
  mv.kind = mode == 0 ? MoveKind::traverse : MoveKind::feed;
  if (mode >= 1) {
    const Word* at = w.has('F') ? w.get('F') : mode_word;
    if (!feed_ok(at ? *at : Word{'G', 0.0, mv.column})) return;
    mv.feed = st_.feed;
  }
  if (mode >= 2 && !arc(w, mode, mv)) return;
  prog_.moves.push_back(mv);
}

void Reader::block(const Block& b) {
  line_ = b.line;
  if (b.words.empty()) return;
  first_column_ = b.words.front().column;
  Words w;
  std::optional<int> mode;
  bool g4 = false;
  const bool letters_ok = classify(b, w);
  if (!g_codes(w, mode, g4) || !letters_ok) return;
  modes(w);
  const Word* mode_word = nullptr;
  for (const Word* g : w.g)
    if (g->value == 4.0 && g4) dwell(w, *g);
    else if (mode && std::lround(g->value * 10.0) == *mode * 10) mode_word = g;
  if (mode) st_.motion = *mode;
  const bool axes = w.has('X') || w.has('Y') || w.has('Z');
  const bool arc_words = w.has('I') || w.has('J') || w.has('K') || w.has('R');
  const int col = column_of(w, "XYZIJKR", first_column_);
  if (axes && g4 && !mode) fail(col, "G4 takes no axis words");
  else if ((axes || arc_words) && st_.motion < 0) fail(col, "axis words without a motion: G0, G1, G2 or G3 first");
  else if (arc_words && st_.motion < 2) fail(column_of(w, "IJKR", col), "I, J, K and R belong to arcs (G2, G3)");
  else if (axes || arc_words) motion(w, st_.motion, mode_word);
  if (!w.m.empty()) ended = true;
}

}  // namespace

ProgramError::ProgramError(const std::string& name, std::vector<Diagnostic> diagnostics)
    : Error([&] {
        std::ostringstream o;
        for (std::size_t k = 0; k < diagnostics.size(); ++k)
          o << (k ? "\n" : "") << name << ":" << diagnostics[k].line << ":" << diagnostics[k].column << ": "
            << diagnostics[k].message;
        return o.str();
      }()),
      diagnostics_(std::move(diagnostics)) {}

// A line holding only '%': a program may open with one, and then ends at the next.
bool percent_line(std::string_view line) {
  const std::size_t a = line.find_first_not_of(" \t\r");
  return a != std::string_view::npos && line[a] == '%' && line.find_first_not_of(" \t\r", a + 1) == std::string_view::npos;
}

Program read_program(std::string_view text, const ReaderOptions& options) {
  Program prog;
  prog.start = options.start;
  Reader r(options, prog);
  int line = 0;
  bool any = false, percent = false;
  int opened = 0;
  for (std::size_t at = 0; !r.ended && static_cast<int>(r.errors.size()) < options.max_errors;) {
    const std::size_t nl = text.find('\n', at);
    const std::string_view ln = text.substr(at, nl == std::string_view::npos ? std::string_view::npos : nl - at);
    ++line;
    if (percent_line(ln) && (!any || percent)) {
      r.ended = percent;  // the closing '%' ends the program
      if (!percent) opened = line;
      percent = any = true;
    } else {
      any = any || ln.find_first_not_of(" \t\r") != std::string_view::npos;
      detail::Block b;
      if (detail::lex(ln, line, b, r.errors)) r.block(b);
    }
    if (nl == std::string_view::npos) break;
    at = nl + 1;
  }
  if (percent && !r.ended)
    r.errors.push_back(Diagnostic{opened, 1, "the program opens with '%' but neither M2, M30 nor '%' ends it"});
  prog.ended = r.ended;
  if (!r.errors.empty()) throw ProgramError(options.name, std::move(r.errors));
  return prog;
}

Vec3 plane_normal(Plane plane) noexcept {
  return plane == Plane::xy ? Vec3::UnitZ() : plane == Plane::zx ? Vec3::UnitY() : Vec3::UnitX();
}

}  // namespace cpm::path
