// SPDX-License-Identifier: Apache-2.0
// Shared by the client subcommands (cmd_client*.cpp): how to reach the
// daemon, and small helpers. Not a subcommand itself.
#pragma once

#include <cstdio>
#include <optional>
#include <string>

#include "cli.hpp"
#include "cpm/daemon/client.hpp"
#include "cpm/daemon/config.hpp"

namespace cpm::cli::client {

// --config FILE (the daemon's config: its lcm section) and/or --url URL.
struct Connection {
  std::optional<std::string> config, url, daemon_key;
};
inline void add_connection(CLI::App& app, Connection& c) {
  app.add_option("--config", c.config, "the daemon's configuration: its lcm section says where cpmd listens")
      ->type_name("DAEMON.yaml");
  app.add_option("--url", c.url, "the LCM URL, instead of the config's")
      ->type_name("LCM_URL")
      ->default_str(daemon::LcmConfig{}.url);
  app.add_option("--daemon-key", c.daemon_key, "cpmd's public key: only state and acks it signed are believed")
      ->type_name("FILE")
      ->default_str("$CPM_DAEMON_KEY, else ~/.config/cpm/cpmd.pub");
}
inline daemon::LcmConfig lcm_options(const Connection& c) {
  daemon::LcmConfig l;
  if (c.config) l = daemon::load_config(*c.config).lcm;
  if (c.url) l.url = *c.url;
  if (c.daemon_key) l.daemon_public_key = *c.daemon_key;
  return l;
}

// The operator's key (docs/security.md): --key FILE, else $CPM_KEY_FILE, else
// ~/.config/cpm/operator.key; the name --operator NAME, else $CPM_OPERATOR,
// else the key file's name, else the login name. None found: nullopt (the
// client then refuses every command but stop).
struct Operator {
  std::optional<std::string> key, name;
};
inline void add_operator(CLI::App& app, Operator& o) {
  app.add_option("--key", o.key, "the operator's key file (docs/security.md)")
      ->type_name("FILE")
      ->default_str("$CPM_KEY_FILE, else ~/.config/cpm/operator.key");
  app.add_option("--operator", o.name, "the operator's name, as cpmd knows it")
      ->type_name("NAME")
      ->default_str("$CPM_OPERATOR, else the key file's name, else the login name");
}
inline std::optional<daemon::Credentials> operator_key(const Operator& o) {
  return daemon::find_credentials(o.key, o.name);
}
// For `stop`, which must work whatever state the key is in: a key that
// cannot be read is said and left out (cpmd takes an unsigned stop).
inline std::optional<daemon::Credentials> operator_key_if_usable(const Operator& o) {
  try {
    return operator_key(o);
  } catch (const Error& e) {
    std::fprintf(stderr, "cpm: warning: %s; stopping without a key\n", e.what());
    return std::nullopt;
  }
}

// Print an ack; returns 0 when accepted, 1 when rejected.
inline int report(const char* what, const cpm_msgs::ack_t& a) {
  if (a.accepted)
    std::printf("%s: accepted (%s); mode %s, %d queued\n", what, a.message.c_str(), daemon::mode_text(a.mode),
                a.queue_depth);
  else
    std::printf("%s: REJECTED: %s (mode %s)\n", what, a.message.c_str(), daemon::mode_text(a.mode));
  return a.accepted ? 0 : 1;
}

inline Vec3 vec3_of(const double* v) { return Vec3(v[0], v[1], v[2]); }

// Parse "x,y,z" (m).
Vec3 parse_point(const std::string& what, const std::string& text);

// Wait until segment `id` has finished (or the machine left moving), printing
// a progress bar when `progress`; returns the final state.
cpm_msgs::state_t wait_segment(daemon::Client& c, std::int64_t id, double timeout_s, bool progress);

// One line of text for a state (mode, position in mm, error in um, faults).
std::string state_line(const cpm_msgs::state_t& s);

}  // namespace cpm::cli::client
