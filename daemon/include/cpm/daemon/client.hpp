// SPDX-License-Identifier: Apache-2.0
// A client of a running cpmd over LCM: used by the `cpm` client subcommands
// and by the end-to-end tests. Not real-time.
#pragma once

#include <array>
#include <functional>
#include <map>
#include <memory>
#include <optional>
#include <set>
#include <string>
#include <variant>
#include <vector>

#include <cpm_msgs/ack_t.hpp>
#include <cpm_msgs/control_command_t.hpp>
#include <cpm_msgs/drives_t.hpp>
#include <cpm_msgs/loop_stats_t.hpp>
#include <cpm_msgs/params_t.hpp>
#include <cpm_msgs/path_command_t.hpp>
#include <cpm_msgs/security_t.hpp>
#include <cpm_msgs/state_t.hpp>
#include <cpm_msgs/trajectory_command_t.hpp>

#include "cpm/daemon/auth.hpp"
#include "cpm/daemon/lcm_config.hpp"
#include "cpm/daemon/modes.hpp"
#include "cpm/daemon/signing.hpp"

namespace lcm {
class LCM;
class ReceiveBuffer;
}  // namespace lcm

namespace cpm::daemon {

// Commands need an operator's key (docs/security.md) and the session cpmd
// grants to one commander at a time (docs/daemon.md): the client signs every
// command with its credentials, acquires the session with its first command,
// stamps every command with it and an increasing seq, pings while it waits
// so the session does not expire, acquires again when the daemon restarted
// or the session expired, and releases it when destroyed. A stop needs
// neither: it is sent without a session when none is held, and unsigned
// without credentials (cpmd takes a stop from anyone). Without credentials
// every other command throws Error before anything is sent.
class Client {
 public:
  // Throws Error when LCM cannot start. `operator_key`: whose commands these
  // are (find_credentials finds the operator's own); none: state and stop only.
  explicit Client(const LcmConfig& cfg, std::optional<Credentials> operator_key = std::nullopt);
  ~Client();  // releases the session, if held

  // Acquire the session now (throws Error naming the reason, e.g. "another
  // commander holds the machine"); the commands below do it when needed.
  void acquire(double timeout_s = 2.0);
  // Give it up (no-op without one); returns whether cpmd confirmed it.
  bool release(double timeout_s = 1.0);
  [[nodiscard]] std::int64_t session() const noexcept { return session_; }

  // A fresh command id (random base per client, then counting).
  std::int64_t next_id();
  // Send and wait for the ack (throws Error on timeout: "no answer from cpmd").
  cpm_msgs::ack_t control(cpm_msgs::control_command_t cmd, double timeout_s = 2.0);
  cpm_msgs::ack_t control(std::int8_t command, double timeout_s = 2.0);
  cpm_msgs::ack_t trajectory(cpm_msgs::trajectory_command_t cmd, double timeout_s = 2.0);
  // Send without waiting; the ack is collected later with wait_ack().
  std::int64_t send_trajectory(cpm_msgs::trajectory_command_t cmd);
  cpm_msgs::ack_t wait_ack(std::int64_t id, double timeout_s);
  // A program's chunk for the path queue (path_command_t, docs/path.md),
  // stamped, signed and sent without waiting; its id is returned (a fresh
  // one unless set). The last chunk's ack comes once cpmd has planned the
  // program.
  std::int64_t send_path(cpm_msgs::path_command_t cmd);

  // Homing (CMD_HOME), send and wait for the ack: `axes` bit i = actuator
  // i + 1; 0 = every actuator in the configured order. The ack says whether
  // it started; state_t.homing_axis/homing_phase/homed tell how it goes.
  cpm_msgs::ack_t home(std::uint8_t axes, double timeout_s = 2.0);
  // Jog (CMD_JOG): `frame` control_command_t::JOG_ACTUATOR (v per actuator,
  // m/s of d1, d2, d3) or JOG_MACHINE (the platform's velocity in the machine
  // frame, m/s; z down); all zeros stops jogging. One signed command, sent
  // without waiting: a jog holds for jog.keepalive s, so a held key repeats
  // it (20 Hz or faster) and cpmd's deadman stops the platform when it stops
  // coming. Returns the command's id. The acks of jogs are not queued: the
  // latest is last_jog_ack(), and wait_ack(id) waits for the latest jog's.
  // A jog refused because the session was lost drops it: the next jog
  // acquires again.
  std::int64_t jog(std::int8_t frame, const double v[3]);
  [[nodiscard]] const std::optional<cpm_msgs::ack_t>& last_jog_ack() const noexcept { return last_jog_ack_; }
  // Change a parameter of params_t (CMD_SET_PARAM; `value` in the SI unit
  // params_t gives it) and wait for the ack: refused with cpmd's sentence
  // when out of range, unknown, or not changeable while the platform moves.
  // Throws Error for a name longer than control_command_t.param_name holds.
  cpm_msgs::ack_t set_param(const std::string& name, double value, double timeout_s = 2.0);

  // The next state message (nullopt on timeout).
  std::optional<cpm_msgs::state_t> state(double timeout_s = 2.0);
  std::optional<cpm_msgs::loop_stats_t> stats(double timeout_s = 3.0);
  std::optional<cpm_msgs::security_t> security(double timeout_s = 3.0);
  // The next drives message (10 Hz) and parameter table (1 Hz and after
  // every change); nullopt on timeout (also from a cpmd that publishes none).
  std::optional<cpm_msgs::drives_t> drives(double timeout_s = 1.0);
  std::optional<cpm_msgs::params_t> params(double timeout_s = 3.0);
  // The latest of each message handled so far (by handle(), state(), ...),
  // without waiting: a view redrawn at its own rate reads these. Empty until
  // the first arrives; state(), stats(), ... empty theirs when they start
  // waiting for the next.
  [[nodiscard]] const std::optional<cpm_msgs::state_t>& latest_state() const noexcept { return last_state_; }
  [[nodiscard]] const std::optional<cpm_msgs::loop_stats_t>& latest_stats() const noexcept { return last_stats_; }
  [[nodiscard]] const std::optional<cpm_msgs::drives_t>& latest_drives() const noexcept { return last_drives_; }
  [[nodiscard]] const std::optional<cpm_msgs::params_t>& latest_params() const noexcept { return last_params_; }
  // Called for every state message while handle() runs.
  void on_state(std::function<void(const cpm_msgs::state_t&)> f) { state_cb_ = std::move(f); }
  // Process incoming messages for up to `timeout_s`, less when a signal
  // interrupts the wait (Ctrl-C: the caller looks at its flag); returns the
  // number handled.
  int handle(double timeout_s);
  [[nodiscard]] const LcmConfig& config() const noexcept { return cfg_; }

  // Signed state (docs/security.md): from now on only messages (state, acks,
  // drives, statistics, parameters, security counts) that a seal signed by
  // `pk` lists, newer than the last of their kind and of the boot of the
  // first verified seal, are taken: each is held until its seal verifies
  // (at most 10 ms, 1 ms for an ack, after cpmd published it); the rest are
  // dropped, counted, and reported once per cause (to stderr, or to
  // `on_refused`). Without it everything is taken unverified.
  void verify_with(const PublicKey& pk) { verifier_.emplace(pk); }
  [[nodiscard]] bool verifying() const noexcept { return verifier_.has_value(); }
  [[nodiscard]] const std::optional<Verifier>& verifier() const noexcept { return verifier_; }
  void on_refused(std::function<void(Trust, const char* what)> f) { refused_cb_ = std::move(f); }
  // For a view that owns the terminal (cpm watch): "" while nothing was
  // refused (or nothing is verified: the constructor warned), else "refused
  // as not cpmd's: N (n1 <cause>, ...)".
  [[nodiscard]] std::string trust_note() const;
  // The boot id of verified-signed messages from another start of cpmd (0: none seen).
  [[nodiscard]] std::int64_t restarted() const noexcept { return restarted_; }

 private:
  // Raw: whoever is on the bus may publish there, and lcm-gen's typed
  // decoding of a string trusts its length (a bad one throws out of handle()).
  void on_ack(const lcm::ReceiveBuffer* rbuf, const std::string&);
  void on_state_msg(const lcm::ReceiveBuffer*, const std::string&, const cpm_msgs::state_t* m);
  void on_stats_msg(const lcm::ReceiveBuffer*, const std::string&, const cpm_msgs::loop_stats_t* m);
  void on_security_msg(const lcm::ReceiveBuffer*, const std::string&, const cpm_msgs::security_t* m);
  void on_drives_msg(const lcm::ReceiveBuffer*, const std::string&, const cpm_msgs::drives_t* m);
  // Raw: params_t's counts and strings are the sender's word (see on_ack).
  void on_params(const lcm::ReceiveBuffer* rbuf, const std::string&);
  void on_seal(const lcm::ReceiveBuffer* rbuf, const std::string&);
  // A message as received: taken at once when nothing is verified, else held
  // until a seal decides (then used, or refused and said).
  // In Stream's order: a held message's index() is its Stream.
  using Held = std::variant<cpm_msgs::state_t, cpm_msgs::ack_t, cpm_msgs::drives_t, cpm_msgs::loop_stats_t,
                            cpm_msgs::params_t, cpm_msgs::security_t>;
  static_assert(std::variant_size_v<Held> == kStreams);
  void receive(Stream s, const lcm::ReceiveBuffer* rbuf, Held&& m);
  void use(const cpm_msgs::state_t& m);
  void use(const cpm_msgs::ack_t& m);
  void use(const cpm_msgs::drives_t& m) { last_drives_ = m; }
  void use(const cpm_msgs::loop_stats_t& m) { last_stats_ = m; }
  void use(const cpm_msgs::params_t& m) { last_params_ = m; }
  void use(const cpm_msgs::security_t& m) { last_security_ = m; }
  // Session, seq and time; then the operator's MAC over all of it.
  template <class M>
  void stamp(M& m);
  void need_key(std::int8_t command) const;  // throws Error without credentials
  // A motion command (trajectory, path chunk) on `channel`: a session
  // acquired first if none is held, stamped, signed; returns its id.
  template <class M>
  std::int64_t send_motion(const std::string& channel, M& cmd);
  // The next message into `slot` (reset first), keeping the session alive meanwhile.
  template <class M>
  std::optional<M> next(std::optional<M>& slot, double timeout_s, int poll_ms);
  void keep_alive();  // a ping when the holder has been silent for 0.25 s
  static bool lost_session(const cpm_msgs::ack_t& a) noexcept;
  void refused(Trust t, const char* what);
  void need_same_boot() const;
  void no_seal();  // says once that messages wait and no seal came (an unsigned cpmd)
  void unverified();  // warns once that nothing can be verified  // throws Error once cpmd is seen to have restarted

  LcmConfig cfg_;
  std::optional<Credentials> creds_;
  std::unique_ptr<lcm::LCM> lcm_;
  std::int64_t next_id_ = 0;
  std::int64_t nonce_ = 0;    // this client's acquire nonce
  std::int64_t session_ = 0;  // 0: none held
  std::int64_t seq_ = 0;
  std::int64_t last_acquire_seq_ = 0;  // an acquire's seq is the wall clock (us), rising
  double last_sent_ = 0.0;    // steady clock (s) of the last stamped command
  std::set<std::int64_t> pings_;  // keep-alive ids whose acks nobody waits for
  // The ids of this client's latest jogs (a ring: their acks come within
  // milliseconds, jogs 50 ms apart), to tell its jog acks from others'.
  std::array<std::int64_t, 16> jog_ids_{};
  std::size_t jog_next_ = 0;
  std::map<std::int64_t, cpm_msgs::ack_t> acks_;
  std::optional<cpm_msgs::state_t> last_state_;
  std::optional<cpm_msgs::loop_stats_t> last_stats_;
  std::optional<cpm_msgs::security_t> last_security_;
  std::optional<cpm_msgs::drives_t> last_drives_;
  std::optional<cpm_msgs::params_t> last_params_;
  std::optional<cpm_msgs::ack_t> last_jog_ack_;
  std::function<void(const cpm_msgs::state_t&)> state_cb_;
  std::optional<Verifier> verifier_;
  std::function<void(Trust, const char*)> refused_cb_;
  std::map<std::uint64_t, Held> held_;  // waiting for their seal, by ticket
  std::uint64_t next_ticket_ = 0;
  std::vector<Verifier::Verdict> decided_;
  std::array<bool, 7> told_{};
  std::int64_t restarted_ = 0;
  bool told_unverified_ = false;
  bool told_no_seal_ = false;
};

// The public key file a client verifies with (LcmConfig::daemon_public_key's
// order); "" when there is none.
std::string daemon_public_key_path(const LcmConfig& cfg);

// "mode names": disabled, holding, ...
const char* mode_text(std::int8_t mode) noexcept;
// "following_error,estop" (empty for 0).
std::string fault_text(std::int32_t mask);

// An ack_t as received: decoded only when its string's length accounts for
// the message exactly and the string's only NUL is its last byte (nullopt
// otherwise).
std::optional<cpm_msgs::ack_t> decode_ack(const void* data, std::size_t size);

}  // namespace cpm::daemon
