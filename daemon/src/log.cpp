// SPDX-License-Identifier: Apache-2.0
#include "cpm/daemon/log.hpp"

#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <cstdarg>
#include <cstdio>
#include <cstdlib>
#include <cstring>

namespace cpm::daemon::log {
namespace {

const char* plain_prefix(Severity s) {
  switch (s) {
    case Severity::error: return "cpmd: error: ";
    case Severity::warning: return "cpmd: warning: ";
    case Severity::debug: return "cpmd: debug: ";
    case Severity::notice:
    case Severity::info: break;
  }
  return "cpmd: ";
}

// A decimal number that fills [p, end) exactly.
bool parse_decimal(const char* p, const char* end, unsigned long long& out) {
  if (p == end) return false;
  out = 0;
  for (; p != end; ++p) {
    if (*p < '0' || *p > '9') return false;
    out = out * 10 + static_cast<unsigned long long>(*p - '0');
  }
  return true;
}

std::string vformat(const char* format, va_list args) {
  va_list again;
  va_copy(again, args);
  const int n = std::vsnprintf(nullptr, 0, format, args);
  std::string s(n > 0 ? static_cast<std::size_t>(n) : 0, '\0');
  if (n > 0) std::vsnprintf(s.data(), s.size() + 1, format, again);
  va_end(again);
  return s;
}

}  // namespace

bool is_journal_stream(const char* journal_stream, dev_t device, ino_t inode) {
  if (!journal_stream) return false;
  const char* colon = std::strchr(journal_stream, ':');
  unsigned long long dev = 0, ino = 0;
  if (!colon || !parse_decimal(journal_stream, colon, dev) ||
      !parse_decimal(colon + 1, journal_stream + std::strlen(journal_stream), ino))
    return false;
  return dev == static_cast<unsigned long long>(device) && ino == static_cast<unsigned long long>(inode);
}

Style style_for(int fd) {
  struct stat st {};
  if (::fstat(fd, &st) != 0) return Style::plain;
  return is_journal_stream(std::getenv("JOURNAL_STREAM"), st.st_dev, st.st_ino) ? Style::journal : Style::plain;
}

std::string format(Style style, Severity severity, std::string_view message) {
  char journal_prefix[8];
  std::snprintf(journal_prefix, sizeof journal_prefix, "<%d>", static_cast<int>(severity));
  const std::string_view prefix = style == Style::journal ? journal_prefix : plain_prefix(severity);
  std::string out;
  out.reserve(message.size() + prefix.size() + 1);
  std::size_t start = 0;
  do {
    const std::size_t nl = message.find('\n', start);
    const std::size_t end = nl == std::string_view::npos ? message.size() : nl;
    out += prefix;
    out += message.substr(start, end - start);
    out += '\n';
    start = end + 1;
  } while (start < message.size());
  return out;
}

void write(Severity severity, std::string_view message) {
  static const Style style = style_for(STDERR_FILENO);
  const std::string text = format(style, severity, message);
  // One write(2), so that the lines of two threads do not interleave.
  for (std::size_t off = 0; off < text.size();) {
    const ssize_t n = ::write(STDERR_FILENO, text.data() + off, text.size() - off);
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) return;  // nowhere to say it
    off += static_cast<std::size_t>(n);
  }
}

#define CPM_LOG_AT(name, severity)             \
  void name(const char* format, ...) {         \
    va_list args;                              \
    va_start(args, format);                    \
    const std::string s = vformat(format, args); \
    va_end(args);                              \
    write(severity, s);                        \
  }
CPM_LOG_AT(error, Severity::error)
CPM_LOG_AT(warning, Severity::warning)
CPM_LOG_AT(notice, Severity::notice)
CPM_LOG_AT(info, Severity::info)
#undef CPM_LOG_AT

}  // namespace cpm::daemon::log
