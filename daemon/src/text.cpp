// SPDX-License-Identifier: Apache-2.0
#include "cpm/daemon/text.hpp"

#include <cstdarg>
#include <cstdint>
#include <cstdio>

namespace cpm::daemon {

std::string printf_text(const char* format, ...) {
  va_list ap;
  va_start(ap, format);
  va_list again;
  va_copy(again, ap);
  const int n = std::vsnprintf(nullptr, 0, format, ap);
  va_end(ap);
  std::string s(n > 0 ? static_cast<std::size_t>(n) : 0, '\0');
  if (n > 0) std::vsnprintf(s.data(), s.size() + 1, format, again);
  va_end(again);
  return s;
}

std::string worst_us_text(std::int32_t ns, bool any) {
  if (!any) return "none yet";
  if (ns >= INT32_MAX) return printf_text("> %d us (beyond what the statistics hold: a stall of 2.1 s or more)", INT32_MAX / 1000);
  return printf_text("%.1f us", ns * 1e-3);
}

}  // namespace cpm::daemon
