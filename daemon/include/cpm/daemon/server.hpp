// SPDX-License-Identifier: Apache-2.0
// The command/state side of cpmd (not real-time): one thread with the LCM
// handle. It decodes commands, authenticates them (docs/security.md: the
// operator's MAC, role and session, before anything costly is done for
// them), validates trajectories against the model and the configured limits
// (the expensive checks, with messages that say what and where), hands what
// passed to the loop through its SPSC queue, and publishes the loop's
// acknowledgements, state snapshots and statistics, and the refusals' counts.
#pragma once

#include <atomic>
#include <functional>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include <cpm_msgs/ack_t.hpp>
#include <cpm_msgs/control_command_t.hpp>
#include <cpm_msgs/path_command_t.hpp>
#include <cpm_msgs/security_t.hpp>
#include <cpm_msgs/trajectory_command_t.hpp>

#include "cpm/control/gain_check.hpp"
#include "cpm/daemon/auth.hpp"
#include "cpm/daemon/signing.hpp"
#include "cpm/daemon/loop.hpp"

namespace lcm {
class LCM;
class ReceiveBuffer;
}  // namespace lcm

namespace cpm::daemon {

class PathService;
class ModelLoader;

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

// Where control_command_t's one string (model_path) begins in its LCM
// encoding: the 8-byte type hash and every fixed field before it (id ..
// param_value). The server checks the string's length prefix there before
// decoding (lcm-gen's decoder trusts it).
inline constexpr std::size_t kControlModelPathOffset = 8 + 8 + 8 + 8 + 8 + 1 + 1 + 1 + 3 * 8 + 3 * 8  // hash .. kd
                                                       + 1 + 1 + 3 * 8 + 48 + 8;  // home_axes .. param_value

// The longest segment accepted (s): validation samples a segment at the
// loop's period in the LCM thread, so its length bounds that thread's pause.
inline constexpr double kMaxSegmentDuration = 600.0;

// Build and validate a segment starting at `start` (m) against the model,
// the soft limits and the velocity/acceleration limits. Pure, for tests.
Validation validate_segment(const cpm_msgs::trajectory_command_t& cmd, const Vec3& start,
                            const ctl::Machine& machine, const LimitsConfig& limits, double dt);

// The first number of a command that is not finite, or subnormal (never a
// machine quantity, and slow to compute with): its field name, e.g.
// "position[3][1]"; nullptr when every double of the message is finite and
// zero or normal. Unused fields count too: a clean sender leaves them 0.
std::string bad_number(const cpm_msgs::trajectory_command_t& cmd);
std::string bad_number(const cpm_msgs::control_command_t& cmd);
std::string bad_number(const cpm_msgs::path_command_t& cmd);

// ack_t.source of the acks of control and trajectory commands (path_message.hpp: of paths).
inline constexpr std::int8_t kControlSource = cpm_msgs::ack_t::SOURCE_CONTROL;
inline constexpr std::int8_t kTrajectorySource = cpm_msgs::ack_t::SOURCE_TRAJECTORY;

// The ack_t.REASON_* code of the loop's refusal (REASON_NONE for none).
std::int16_t ack_reason(Refusal r) noexcept;

// Whether a law and gains can hold the machine as cpmd runs it (the loop's
// rate, the velocity its backend gives, limits.following_error for a law
// without gravity): ctl::check_gains with the daemon's figures.
ctl::GainVerdict check_daemon_gains(const DaemonConfig& cfg, const ctl::Machine& model, ctl::ControlLaw law,
                                    const ctl::Gains& gains);

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
  // Stops on their own path: a second LCM handle on its own thread that
  // decodes only the control channel's stops and rings the loop
  // (ControlLoop::request_stop), so that nothing the LCM thread is busy with
  // delays braking. run() starts it; without it (tests cycling by hand) the
  // stop is acted on from the command queue alone.
  void start_stop_listener(const std::atomic<bool>& stop);
  [[nodiscard]] std::int64_t stops_heard() const noexcept { return stops_heard_.load(); }
  // The daemon's LCM handle (tests on memq:// subscribe to the acks and
  // publish raw bytes on it; handle() then runs the daemon's subscriptions).
  [[nodiscard]] lcm::LCM& bus() noexcept { return *lcm_; }
  // The clock sessions expire by (s, monotonic); tests replace it.
  void set_clock(std::function<double()> now) { now_ = std::move(now); }
  // This start's boot id (state_t.boot_id; random, never 0): acquires are
  // signed for it. Tests set a fixed one.
  [[nodiscard]] std::int64_t boot_id() const noexcept { return boot_id_; }
  void set_boot_id(std::int64_t id) noexcept;
  // Publishes the seal of what was published since the last one, now
  // (docs/security.md, "Signed state"; drain() does it when one is due:
  // every 32 messages, 10 ms after a message, 1 ms after an ack). Tests on
  // a stopped clock call it.
  void seal();
  // The wall clock acquires are checked against (s since the epoch); tests replace it.
  void set_wall_clock(std::function<double()> now) { wall_now_ = std::move(now); }
  // The session held now (0: none, or the holder went silent for
  // lcm.session_timeout s).
  [[nodiscard]] std::int64_t session() const;
  // Plans held by the path queue's store (tests: freed once retired).
  [[nodiscard]] std::size_t plans_held() const;
  // A program is being planned (tests wait for it).
  [[nodiscard]] bool planning() const;
  // A model file is being read and checked off this thread, or its result
  // waits for drain() (tests wait for it).
  [[nodiscard]] bool loading_model() const;

  // The operators who may command (docs/security.md). Any thread: the
  // housekeeping thread hands a freshly loaded table over whole; the LCM
  // thread takes the table in use at the start of each message. Without
  // one, nobody can command (a stop still works).
  void set_operators(std::shared_ptr<const OperatorTable> table);
  // A reload that failed (the table in use stays): counted in security_t.
  void note_reload_failure();
  [[nodiscard]] std::shared_ptr<const OperatorTable> operators() const;
  // Counted refusals (security_t without its header), for tests.
  [[nodiscard]] cpm_msgs::security_t security() const;

 private:
  void on_raw(const lcm::ReceiveBuffer* rbuf, const std::string& channel);
  // `raw`: the bytes as received (the MAC is over them).
  void on_control(const std::uint8_t* raw, std::size_t size, const cpm_msgs::control_command_t* msg);
  void on_trajectory(const std::uint8_t* raw, std::size_t size, const cpm_msgs::trajectory_command_t* msg);
  // The path queue (path_server.cpp): a program's chunk; planned programs to
  // the loop and plans the loop retired back to the store.
  void on_path(const std::uint8_t* raw, std::size_t size, const cpm_msgs::path_command_t* msg);
  void drain_paths();
  // A model load the worker finished: to the loop, or its refusal.
  void drain_model_load();
  // Where a new segment must start and how fast it must be moving there:
  // the end of what was sent, else of what the latest ack or state says is
  // queued (m, m/s).
  struct QueueEnd {
    Vec3 position = Vec3::Zero();
    Vec3 velocity = Vec3::Zero();
  };
  [[nodiscard]] QueueEnd queue_end_now() const;
  // Why a motion that needs the platform's position is refused now ("":
  // every actuator homed, as the latest state says).
  [[nodiscard]] std::string not_homed() const;
  void publish_ack(std::int64_t id, std::int8_t source, std::int8_t code, bool ok, std::int16_t reason,
                   const std::string& message, Mode mode, std::int16_t depth, std::int64_t session = 0);
  // A refusal of a command not (yet) proven to come from an operator, or a
  // replay: counted always, answered within security.refusal_acks_per_second.
  void refuse_limited(std::int64_t id, std::int8_t source, std::int8_t code, std::int16_t reason,
                      const std::string& message);
  // To the loop (false: its queue is full, answered REASON_BUSY, a model it
  // carried freed); what the loop's ack settles is recorded as pending.
  bool send(Command& c);
  // The server's side of a command the loop may still refuse: a model, a
  // law and gains, limits, kept by the command's id until its ack
  // (record_pending, when sent; settle_pending, when answered).
  void record_pending(const Command& c);
  void settle_pending(const Ack& a);
  // on_control's steps: authorize (false: refused, or a session command
  // answered here), then decode into the loop's command or a refusal, then send.
  struct Refused {
    std::int16_t reason = 0;  // ack_t.REASON_*
    std::string why;
  };
  bool authorize_control(const std::uint8_t* raw, std::size_t size, const cpm_msgs::control_command_t& m);
  // Fills `c`; c.kind stays none when nothing goes to the loop now (a model
  // load: the loader's thread answers).
  std::optional<Refused> decode_control(const cpm_msgs::control_command_t& m, Command& c);
  std::optional<Refused> decode_home(const cpm_msgs::control_command_t& m, Command& c) const;
  std::optional<Refused> decode_set_param(const cpm_msgs::control_command_t& m, Command& c) const;
  std::optional<Refused> decode_jog(const cpm_msgs::control_command_t& m, Command& c) const;
  std::optional<Refused> decode_select(const cpm_msgs::control_command_t& m, Command& c) const;
  std::optional<Refused> decode_load_model(const cpm_msgs::control_command_t& m);
  // The operator whose key made the message's MAC; nullptr (after the
  // counted, rate-limited refusal "not authorized") for anyone else.
  const Operator* authenticate(const OperatorTable* table, const std::uint8_t* raw, std::size_t size,
                               const std::uint8_t (&name)[kOperatorNameBytes], std::int64_t id, std::int8_t source,
                               std::int8_t code);
  // Who may command (docs/daemon.md): false after publishing the refusal.
  bool admit(std::int64_t id, std::int8_t source, std::int8_t code, std::int64_t session, std::int64_t seq,
             const Operator& op);
  void acquire(const cpm_msgs::control_command_t& m, const Operator& op);
  [[nodiscard]] ctl::GainVerdict check_gains_for(const ctl::Machine& model, ctl::ControlLaw law,
                                                const ctl::Gains& g) const;
  void log_security(double now);
  // A newly latched fault goes to the journal once, in fault_report's words.
  void journal_fault(const cpm_msgs::state_t& st);
  void publish_security(double now);
  void publish_params(double now);

  DaemonConfig cfg_;
  ControlLoop& loop_;
  ModelStore& models_;
  std::unique_ptr<lcm::LCM> lcm_;
  cpm_msgs::state_t latest_{};
  bool have_state_ = false;
  std::int64_t journaled_fault_cycle_ = -1;  // the fault last written to the journal
  int inflight_segments_ = 0;
  Vec3 planned_end_ = Vec3::Zero();
  Vec3 planned_end_v_ = Vec3::Zero();   // the velocity the queue will end with (m/s)
  // The queue's end from the newest of the last ack and the last state: the
  // state drained after an ack may be of a cycle before it (the snapshots
  // wait in their ring), and its queue end then lacks the acked segment.
  bool ack_newer_than_state_ = false;
  std::int64_t ack_cycle_ = -1;
  Vec3 ack_end_ = Vec3::Zero();
  Vec3 ack_end_v_ = Vec3::Zero();
  ctl::ControlLaw law_;
  ctl::Gains gains_;
  std::unique_ptr<Command> scratch_;
  std::unique_ptr<PathService> paths_;
  std::int64_t undecodable_ = 0;
  std::function<double()> now_;
  std::function<double()> wall_now_;
  std::int64_t session_ = 0;        // 0: nobody holds the machine
  std::int64_t session_nonce_ = 0;  // the holder's acquire nonce
  std::string session_operator_;    // the operator who holds it
  std::map<std::string, std::int64_t, std::less<>> last_acquire_seq_;  // per operator: acquires are not replayed
  std::int64_t last_seq_ = 0;       // the holder's last admitted seq
  double last_heard_ = 0.0;         // now_() when the holder last spoke
  std::uint64_t session_salt_ = 0;  // random per daemon start: sessions do not repeat across restarts
  std::int64_t boot_id_ = 0;        // random per daemon start, published in the state
  std::unique_ptr<Signer> signer_;  // null: no security.signing_key, nothing sealed
  // Encoded once, listed for the next seal (when signing), published.
  template <class M>
  void publish_sealed(const std::string& channel, M& m, bool ack = false);
  // Security (docs/security.md).
  mutable std::mutex ops_mu_;  // guards ops_ and the reload counters (housekeeping thread vs this one)
  std::shared_ptr<const OperatorTable> ops_;
  std::int64_t ops_loaded_utime_ = 0;
  std::int32_t reloads_ = 0, reload_failures_ = 0;
  cpm_msgs::security_t counts_{};      // the refusal counters (this thread)
  cpm_msgs::security_t logged_{};      // as of the last journal line
  double refusal_tokens_ = 0.0, refusal_tokens_at_ = 0.0;
  double last_security_publish_ = -1e300, last_security_log_ = -1e300;
  std::string last_stranger_;          // the last refused operator name (journal)
  std::map<std::int64_t, const ctl::Machine*> pending_models_;
  // CMD_LOAD_MODEL is read, parsed and checked here, off this thread, so
  // that no file can delay the next stop (docs/security.md).
  std::unique_ptr<ModelLoader> loader_;
  std::thread stop_listener_;
  std::atomic<std::int64_t> stops_heard_{0};
  std::atomic<bool> listener_quit_{false};
  std::map<std::int64_t, Settings> pending_settings_;  // CMD_SET_PARAM of a limit or the jog, until the loop's ack
  bool params_changed_ = true;                          // publish params_t at once
  double last_params_publish_ = -1e300;
  std::map<std::int64_t, std::pair<ctl::ControlLaw, ctl::Gains>> pending_laws_;  // a Command is large: build it off the stack
};

// Whether another daemon already publishes on this bus (its state, statistics
// or security channel), listening long enough to hear one at `rate_hz` and
// lcm.state_decimation. Before the loop starts; two daemons starting in the
// same instant may both hear nothing.
bool bus_has_another_daemon(const LcmConfig& lcm, double rate_hz);

// systemd's notification protocol ($NOTIFY_SOCKET), without libsystemd.
// Returns false when not run by systemd or when sending failed.
bool sd_notify(const std::string& message);
// The watchdog interval systemd asks for (s), 0 when none.
double sd_watchdog_interval();

}  // namespace cpm::daemon
