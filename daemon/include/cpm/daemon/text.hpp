// SPDX-License-Identifier: Apache-2.0
// printf into a std::string, for the sentences cpmd and its clients show
// (fault reports, the console). Not for the real-time path (it allocates).
#pragma once

#include <string>

namespace cpm::daemon {

std::string printf_text(const char* format, ...) __attribute__((format(printf, 1, 2)));

}  // namespace cpm::daemon
