// SPDX-License-Identifier: Apache-2.0
// The measurement files of docs/data-formats.md: CSV with `#`
// comments, `# key = value` metadata and a header of column names.
//
// The reader is one pass over lines (string_views into the file's bytes) and
// std::from_chars on the columns it needs: a 60 000-row motion log reads in
// a few tens of milliseconds (bench/bench_io.cpp).
#include "cpm/io/data_files.hpp"

#include <cctype>
#include <cmath>
#include <cstring>
#include <optional>
#include <sstream>
#include <type_traits>

#include "cpm/io/model_file.hpp"
#include "util.hpp"

namespace cpm::io {

using detail::trim;

const char* kind_name(DataKind k) noexcept {
  switch (k) {
    case DataKind::ballbar: return "ballbar";
    case DataKind::position: return "position";
    case DataKind::motion: return "motion";
  }
  return "?";
}

namespace {

// Every column any layout knows. Values index `Table::cols`.
enum Col : int {
  c_t, c_d1, c_d2, c_d3, c_length, c_px, c_py, c_pz, c_v1, c_v2, c_v3, c_f1, c_f2, c_f3,
  c_a1, c_a2, c_a3, c_dir1, c_dir2, c_dir3, c_run, c_count
};
constexpr const char* kColName[c_count] = {
    "t",  "d1", "d2", "d3", "length", "px", "py", "pz", "v1",   "v2",   "v3",
    "f1", "f2", "f3", "a1", "a2",     "a3", "dir1", "dir2", "dir3", "run"};

// The SI unit of each column, which a header may state: "d1 (m)", "f1 [N]".
constexpr const char* kColUnit[c_count] = {"s", "m", "m", "m", "m", "m", "m", "m", "m/s", "m/s", "m/s",
                                           "N", "N", "N", "m/s^2", "m/s^2", "m/s^2", "1", "1", "1", "1"};

bool unit_matches(std::string_view given, const char* si) {
  std::string g;
  for (char ch : given)
    if (ch != ' ') g.push_back(ch);
  const std::string want = si;
  if (g == want) return true;
  if (want == "m/s^2") return g == "m/s2" || g == "m/s\xC2\xB2" || g == "m*s^-2";
  if (want == "1") return g.empty() || g == "-";
  return false;
}

// "d1 (m)" -> name "d1", unit "m"; "d1" -> name "d1", no unit.
void split_unit(std::string_view field, std::string_view& name, std::optional<std::string_view>& unit) {
  name = field;
  unit.reset();
  if (field.empty()) return;
  const char close = field.back();
  const char open = close == ')' ? '(' : close == ']' ? '[' : 0;
  if (!open) return;
  const std::size_t at = field.rfind(open);
  if (at == std::string_view::npos || at == 0) return;
  name = trim(field.substr(0, at));
  unit = trim(field.substr(at + 1, field.size() - at - 2));
}

struct Layout {
  std::vector<Col> required;
  std::vector<Col> optional;
};

const Layout& layout(DataKind k) {
  static const Layout ballbar{{c_d1, c_d2, c_d3, c_length}, {c_t, c_dir1, c_dir2, c_dir3, c_run}};
  static const Layout position{{c_d1, c_d2, c_d3, c_px, c_py, c_pz},
                               {c_t, c_dir1, c_dir2, c_dir3, c_run}};
  static const Layout motion{{c_t, c_d1, c_d2, c_d3, c_v1, c_v2, c_v3, c_f1, c_f2, c_f3},
                             {c_a1, c_a2, c_a3, c_run}};
  switch (k) {
    case DataKind::ballbar: return ballbar;
    case DataKind::position: return position;
    case DataKind::motion: return motion;
  }
  return ballbar;
}

std::optional<DataKind> kind_from_name(std::string_view s) {
  if (s == "ballbar") return DataKind::ballbar;
  if (s == "position") return DataKind::position;
  if (s == "motion") return DataKind::motion;
  return std::nullopt;
}

// A field without surrounding spaces or double quotes (spreadsheet exports).
std::string_view clean_field(std::string_view f) {
  f = trim(f);
  if (f.size() >= 2 && f.front() == '"' && f.back() == '"') f = trim(f.substr(1, f.size() - 2));
  return f;
}

bool is_metadata_key(std::string_view k) {
  if (k.empty() || !std::isalpha(static_cast<unsigned char>(k[0]))) return false;
  for (char ch : k)
    if (!std::isalnum(static_cast<unsigned char>(ch)) && ch != '_' && ch != '-' && ch != '.')
      return false;
  return true;
}

struct Line {
  std::string_view text;
  int number;  // 1-based
};

// The file split into metadata, header and data lines, before any number is read.
struct Table {
  std::string name;
  FileInfo info;
  std::map<std::string, int> meta_line;  // line of each metadata key
  Line header{{}, 0};
  std::vector<std::string_view> header_fields;
  std::vector<Line> rows;
  std::optional<DataKind> kind;
  // Parsed columns (only those the layout knows and the header has).
  std::array<std::vector<double>, c_count> cols;
  std::array<bool, c_count> present{};

  [[noreturn]] void fail(int line, const std::string& what) const {
    throw Error(line > 0 ? name + ":" + std::to_string(line) + ": " + what : name + ": " + what);
  }
  [[noreturn]] void fail_meta(const std::string& key, const std::string& what) const {
    const auto it = meta_line.find(key);
    fail(it == meta_line.end() ? 0 : it->second, "metadata '" + key + "': " + what);
  }
};

void split_lines(Table& tb, std::string_view text) {
  // A UTF-8 byte order mark is not part of the first line.
  if (text.size() >= 3 && std::memcmp(text.data(), "\xEF\xBB\xBF", 3) == 0) text.remove_prefix(3);
  int number = 0;
  std::size_t pos = 0;
  while (pos < text.size()) {
    std::size_t end = text.find('\n', pos);
    if (end == std::string_view::npos) end = text.size();
    std::string_view line = text.substr(pos, end - pos);
    pos = end + 1;
    ++number;
    if (!line.empty() && line.back() == '\r') line.remove_suffix(1);
    const std::string_view t = trim(line);
    if (t.empty()) continue;  // blank lines carry nothing (trailing ones are common)
    if (t.front() == '#') {
      std::string_view body = trim(t.substr(1));
      const std::size_t eq = body.find('=');
      if (eq == std::string_view::npos) continue;
      const std::string_view key = trim(body.substr(0, eq));
      if (!is_metadata_key(key)) continue;  // an ordinary comment that happens to hold '='
      const std::string k(key);
      const std::string v(trim(body.substr(eq + 1)));
      // A lone CR (not a CRLF line end) would make a value no writer can
      // write back (found by fuzz/targets/csv_data.cpp).
      if (v.find('\r') != std::string::npos)
        tb.fail(number, "metadata '" + k + "': the value holds a carriage return; a value is one line");
      if (const auto it = tb.info.metadata.find(k); it != tb.info.metadata.end()) {
        if (it->second != v)
          tb.fail(number, "metadata '" + k + "' given twice with different values (first on line " +
                              std::to_string(tb.meta_line[k]) + ": '" + it->second + "', here: '" +
                              v + "')");
        continue;
      }
      tb.info.metadata.emplace(k, v);
      tb.meta_line.emplace(k, number);
      continue;
    }
    if (tb.header.number == 0)
      tb.header = {t, number};
    else
      tb.rows.push_back({t, number});
  }
}

std::vector<std::string_view> split_fields(std::string_view line) {
  std::vector<std::string_view> out;
  std::size_t pos = 0;
  for (;;) {
    const std::size_t c = line.find(',', pos);
    out.push_back(clean_field(line.substr(pos, c == std::string_view::npos ? line.npos : c - pos)));
    if (c == std::string_view::npos) break;
    pos = c + 1;
  }
  return out;
}

void read_kind(Table& tb) {
  const auto it = tb.info.metadata.find("kind");
  if (it == tb.info.metadata.end())
    tb.fail(0, "no '# kind = ...' line: the file must say which layout it is "
               "(ballbar, position or motion; docs/data-formats.md)");
  tb.kind = kind_from_name(it->second);
  if (!tb.kind)
    tb.fail_meta("kind", "'" + it->second + "' is not one of ballbar, position, motion");
}

void parse_rows(Table& tb) {
  if (tb.header.number == 0) tb.fail(0, "empty file: no header line and no data");
  tb.header_fields = split_fields(tb.header.text);
  const Layout& lay = layout(*tb.kind);
  auto known = [&](Col c) {
    for (Col r : lay.required)
      if (r == c) return true;
    for (Col o : lay.optional)
      if (o == c) return true;
    return false;
  };
  // Map each field of the header to a column slot (-1: ignored).
  {
    // A file without a header: its first row would be taken for one.
    bool numeric = true;
    double v;
    for (const auto f : tb.header_fields) numeric = numeric && detail::parse_double(f, v);
    if (numeric)
      tb.fail(tb.header.number, "this line holds numbers, not column names: the first line that is "
                                "not a comment must be the header (e.g. d1,d2,d3,...)");
  }
  std::vector<int> slot(tb.header_fields.size(), -1);
  for (std::size_t j = 0; j < tb.header_fields.size(); ++j) {
    const std::string_view nm = tb.header_fields[j];
    if (nm.empty())
      tb.fail(tb.header.number, "column " + std::to_string(j + 1) + " of the header has no name");
    for (std::size_t k = 0; k < j; ++k)
      if (tb.header_fields[k] == nm)
        tb.fail(tb.header.number, "column '" + std::string(nm) + "' appears twice in the header");
    std::string_view base;
    std::optional<std::string_view> unit;
    split_unit(nm, base, unit);
    int c = -1;
    for (int k = 0; k < c_count; ++k)
      if (base == kColName[k]) c = k;
    if (c >= 0 && known(static_cast<Col>(c))) {
      if (unit && !unit_matches(*unit, kColUnit[c]))
        tb.fail(tb.header.number, "column '" + std::string(nm) + "': the unit '" + std::string(*unit) +
                                      "' is not " + kColName[c] + "'s SI unit (" + kColUnit[c] +
                                      "); these files are in SI units, convert the column");
      if (tb.present[c])
        tb.fail(tb.header.number, "column '" + std::string(base) + "' appears twice in the header");
      slot[j] = c;
      tb.present[c] = true;
    } else {
      tb.info.warnings.push_back(tb.name + ":" + std::to_string(tb.header.number) + ": column '" +
                                 std::string(nm) + "' is not part of the " + kind_name(*tb.kind) +
                                 " layout; ignored");
    }
  }
  if (tb.header_fields.size() == 1) {
    for (const char sep : {';', '\t', ' '})
      if (tb.header.text.find(sep) != std::string_view::npos)
        tb.fail(tb.header.number, std::string("the header is not comma separated (it holds '") +
                                      (sep == '\t' ? "\\t" : std::string(1, sep)) +
                                      "'): columns are separated by commas");
  }
  for (Col r : lay.required)
    if (!tb.present[r]) {
      for (const auto f : tb.header_fields) {
        std::string low(f);
        for (char& ch : low) ch = static_cast<char>(std::tolower(static_cast<unsigned char>(ch)));
        if (low == kColName[r])
          tb.fail(tb.header.number, std::string("required column '") + kColName[r] +
                                        "' is missing (the header has '" + std::string(f) +
                                        "': column names are lower case)");
      }
      std::string needs;
      for (Col q : lay.required) {
        if (!needs.empty()) needs.push_back(',');
        needs.append(kColName[q]);
      }
      tb.fail(tb.header.number, std::string("required column '") + kColName[r] + "' is missing (a " +
                                    kind_name(*tb.kind) + " file needs " + needs + ")");
    }
  // Columns that only mean something together.
  for (const auto& group : {std::array<Col, 3>{c_dir1, c_dir2, c_dir3}, std::array<Col, 3>{c_a1, c_a2, c_a3}}) {
    const int n = tb.present[group[0]] + tb.present[group[1]] + tb.present[group[2]];
    if (n != 0 && n != 3)
      for (Col c : group)
        if (!tb.present[c])
          tb.fail(tb.header.number, std::string("column '") + kColName[c] + "' is missing: " +
                                        kColName[group[0]] + ".." + kColName[group[2]] +
                                        " come all three or not at all");
  }
  if (tb.rows.empty())
    tb.fail(tb.header.number, "no data: the header is not followed by any row");

  const std::size_t n = tb.rows.size();
  for (int c = 0; c < c_count; ++c)
    if (tb.present[c]) tb.cols[c].resize(n);
  tb.info.line_of_row.resize(n);
  const std::size_t nf = tb.header_fields.size();
  for (std::size_t r = 0; r < n; ++r) {
    const Line& ln = tb.rows[r];
    tb.info.line_of_row[r] = ln.number;
    std::string_view rest = ln.text;
    std::size_t j = 0;
    auto repeated_header = [&] {
      const auto f = split_fields(ln.text);
      return f == tb.header_fields;
    };
    for (;; ++j) {
      const std::size_t comma = rest.find(',');
      const std::string_view raw = comma == std::string_view::npos ? rest : rest.substr(0, comma);
      if (j < nf && slot[j] >= 0) {
        const int c = slot[j];
        const std::string_view f = clean_field(raw);
        double v;
        if (!detail::parse_double(f, v)) {
          if (repeated_header())
            tb.fail(ln.number, "the header line is repeated here (first on line " +
                                   std::to_string(tb.header.number) + "): two files joined together?");
          if (f.empty()) tb.fail(ln.number, std::string("column '") + kColName[c] + "': empty value");
          tb.fail(ln.number, std::string("column '") + kColName[c] + "': '" + std::string(f) +
                                 "' is not a number");
        }
        if (!std::isfinite(v))
          tb.fail(ln.number, std::string("column '") + kColName[c] + "': '" + std::string(f) +
                                 "' is not a finite number (NaN and infinity are refused)");
        if ((c == c_dir1 || c == c_dir2 || c == c_dir3) && v != 1.0 && v != -1.0)
          tb.fail(ln.number, std::string("column '") + kColName[c] + "': '" + std::string(f) +
                                 "' is not a direction (must be -1 or +1)");
        if (c == c_run && (v != std::floor(v) || std::abs(v) > 9.0e15))
          tb.fail(ln.number, std::string("column 'run': '") + std::string(f) + "' is not an integer");
        if (c == c_length && !(v > 0.0))
          tb.fail(ln.number, std::string("column 'length': '") + std::string(f) +
                                 "' is not a bar length (must be > 0 m)");
        tb.cols[c][r] = v;
      }
      if (comma == std::string_view::npos) break;
      rest.remove_prefix(comma + 1);
    }
    if (j + 1 != nf) {
      if (repeated_header())
        tb.fail(ln.number, "the header line is repeated here (first on line " +
                               std::to_string(tb.header.number) + ")");
      tb.fail(ln.number, std::to_string(j + 1) + " fields, but the header (line " +
                             std::to_string(tb.header.number) + ") has " + std::to_string(nf) +
                             " columns");
    }
  }
  // Catch the commonest unit mistake (millimetres) without refusing the file.
  double dmax = 0.0;
  for (Col c : {c_d1, c_d2, c_d3})
    for (double v : tb.cols[c]) dmax = std::max(dmax, std::abs(v));
  if (dmax > 5.0)
    tb.info.warnings.push_back(tb.name + ": actuator displacements reach " + detail::format_double(dmax) +
                               " m: are they in millimetres? These files are in metres (SI)");
}

Table make_table(const std::string& text, const std::string& name) {
  Table tb;
  tb.name = name;
  tb.info.path = name;
  split_lines(tb, text);
  read_kind(tb);
  return tb;
}

std::vector<Vec3> vec3s(const Table& tb, Col a, Col b, Col c) {
  std::vector<Vec3> out;
  if (!tb.present[a]) return out;
  const std::size_t n = tb.cols[a].size();
  out.resize(n);
  for (std::size_t i = 0; i < n; ++i) out[i] = Vec3(tb.cols[a][i], tb.cols[b][i], tb.cols[c][i]);
  return out;
}

std::vector<long> runs(const Table& tb) {
  std::vector<long> out;
  if (!tb.present[c_run]) return out;
  out.reserve(tb.cols[c_run].size());
  for (double v : tb.cols[c_run]) out.push_back(static_cast<long>(v));
  return out;
}

CommonColumns common(const Table& tb) {
  CommonColumns cc;
  if (tb.present[c_t]) cc.t = tb.cols[c_t];
  if (tb.present[c_dir1]) {
    const std::size_t n = tb.cols[c_dir1].size();
    cc.dir.resize(n);
    for (std::size_t i = 0; i < n; ++i)
      for (int k = 0; k < 3; ++k)
        cc.dir[i][k] = static_cast<std::int8_t>(tb.cols[c_dir1 + k][i]);
  }
  cc.run = runs(tb);
  return cc;
}

double meta_number(const Table& tb, const std::string& key) {
  const std::string& s = tb.info.metadata.at(key);
  double v;
  if (!detail::parse_double(s, v)) tb.fail_meta(key, "'" + s + "' is not a number");
  if (!std::isfinite(v)) tb.fail_meta(key, "'" + s + "' is not a finite number");
  return v;
}

BallbarData to_ballbar(Table& tb) {
  parse_rows(tb);
  BallbarData out;
  const auto& md = tb.info.metadata;
  const auto pv = md.find("pivot");
  if (pv == md.end())
    tb.fail(0, "no '# pivot = x y z' line: a ballbar file needs the nominal position of the "
               "fixed ball (m, machine frame)");
  {
    std::string s = pv->second;
    for (char& ch : s)
      if (ch == ',' || ch == '\t') ch = ' ';
    std::vector<double> v;
    std::size_t pos = 0;
    while (pos < s.size()) {
      while (pos < s.size() && s[pos] == ' ') ++pos;
      if (pos >= s.size()) break;
      std::size_t e = s.find(' ', pos);
      if (e == std::string::npos) e = s.size();
      double x;
      const std::string_view f(s.data() + pos, e - pos);
      if (!detail::parse_double(f, x) || !std::isfinite(x))
        tb.fail_meta("pivot", "'" + std::string(f) + "' is not a finite number (expected 'x y z' in m)");
      v.push_back(x);
      pos = e;
    }
    if (v.size() != 3)
      tb.fail_meta("pivot", "expected 3 numbers 'x y z' (m), got " + std::to_string(v.size()));
    out.pivot = Vec3(v[0], v[1], v[2]);
  }
  if (const auto it = md.find("length_offset_known"); it != md.end()) {
    std::string s = it->second;
    for (char& ch : s) ch = static_cast<char>(std::tolower(static_cast<unsigned char>(ch)));
    if (s == "true")
      out.length_offset_known = true;
    else if (s == "false")
      out.length_offset_known = false;
    else
      tb.fail_meta("length_offset_known", "'" + it->second + "' must be true or false");
  }
  out.d = vec3s(tb, c_d1, c_d2, c_d3);
  out.length = tb.cols[c_length];
  out.extra = common(tb);
  double lmax = 0.0;
  for (double v : out.length) lmax = std::max(lmax, v);
  if (lmax > 5.0)
    tb.info.warnings.push_back(tb.name + ": bar lengths reach " + detail::format_double(lmax) +
                               " m: are they in millimetres? These files are in metres (SI)");
  out.info = std::move(tb.info);
  return out;
}

PositionData to_position(Table& tb) {
  parse_rows(tb);
  PositionData out;
  if (tb.info.metadata.count("sigma")) {
    out.sigma = meta_number(tb, "sigma");
    if (out.sigma < 0.0) tb.fail_meta("sigma", "a standard deviation must be >= 0 m");
  }
  out.d = vec3s(tb, c_d1, c_d2, c_d3);
  out.p = vec3s(tb, c_px, c_py, c_pz);
  out.extra = common(tb);
  out.info = std::move(tb.info);
  return out;
}

MotionData to_motion(Table& tb) {
  parse_rows(tb);
  MotionData out;
  if (tb.info.metadata.count("rate")) {
    out.rate = meta_number(tb, "rate");
    if (!(out.rate > 0.0)) tb.fail_meta("rate", "a sample rate must be > 0 Hz");
  }
  out.t = tb.cols[c_t];
  out.d = vec3s(tb, c_d1, c_d2, c_d3);
  out.v = vec3s(tb, c_v1, c_v2, c_v3);
  out.f = vec3s(tb, c_f1, c_f2, c_f3);
  out.a = vec3s(tb, c_a1, c_a2, c_a3);
  out.run = runs(tb);
  // Time that runs backwards inside a run breaks every filter of the tools:
  // say where, without refusing a log that may be several joined on purpose.
  std::size_t backwards = 0, first = 0;
  for (std::size_t k = 1; k < out.t.size(); ++k)
    if (out.t[k] <= out.t[k - 1] && (out.run.empty() || out.run[k] == out.run[k - 1]))
      if (backwards++ == 0) first = k;
  if (backwards)
    tb.info.warnings.push_back(tb.name + ":" + std::to_string(tb.info.line_of_row[first]) +
                               ": t does not increase (" + detail::format_double(out.t[first - 1]) +
                               " s, then " + detail::format_double(out.t[first]) + " s) within a run; " +
                               std::to_string(backwards) + " such step(s) in the file");
  out.info = std::move(tb.info);
  return out;
}

// The kind check of read_ballbar & co.: names what the file says it is.
void expect_kind(const Table& tb, DataKind want) {
  if (*tb.kind != want)
    tb.fail_meta("kind", std::string("this is a ") + kind_name(*tb.kind) + " file, but a " +
                             kind_name(want) + " file was expected");
}

template <class T, class F>
T read_kind_file(const std::string& path, DataKind want, F convert) {
  const std::string text = detail::read_whole_file(path);
  Table tb = make_table(text, path);
  expect_kind(tb, want);
  return convert(tb);
}

}  // namespace

DataSet parse_data(const std::string& text, const std::string& name) {
  Table tb = make_table(text, name);
  switch (*tb.kind) {
    case DataKind::ballbar: return to_ballbar(tb);
    case DataKind::position: return to_position(tb);
    case DataKind::motion: return to_motion(tb);
  }
  throw Error(name + ": unknown kind");
}

DataSet read_data_file(const std::string& path) {
  return parse_data(detail::read_whole_file(path), path);
}

BallbarData read_ballbar(const std::string& path) {
  return read_kind_file<BallbarData>(path, DataKind::ballbar, to_ballbar);
}
PositionData read_position(const std::string& path) {
  return read_kind_file<PositionData>(path, DataKind::position, to_position);
}
MotionData read_motion(const std::string& path) {
  return read_kind_file<MotionData>(path, DataKind::motion, to_motion);
}

// ---------------------------------------------------------------- writers

namespace {

void check_size(const std::string& path, const char* what, std::size_t got, std::size_t n) {
  if (got != n)
    throw Error(path + ": cannot write: column '" + what + "' has " + std::to_string(got) +
                " values but there are " + std::to_string(n) + " rows");
}

void put(std::string& out, const std::string& path, std::size_t row, const char* col, double v) {
  if (!std::isfinite(v))
    throw Error(path + ": cannot write: row " + std::to_string(row + 1) + ", column '" + col +
                "' is not a finite number (the reader would refuse the file)");
  out.push_back(',');
  detail::append_double(out, v);
}

// Metadata lines: the struct's own fields first, then the rest of info.metadata.
std::string metadata_block(const std::string& path, DataKind kind,
                           const std::vector<std::pair<std::string, std::string>>& own,
                           const std::map<std::string, std::string>& extra) {
  std::string out = std::string("# kind = ") + kind_name(kind) + "\n";
  for (const auto& [k, v] : own) out += "# " + k + " = " + v + "\n";
  for (const auto& [k, v] : extra) {
    if (k == "kind") continue;
    bool own_key = false;
    for (const auto& o : own) own_key |= (o.first == k);
    if (own_key) continue;
    if (!is_metadata_key(k) || v.find_first_of("\r\n") != std::string::npos)
      throw Error(path + ": cannot write metadata '" + k +
                  "': keys are letters, digits, '_', '-', '.'; values are one line");
    out += "# " + k + " = " + v + "\n";
  }
  return out;
}

void header(std::string& out, std::initializer_list<const char*> names, bool t, bool dir, bool run,
            bool a = false) {
  bool first = true;
  auto add = [&](const char* n) {
    if (!first) out.push_back(',');
    out += n;
    first = false;
  };
  if (t) add("t");
  for (const char* n : names) add(n);
  if (a) {
    add("a1");
    add("a2");
    add("a3");
  }
  if (dir) {
    add("dir1");
    add("dir2");
    add("dir3");
  }
  if (run) add("run");
  out.push_back('\n');
}

// Appends the optional common columns of one row (after the required ones).
void common_tail(std::string& out, const std::string& path, const CommonColumns& cc, std::size_t i) {
  if (!cc.dir.empty())
    for (int k = 0; k < 3; ++k) {
      const int v = cc.dir[i][k];
      if (v != 1 && v != -1)
        throw Error(path + ": cannot write: row " + std::to_string(i + 1) + ", column 'dir" +
                    std::to_string(k + 1) + "' is " + std::to_string(v) + ", not -1 or +1");
      out += v > 0 ? ",1" : ",-1";
    }
  if (!cc.run.empty()) {
    out.push_back(',');
    out += std::to_string(cc.run[i]);
  }
}

void check_common(const std::string& path, const CommonColumns& cc, std::size_t n) {
  if (!cc.t.empty()) check_size(path, "t", cc.t.size(), n);
  if (!cc.dir.empty()) check_size(path, "dir1..dir3", cc.dir.size(), n);
  if (!cc.run.empty()) check_size(path, "run", cc.run.size(), n);
}

void check_rows(const std::string& path, std::size_t n) {
  if (n == 0) throw Error(path + ": cannot write: no rows (the reader refuses a file without data)");
}

std::string vec_text(const Vec3& v) {
  return detail::format_double(v.x()) + " " + detail::format_double(v.y()) + " " +
         detail::format_double(v.z());
}

}  // namespace

std::string render_ballbar(const BallbarData& data, const std::string& path) {
  const std::size_t n = data.d.size();
  check_rows(path, n);
  check_size(path, "length", data.length.size(), n);
  check_common(path, data.extra, n);
  if (!data.pivot.allFinite()) throw Error(path + ": cannot write: pivot is not finite");
  std::string out = metadata_block(
      path, DataKind::ballbar,
      {{"pivot", vec_text(data.pivot)},
       {"length_offset_known", data.length_offset_known ? "true" : "false"}},
      data.info.metadata);
  out.reserve(out.size() + n * 120);
  header(out, {"d1", "d2", "d3", "length"}, !data.extra.t.empty(), !data.extra.dir.empty(),
         !data.extra.run.empty());
  for (std::size_t i = 0; i < n; ++i) {
    std::size_t mark = out.size();
    if (!data.extra.t.empty()) put(out, path, i, "t", data.extra.t[i]);
    put(out, path, i, "d1", data.d[i].x());
    put(out, path, i, "d2", data.d[i].y());
    put(out, path, i, "d3", data.d[i].z());
    if (!(data.length[i] > 0.0))
      throw Error(path + ": cannot write: row " + std::to_string(i + 1) + ", length must be > 0 m");
    put(out, path, i, "length", data.length[i]);
    common_tail(out, path, data.extra, i);
    out.erase(mark, 1);  // the leading comma
    out.push_back('\n');
  }
  return out;
}

std::string render_position(const PositionData& data, const std::string& path) {
  const std::size_t n = data.d.size();
  check_rows(path, n);
  check_size(path, "px,py,pz", data.p.size(), n);
  check_common(path, data.extra, n);
  std::vector<std::pair<std::string, std::string>> own;
  if (!std::isfinite(data.sigma) || data.sigma < 0.0)
    throw Error(path + ": cannot write: sigma must be a finite value >= 0 m");
  if (data.sigma > 0.0) own.emplace_back("sigma", detail::format_double(data.sigma));
  std::string out = metadata_block(path, DataKind::position, own, data.info.metadata);
  out.reserve(out.size() + n * 150);
  header(out, {"d1", "d2", "d3", "px", "py", "pz"}, !data.extra.t.empty(), !data.extra.dir.empty(),
         !data.extra.run.empty());
  for (std::size_t i = 0; i < n; ++i) {
    std::size_t mark = out.size();
    if (!data.extra.t.empty()) put(out, path, i, "t", data.extra.t[i]);
    put(out, path, i, "d1", data.d[i].x());
    put(out, path, i, "d2", data.d[i].y());
    put(out, path, i, "d3", data.d[i].z());
    put(out, path, i, "px", data.p[i].x());
    put(out, path, i, "py", data.p[i].y());
    put(out, path, i, "pz", data.p[i].z());
    common_tail(out, path, data.extra, i);
    out.erase(mark, 1);
    out.push_back('\n');
  }
  return out;
}

std::string render_motion(const MotionData& data, const std::string& path) {
  const std::size_t n = data.t.size();
  check_rows(path, n);
  check_size(path, "d1,d2,d3", data.d.size(), n);
  check_size(path, "v1,v2,v3", data.v.size(), n);
  check_size(path, "f1,f2,f3", data.f.size(), n);
  if (!data.a.empty()) check_size(path, "a1,a2,a3", data.a.size(), n);
  if (!data.run.empty()) check_size(path, "run", data.run.size(), n);
  std::vector<std::pair<std::string, std::string>> own;
  if (!std::isfinite(data.rate) || data.rate < 0.0)
    throw Error(path + ": cannot write: rate must be a finite value >= 0 Hz (0: not stated)");
  if (data.rate > 0.0) own.emplace_back("rate", detail::format_double(data.rate));
  std::string out = metadata_block(path, DataKind::motion, own, data.info.metadata);
  out.reserve(out.size() + n * 220);
  header(out, {"d1", "d2", "d3", "v1", "v2", "v3", "f1", "f2", "f3"}, true, false,
         !data.run.empty(), !data.a.empty());
  static const char* names[] = {"d1", "d2", "d3", "v1", "v2", "v3", "f1", "f2", "f3", "a1", "a2", "a3"};
  for (std::size_t i = 0; i < n; ++i) {
    std::size_t mark = out.size();
    put(out, path, i, "t", data.t[i]);
    for (int k = 0; k < 3; ++k) put(out, path, i, names[k], data.d[i][k]);
    for (int k = 0; k < 3; ++k) put(out, path, i, names[3 + k], data.v[i][k]);
    for (int k = 0; k < 3; ++k) put(out, path, i, names[6 + k], data.f[i][k]);
    if (!data.a.empty())
      for (int k = 0; k < 3; ++k) put(out, path, i, names[9 + k], data.a[i][k]);
    if (!data.run.empty()) {
      out.push_back(',');
      out += std::to_string(data.run[i]);
    }
    out.erase(mark, 1);
    out.push_back('\n');
  }
  return out;
}

void write_ballbar(const std::string& path, const BallbarData& data) {
  write_file_atomically(path, render_ballbar(data, path));
}
void write_position(const std::string& path, const PositionData& data) {
  write_file_atomically(path, render_position(data, path));
}
void write_motion(const std::string& path, const MotionData& data) {
  write_file_atomically(path, render_motion(data, path));
}

DataKind kind_of(const DataSet& data) noexcept {
  if (std::holds_alternative<BallbarData>(data)) return DataKind::ballbar;
  if (std::holds_alternative<PositionData>(data)) return DataKind::position;
  return DataKind::motion;
}

std::size_t sample_count(const DataSet& data) noexcept {
  return std::visit(
      [](const auto& d) -> std::size_t {
        using T = std::decay_t<decltype(d)>;
        if constexpr (std::is_same_v<T, MotionData>)
          return d.t.size();
        else
          return d.d.size();
      },
      data);
}

void write_data_file(const std::string& path, const DataSet& data) {
  std::visit(
      [&](const auto& d) {
        using T = std::decay_t<decltype(d)>;
        if constexpr (std::is_same_v<T, BallbarData>)
          write_ballbar(path, d);
        else if constexpr (std::is_same_v<T, PositionData>)
          write_position(path, d);
        else
          write_motion(path, d);
      },
      data);
}

}  // namespace cpm::io
