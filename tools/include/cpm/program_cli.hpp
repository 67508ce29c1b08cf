// SPDX-License-Identifier: Apache-2.0
// What every program of the project does with its command line beside its
// own options (CLI11): --version prints "NAME VERSION" with the build's
// version (cmake/version.cmake), --help prints the options and exits 0, and
// a bad command line is said on stderr, naming the option, with exit status 2.
#pragma once

#include <CLI/CLI.hpp>
#include <cmath>
#include <cstdio>
#include <memory>
#include <sstream>
#include <string>

#include "cpm/version.hpp"

namespace cpm::program {

inline bool takes_value(const CLI::Option* o) { return o->get_expected_max() != 0; }  // a flag expects none
inline bool is_vector(const CLI::Option* o) { return o->get_expected_max() == CLI::detail::expected_max_vector_size; }

// CLI11's help with the defaults in the description ("[default 0.15]") rather
// than glued to the value's name, and long descriptions wrapped under their
// column (help2man keeps the indented lines with their option).
class HelpFormatter : public CLI::Formatter {
 public:
  HelpFormatter() { column_width(kColumn); }

  std::string make_option_opts(const CLI::Option* o) const override {
    std::string out;
    if (!takes_value(o)) return out;
    if (!o->get_type_name().empty()) out += " " + o->get_type_name();
    if (is_vector(o)) out += " ...";
    if (o->get_required()) out += " (required)";
    return out;
  }

  std::string make_option_desc(const CLI::Option* o) const override {
    std::string d = o->get_description();
    const std::string def = o->get_default_str();
    if (takes_value(o) && !o->get_required() && !def.empty() && def != "[]" && def != "{}")
      d += " [default " + def + "]";
    return d;
  }

  std::string make_option(const CLI::Option* o, bool is_positional) const override {
    std::string left = "  " + make_option_name(o, is_positional) + (is_positional ? "" : make_option_opts(o));
    std::istringstream words(make_option_desc(o));
    std::string out, line, w;
    const auto indent = static_cast<std::size_t>(kColumn);
    if (left.size() >= indent) {
      out = left + "\n";
      left.clear();
    }
    line = left + std::string(indent - left.size(), ' ');
    bool first = true;
    while (words >> w) {
      if (!first && line.size() + 1 + w.size() > kWidth) {
        out += line + "\n";
        line = std::string(indent, ' ');
        first = true;
      }
      line += (first ? "" : " ") + w;
      first = false;
    }
    return out + line + "\n";
  }

 private:
  static constexpr int kColumn = 30;
  static constexpr std::size_t kWidth = 100;
};

// The project's conventions on `app` (call before adding options): the help
// above, defaults shown, and --version printing "NAME VERSION" (e.g.
// "cpmd 0.2.0+g1b1cebc").
inline void setup(CLI::App& app) {
  app.formatter(std::make_shared<HelpFormatter>());
  app.option_defaults()->always_capture_default();
  app.set_version_flag("--version", app.get_name() + " " + kVersion, "print the version and exit");
}

// A finite number: CLI11 alone takes nan and inf for a double.
inline const CLI::Validator& finite() {
  static const CLI::Validator v(
      [](std::string& s) -> std::string {
        double x = 0;
        if (!CLI::detail::lexical_cast(s, x) || !std::isfinite(x)) return "'" + s + "' is not a finite number";
        return {};
      },
      "");
  return v;
}

// The exit status after CLI11 stopped the parse: 0 after --help or --version
// (printed on stdout), else 2 with "WHO: what is wrong" on stderr.
inline int parse_exit(const CLI::App& app, const CLI::ParseError& e, const std::string& who) {
  if (e.get_exit_code() == static_cast<int>(CLI::ExitCodes::Success)) return app.exit(e);
  std::fprintf(stderr, "%s: %s\n'%s --help' shows the options.\n", who.c_str(), e.what(), who.c_str());
  return 2;
}

}  // namespace cpm::program
