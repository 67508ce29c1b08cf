// SPDX-License-Identifier: Apache-2.0
// Helpers shared by the io sources (not a public interface).
#pragma once

#include <charconv>
#include <string>
#include <string_view>

namespace cpm::io::detail {

// The whole file as bytes; Error "PATH: cannot read: <reason>" on failure.
std::string read_whole_file(const std::string& path);

// Shortest text that reads back to exactly the same double (std::to_chars),
// so writers are bit-exact and still readable (0.1, not 0.10000000000000001).
inline void append_double(std::string& out, double v) {
  char buf[32];
  const auto r = std::to_chars(buf, buf + sizeof buf, v);
  out.append(buf, r.ptr);
}
inline std::string format_double(double v) {
  std::string s;
  append_double(s, v);
  return s;
}

// Parse a whole field as a double (leading '+' allowed, surrounding spaces
// already trimmed). False when the text is not exactly one number.
inline bool parse_double(std::string_view s, double& v) {
  if (!s.empty() && s.front() == '+') s.remove_prefix(1);
  if (s.empty()) return false;
  const auto r = std::from_chars(s.data(), s.data() + s.size(), v);
  return r.ec == std::errc() && r.ptr == s.data() + s.size();
}

inline std::string_view trim(std::string_view s) {
  while (!s.empty() && (s.front() == ' ' || s.front() == '\t')) s.remove_prefix(1);
  while (!s.empty() && (s.back() == ' ' || s.back() == '\t' || s.back() == '\r')) s.remove_suffix(1);
  return s;
}

}  // namespace cpm::io::detail
