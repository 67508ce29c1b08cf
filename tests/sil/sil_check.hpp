// SPDX-License-Identifier: Apache-2.0
// Minimal checks for the SIL smoke programs: they run inside the VM, where a
// small self-contained binary is easiest to read in a serial log. Each
// failed check prints what and where, and the program exits non-zero.
#pragma once

#include <cerrno>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string>

namespace sil {

inline int failures = 0;

inline void check(bool ok, const char* what, const char* file, int line, const std::string& detail = {}) {
  if (!ok) {
    ++failures;
    std::fprintf(stderr, "%s:%d: FAILED: %s%s%s\n", file, line, what, detail.empty() ? "" : " — ", detail.c_str());
  }
}

inline std::string errno_text() { return std::string(std::strerror(errno)) + " (errno " + std::to_string(errno) + ")"; }

inline const char* env_or(const char* name, const char* fallback) {
  const char* v = std::getenv(name);
  return (v != nullptr && *v != '\0') ? v : fallback;
}

inline int finish(const char* name) {
  if (failures == 0) {
    std::printf("%s: all checks passed\n", name);
    return 0;
  }
  std::printf("%s: %d check(s) failed\n", name, failures);
  return 1;
}

}  // namespace sil

#define SIL_CHECK(cond) ::sil::check((cond), #cond, __FILE__, __LINE__)
#define SIL_CHECK_MSG(cond, msg) ::sil::check((cond), #cond, __FILE__, __LINE__, (msg))
// A precondition without which the rest is meaningless.
#define SIL_REQUIRE(cond, msg)                                   \
  do {                                                           \
    if (!(cond)) {                                               \
      ::sil::check(false, #cond, __FILE__, __LINE__, (msg));     \
      return ::sil::finish("check");                            \
    }                                                            \
  } while (0)
