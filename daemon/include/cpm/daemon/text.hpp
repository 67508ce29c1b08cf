// SPDX-License-Identifier: Apache-2.0
// printf into a std::string, for the sentences cpmd and its clients show
// (fault reports, the console). Not for the real-time path (it allocates).
#pragma once

#include <cstdint>
#include <string>

namespace cpm::daemon {

std::string printf_text(const char* format, ...) __attribute__((format(printf, 1, 2)));

// A worst-case time from cpmd's statistics (int32 ns) in us, as cpmd's log
// and the screens show it: "none yet" before the first sample (`any` false),
// "> 2147483 us" where the figure stopped at the message's 32-bit maximum (a
// stall of 2.1 s or more: the true figure is unknown), else "45.6 us".
std::string worst_us_text(std::int32_t ns, bool any);

}  // namespace cpm::daemon
