// SPDX-License-Identifier: Apache-2.0
// Where cpmd and its clients meet on LCM: the URL and the channels (the
// `lcm:` section of cpmd's configuration, docs/daemon.md). On its own so that
// a client (cpm_client, find_package(cpmd)) needs none of the daemon's types.
#pragma once

#include <string>

namespace cpm::daemon {

struct LcmConfig {
  std::string url = "udpm://239.255.76.67:7667?ttl=0";  // ttl=0: never leaves the host
  std::string state_channel = "CPMD_STATE";
  std::string stats_channel = "CPMD_STATS";
  std::string trajectory_channel = "CPMD_TRAJ";
  std::string path_channel = "CPMD_PATH";          // path_command_t: programs for the path queue
  std::string control_channel = "CPMD_CONTROL";
  std::string ack_channel = "CPMD_ACK";
  std::string security_channel = "CPMD_SECURITY";  // security_t, 1 Hz
  std::string drives_channel = "CPMD_DRIVES";      // drives_t, 10 Hz
  std::string params_channel = "CPMD_PARAMS";      // params_t, 1 Hz and on change
  std::string seal_channel = "CPMD_SEAL";          // seal_t: what makes the others trusted
  int state_decimation = 1;  // publish the state every N cycles
  // A commander's session ends after this long without a command or ping
  // from it (s); clients ping every 0.25 s while they hold one.
  double session_timeout = 2.0;
  // A client's: cpmd's public key file (docs/security.md, "Signed state").
  // Empty: $CPM_DAEMON_KEY, else ~/.config/cpm/cpmd.pub if it exists, else
  // none (state and acks are then taken unverified, with a warning).
  std::string daemon_public_key;
};

}  // namespace cpm::daemon
