// SPDX-License-Identifier: Apache-2.0
// Shared by the console's subcommands (cmd_console*.cpp). Not a subcommand.
#pragma once

#include <optional>
#include <string>

#include "cmd_client_common.hpp"

namespace cpm::cli::client {

// The message a wait returned, or an Error saying what did not come, within
// how long, and where it was listened for.
template <class M>
M received(std::optional<M> m, const char* what, double within_s, const daemon::LcmConfig& l,
           const std::string& channel) {
  if (m) return std::move(*m);
  char s[32];
  std::snprintf(s, sizeof s, "%g", within_s);
  throw Error(std::string("no ") + what + " from cpmd within " + s + " s (is it running? LCM " + l.url +
              ", channel " + channel + ")");
}

}  // namespace cpm::cli::client
