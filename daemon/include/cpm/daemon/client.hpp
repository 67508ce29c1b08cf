// A client of a running cpmd over LCM: used by the `cpm` client subcommands
// and by the end-to-end tests. Not real-time.
#pragma once

#include <functional>
#include <map>
#include <memory>
#include <optional>
#include <set>
#include <string>

#include <cpm_msgs/ack_t.hpp>
#include <cpm_msgs/control_command_t.hpp>
#include <cpm_msgs/loop_stats_t.hpp>
#include <cpm_msgs/state_t.hpp>
#include <cpm_msgs/trajectory_command_t.hpp>

#include "cpm/daemon/config.hpp"

namespace lcm {
class LCM;
class ReceiveBuffer;
}  // namespace lcm

namespace cpm::daemon {

// Commands need the session cpmd grants to one commander at a time
// (docs/daemon.md): the client acquires it with its first command, stamps
// every command with it and an increasing seq, pings while it waits so the
// session does not expire, acquires again when the daemon restarted or the
// session expired, and releases it when destroyed. A stop is sent without a
// session when none is held (cpmd takes a stop from anyone).
class Client {
 public:
  explicit Client(const LcmConfig& cfg);  // throws Error when LCM cannot start
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

  // The next state message (nullopt on timeout).
  std::optional<cpm_msgs::state_t> state(double timeout_s = 2.0);
  std::optional<cpm_msgs::loop_stats_t> stats(double timeout_s = 3.0);
  // Called for every state message while handle() runs.
  void on_state(std::function<void(const cpm_msgs::state_t&)> f) { state_cb_ = std::move(f); }
  // Process incoming messages for up to `timeout_s`; returns the number handled.
  int handle(double timeout_s);
  [[nodiscard]] const LcmConfig& config() const noexcept { return cfg_; }

 private:
  void on_ack(const lcm::ReceiveBuffer*, const std::string&, const cpm_msgs::ack_t* m);
  void on_state_msg(const lcm::ReceiveBuffer*, const std::string&, const cpm_msgs::state_t* m);
  void on_stats_msg(const lcm::ReceiveBuffer*, const std::string&, const cpm_msgs::loop_stats_t* m);
  template <class M>
  void stamp(M& m);
  void keep_alive();  // a ping when the holder has been silent for 0.25 s
  static bool lost_session(const cpm_msgs::ack_t& a) noexcept;

  LcmConfig cfg_;
  std::unique_ptr<lcm::LCM> lcm_;
  std::int64_t next_id_ = 0;
  std::int64_t nonce_ = 0;    // this client's acquire nonce
  std::int64_t session_ = 0;  // 0: none held
  std::int64_t seq_ = 0;
  double last_sent_ = 0.0;    // steady clock (s) of the last stamped command
  std::set<std::int64_t> pings_;  // keep-alive ids whose acks nobody waits for
  std::map<std::int64_t, cpm_msgs::ack_t> acks_;
  std::optional<cpm_msgs::state_t> last_state_;
  std::optional<cpm_msgs::loop_stats_t> last_stats_;
  std::function<void(const cpm_msgs::state_t&)> state_cb_;
};

// "mode names": disabled, holding, ...
const char* mode_text(std::int8_t mode) noexcept;
// "following_error,estop" (empty for 0).
std::string fault_text(std::int32_t mask);

}  // namespace cpm::daemon
