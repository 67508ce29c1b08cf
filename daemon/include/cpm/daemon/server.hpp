// The command/state side of cpmd (not real-time): one thread with the LCM
// handle. It decodes commands, validates trajectories against the model and
// the configured limits (the expensive checks, with messages that say what
// and where), hands what passed to the loop through its SPSC queue, and
// publishes the loop's acknowledgements, state snapshots and statistics.
#pragma once

#include <atomic>
#include <functional>
#include <map>
#include <memory>
#include <string>
#include <vector>

#include <cpm_msgs/ack_t.hpp>
#include <cpm_msgs/control_command_t.hpp>
#include <cpm_msgs/trajectory_command_t.hpp>

#include "cpm/daemon/loop.hpp"

namespace lcm {
class LCM;
class ReceiveBuffer;
}  // namespace lcm

namespace cpm::daemon {

// Owns the prepared machine models; the loop holds a pointer to the current one.
class ModelStore {
 public:
  explicit ModelStore(std::unique_ptr<ctl::Machine> first);
  [[nodiscard]] const ctl::Machine& current() const noexcept { return *current_; }
  const ctl::Machine* add(std::unique_ptr<ctl::Machine> m);
  void make_current(const ctl::Machine* m) noexcept { current_ = m; }
  void release(const ctl::Machine* m);  // free a model the loop no longer uses

 private:
  std::vector<std::unique_ptr<ctl::Machine>> models_;
  const ctl::Machine* current_;
};

// Result of validating a trajectory command: a segment, or a reason.
struct Validation {
  bool ok = false;
  std::int16_t reason = 0;  // ack_t.REASON_*
  std::string message;
  Segment segment;
};

// The longest segment accepted (s): validation samples a segment at the
// loop's period in the LCM thread, so its length bounds that thread's pause.
inline constexpr double kMaxSegmentDuration = 600.0;

// Build and validate a segment starting at `start` (m) against the model,
// the soft limits and the velocity/acceleration limits. Pure, for tests.
Validation validate_segment(const cpm_msgs::trajectory_command_t& cmd, const Vec3& start,
                            const ctl::Machine& machine, const LimitsConfig& limits, double dt);

class Server {
 public:
  Server(const DaemonConfig& cfg, ControlLoop& loop, ModelStore& models);
  ~Server();
  // Runs until `stop` is set. Throws Error when LCM cannot start.
  void run(const std::atomic<bool>& stop);
  // Publish what the loop queued (acks, snapshots, statistics); returns how many.
  int drain();
  // One LCM message as received on `channel`: decoded and handled exactly as
  // run() does (its subscriptions call this). Bytes that do not decode, or
  // whose strings carry an impossible length, are dropped and counted;
  // nothing a sender puts in a message escapes as an exception (fuzz/,
  // tests/daemon/test_hostile_*). Returns whether the message was handled.
  bool receive(const std::string& channel, const void* data, std::size_t size);
  [[nodiscard]] std::int64_t undecodable() const noexcept { return undecodable_; }
  // The daemon's LCM handle (tests on memq:// subscribe to the acks and
  // publish raw bytes on it; handle() then runs the daemon's subscriptions).
  [[nodiscard]] lcm::LCM& bus() noexcept { return *lcm_; }
  // The clock sessions expire by (s, monotonic); tests replace it.
  void set_clock(std::function<double()> now) { now_ = std::move(now); }
  // The session held now (0: none, or the holder went silent for
  // lcm.session_timeout s).
  [[nodiscard]] std::int64_t session() const;

 private:
  void on_raw(const lcm::ReceiveBuffer* rbuf, const std::string& channel);
  void on_control(const lcm::ReceiveBuffer* rbuf, const std::string& channel,
                  const cpm_msgs::control_command_t* msg);
  void on_trajectory(const lcm::ReceiveBuffer* rbuf, const std::string& channel,
                     const cpm_msgs::trajectory_command_t* msg);
  void publish_ack(std::int64_t id, std::int8_t source, std::int8_t code, bool ok, std::int16_t reason,
                   const std::string& message, Mode mode, std::int16_t depth, std::int64_t session = 0);
  bool send(Command& c);
  // Who may command (docs/daemon.md): false after publishing the refusal.
  bool admit(std::int64_t id, std::int8_t source, std::int8_t code, std::int64_t session, std::int64_t seq);
  void acquire(const cpm_msgs::control_command_t& m);

  DaemonConfig cfg_;
  ControlLoop& loop_;
  ModelStore& models_;
  std::unique_ptr<lcm::LCM> lcm_;
  cpm_msgs::state_t latest_{};
  bool have_state_ = false;
  int inflight_segments_ = 0;
  Vec3 planned_end_ = Vec3::Zero();
  bool ack_newer_than_state_ = false;
  Vec3 ack_end_ = Vec3::Zero();
  ctl::ControlLaw law_;
  ctl::Gains gains_;
  std::unique_ptr<Command> scratch_;
  std::int64_t undecodable_ = 0;
  std::function<double()> now_;
  std::int64_t session_ = 0;        // 0: nobody holds the machine
  std::int64_t session_nonce_ = 0;  // the holder's acquire nonce
  std::int64_t last_seq_ = 0;       // the holder's last admitted seq
  double last_heard_ = 0.0;         // now_() when the holder last spoke
  std::uint64_t session_salt_ = 0;  // random per daemon start: sessions do not repeat across restarts
  std::map<std::int64_t, const ctl::Machine*> pending_models_;
  std::map<std::int64_t, std::pair<ctl::ControlLaw, ctl::Gains>> pending_laws_;  // a Command is large: build it off the stack
};

// systemd's notification protocol ($NOTIFY_SOCKET), without libsystemd.
// Returns false when not run by systemd or when sending failed.
bool sd_notify(const std::string& message);
// The watchdog interval systemd asks for (s), 0 when none.
double sd_watchdog_interval();

}  // namespace cpm::daemon
