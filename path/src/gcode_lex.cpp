// SPDX-License-Identifier: Apache-2.0
// Lexing a G-code line: words, numbers, comments (gcode.hpp).
#include <cctype>
#include <cmath>
#include <string>

#include "gcode_internal.hpp"

namespace cpm::path::detail {
namespace {

bool blank(char c) { return c == ' ' || c == '\t' || c == '\r'; }

void fail(std::vector<Diagnostic>& errors, int line, std::size_t at, const std::string& why) {
  errors.push_back(Diagnostic{line, static_cast<int>(at) + 1, why});
}

// A real number from text[i]: [+-] digits [. digits], blanks allowed
// between its characters as RS274NGC allows. Advances i; false if none.
bool number(std::string_view text, std::size_t& i, double& value) {
  std::string digits;
  bool any = false, dot = false;
  for (; i < text.size(); ++i) {
    const char c = text[i];
    if (blank(c)) continue;
    if ((c == '+' || c == '-') && digits.empty()) digits += c;
    else if (c == '.' && !dot) dot = true, digits += c;
    else if (std::isdigit(static_cast<unsigned char>(c))) any = true, digits += c;
    else break;
  }
  if (!any) return false;
  value = std::stod(digits);
  return std::isfinite(value);
}

// Skip a ( ) comment from text[i] == '('; false if it does not close.
bool comment(std::string_view text, std::size_t& i) {
  const std::size_t close = text.find(')', i);
  if (close == std::string_view::npos) return false;
  i = close + 1;
  return true;
}

}  // namespace

bool lex(std::string_view text, int line, Block& out, std::vector<Diagnostic>& errors) {
  out.line = line;
  out.words.clear();
  for (std::size_t i = 0; i < text.size();) {
    const char c = text[i];
    if (blank(c)) {
      ++i;
    } else if (c == ';') {
      break;
    } else if (c == '(') {
      if (!comment(text, i)) return fail(errors, line, i, "comment not closed: ')' missing"), false;
    } else if (std::isalpha(static_cast<unsigned char>(c))) {
      Word w{static_cast<char>(std::toupper(static_cast<unsigned char>(c))), 0.0, static_cast<int>(i) + 1};
      ++i;
      const std::size_t next = text.find_first_not_of(" \t\r", i);
      if (next != std::string_view::npos && (text[next] == '#' || text[next] == '['))
        return fail(errors, line, next, text[next] == '#' ? "parameters (#) are not supported"
                                                          : "expressions ([ ]) are not supported"),
               false;
      if (!number(text, i, w.value))
        return fail(errors, line, static_cast<std::size_t>(w.column - 1), std::string("word ") + w.letter + " has no number"),
               false;
      out.words.push_back(w);
    } else {
      const std::string what = c == '#' ? "parameters (#) are not supported"
                               : c == '[' ? "expressions ([ ]) are not supported"
                               : c == '/' ? "block delete (/) is not supported"
                               : c == '%' ? "'%' stands alone on a program's first line and on the line that ends it"
                                          : std::string("unexpected character '") + c + "'";
      return fail(errors, line, i, what), false;
    }
  }
  return true;
}

}  // namespace cpm::path::detail
