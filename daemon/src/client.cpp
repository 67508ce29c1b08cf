// SPDX-License-Identifier: Apache-2.0
#include "cpm/daemon/client.hpp"

#include <unistd.h>

#include <chrono>
#include <lcm/lcm-cpp.hpp>
#include <algorithm>
#include <cerrno>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <utility>
#include <random>

#include "cpm/daemon/modes.hpp"

namespace cpm::daemon {

using Clock = std::chrono::steady_clock;

const char* mode_text(std::int8_t mode) noexcept {
  if (mode < 0 || mode > static_cast<std::int8_t>(Mode::jogging)) return "unknown";
  return mode_name(static_cast<Mode>(mode));
}

std::string fault_text(std::int32_t mask) {
  std::string s;
  for (std::uint32_t bit = 1; bit != 0 && bit <= static_cast<std::uint32_t>(mask); bit <<= 1)
    if (static_cast<std::uint32_t>(mask) & bit) {
      if (!s.empty()) s.push_back(',');
      s.append(fault_bit_name(bit));
    }
  return s;
}

namespace {
// A client records a 1 kHz stream: ask the kernel for a socket buffer that
// holds a few seconds of it (capped by net.core.rmem_max; 4 MB is about 3 s
// of state messages), unless the URL already says how big.
std::string with_receive_buffer(const std::string& url) {
  if (url.rfind("udpm://", 0) != 0 || url.find("recv_buf_size=") != std::string::npos) return url;
  return url + (url.find('?') == std::string::npos ? "?" : "&") + "recv_buf_size=4194304";
}
}  // namespace

std::string daemon_public_key_path(const LcmConfig& cfg) {
  if (!cfg.daemon_public_key.empty()) return cfg.daemon_public_key;
  if (const char* env = std::getenv("CPM_DAEMON_KEY"); env && *env) return env;
  if (const char* home = std::getenv("HOME"); home && *home) {
    const std::string p = std::string(home) + "/.config/cpm/cpmd.pub";
    if (::access(p.c_str(), F_OK) == 0) return p;
  }
  return "";
}

std::optional<cpm_msgs::ack_t> decode_ack(const void* data, std::size_t size) {
  // hash, utime, id (8 each), source, command, accepted (1), reason (2): then message.
  // After it: mode, queue_depth, session, boot_id, sign_counter.
  constexpr std::size_t kHead = 8 + 8 + 8 + 1 + 1 + 1 + 2, kTail = 1 + 2 + 8 + 8 + 8;
  if (size < kHead + 4 + 1 + kTail || size > (1u << 20)) return std::nullopt;
  const auto* p = static_cast<const std::uint8_t*>(data) + kHead;
  const auto len = static_cast<std::int32_t>((std::uint32_t{p[0]} << 24) | (std::uint32_t{p[1]} << 16) |
                                             (std::uint32_t{p[2]} << 8) | std::uint32_t{p[3]});
  if (len < 1 || static_cast<std::size_t>(len) != size - kHead - 4 - kTail) return std::nullopt;
  // A string LCM wrote ends in its only NUL.
  if (std::memchr(p + 4, 0, static_cast<std::size_t>(len)) != p + 4 + len - 1) return std::nullopt;
  cpm_msgs::ack_t a;
  if (a.decode(data, 0, static_cast<int>(size)) != static_cast<int>(size)) return std::nullopt;
  return a;
}

Client::Client(const LcmConfig& cfg, std::optional<Credentials> operator_key)
    : cfg_(cfg), creds_(std::move(operator_key)) {
  lcm_ = std::make_unique<lcm::LCM>(with_receive_buffer(cfg_.url));
  if (!lcm_->good()) throw Error("lcm: cannot open '" + cfg_.url + "'");
  // LCM queues at most 30 messages per subscription between its receive
  // thread and handle(), then drops silently: 30 ms of the state stream at
  // 1 kHz. A client descheduled for longer (a loaded machine, a recorder
  // writing to disk) would lose state. 10 s of queue costs a few MB at most
  // and only while the client is behind.
  constexpr int kQueuedMessages = 10000;
  lcm_->subscribe(cfg_.ack_channel, &Client::on_ack, this)->setQueueCapacity(kQueuedMessages);
  lcm_->subscribe(cfg_.state_channel, &Client::on_state_msg, this)->setQueueCapacity(kQueuedMessages);
  lcm_->subscribe(cfg_.stats_channel, &Client::on_stats_msg, this)->setQueueCapacity(kQueuedMessages);
  lcm_->subscribe(cfg_.security_channel, &Client::on_security_msg, this)->setQueueCapacity(100);
  lcm_->subscribe(cfg_.drives_channel, &Client::on_drives_msg, this)->setQueueCapacity(100);
  lcm_->subscribe(cfg_.params_channel, &Client::on_params, this)->setQueueCapacity(100);
  lcm_->subscribe(cfg_.seal_channel, &Client::on_seal, this)->setQueueCapacity(kQueuedMessages);
  // Said now, before a full-screen view (cpm watch) takes the terminal.
  if (const std::string pk = daemon_public_key_path(cfg_); !pk.empty())
    verify_with(read_public_key_file(pk));
  else
    unverified();
  std::random_device rd;
  next_id_ = (static_cast<std::int64_t>(rd() & 0x7fffffu) << 32) ^ (static_cast<std::int64_t>(::getpid()) << 8);
  nonce_ = static_cast<std::int64_t>(((std::uint64_t{rd()} << 32) ^ rd()) & 0x7FFFFFFFFFFFFFFFull) | 1;
}

Client::~Client() {
  try {
    if (session_ != 0) {
      cpm_msgs::control_command_t c{};
      c.command = cpm_msgs::control_command_t::CMD_RELEASE;
      c.id = next_id();
      stamp(c);
      lcm_->publish(cfg_.control_channel, &c);  // not waited for: it expires anyway
    }
  } catch (...) {
  }
}

namespace {
double steady_now() { return std::chrono::duration<double>(Clock::now().time_since_epoch()).count(); }
std::int64_t wall_us() {
  return std::chrono::duration_cast<std::chrono::microseconds>(
             std::chrono::system_clock::now().time_since_epoch()).count();
}
}  // namespace

template <class M>
void Client::stamp(M& m) {
  m.session = session_;
  m.seq = ++seq_;
  m.utime = wall_us();
  if (creds_) sign(m, *creds_);
  last_sent_ = steady_now();
}

void Client::need_key(std::int8_t command) const {
  if (creds_ || command == cpm_msgs::control_command_t::CMD_STOP) return;
  throw Error(
      "no operator key: only `stop` and reading the state need none. Give --key FILE, set CPM_KEY_FILE, or put the "
      "key cpmd knows you by in ~/.config/cpm/operator.key (docs/security.md)");
}

bool Client::lost_session(const cpm_msgs::ack_t& a) noexcept {
  return !a.accepted && a.reason == cpm_msgs::ack_t::REASON_NOT_HOLDER;
}

void Client::acquire(double timeout_s) {
  need_key(cpm_msgs::control_command_t::CMD_ACQUIRE);
  // Signed for this start of cpmd (its boot id, from its newest state): a
  // recording of it is refused by any later start. What is queued is read
  // first, so that the newest state is the one used; if cpmd restarted since,
  // the acquire is refused as unauthorized and made again for the new boot.
  while (lcm_->handleTimeout(0) > 0) {
  }
  std::optional<cpm_msgs::state_t> st = last_state_;
  for (int attempt = 0;; ++attempt) {
    if (!st) st = state(timeout_s);
    need_same_boot();
    if (!st)
      throw Error("no state from cpmd within " + std::to_string(timeout_s) + " s: is it running on " + cfg_.url + "?");
    cpm_msgs::control_command_t c{};
    c.command = cpm_msgs::control_command_t::CMD_ACQUIRE;
    c.id = next_id();
    c.session = nonce_;
    c.utime = wall_us();
    // The wall clock, rising: cpmd refuses an acquire that is old or not newer
    // than the operator's last (a recorded one played back).
    c.seq = last_acquire_seq_ = std::max(c.utime, last_acquire_seq_ + 1);
    Credentials for_boot = *creds_;
    for_boot.boot = st->boot_id;
    sign(c, for_boot);
    lcm_->publish(cfg_.control_channel, &c);
    const cpm_msgs::ack_t a = wait_ack(c.id, timeout_s);
    if (!a.accepted && a.reason == cpm_msgs::ack_t::REASON_NOT_AUTHORIZED && attempt == 0) {
      const std::int64_t used = st->boot_id;
      st = state(timeout_s);
      need_same_boot();  // verified state of another boot is refused: a restart is reported
      if (st && st->boot_id != used) continue;  // cpmd restarted meanwhile (unverified clients only)
    }
    if (!a.accepted || a.session == 0) throw Error("cpmd refused to let this process command the machine: " + a.message);
    session_ = a.session;
    seq_ = 0;
    last_sent_ = steady_now();
    return;
  }
}

bool Client::release(double timeout_s) {
  if (session_ == 0) return true;
  cpm_msgs::control_command_t c{};
  c.command = cpm_msgs::control_command_t::CMD_RELEASE;
  c.id = next_id();
  stamp(c);
  session_ = 0;
  lcm_->publish(cfg_.control_channel, &c);
  try {
    return wait_ack(c.id, timeout_s).accepted;
  } catch (const Error&) {
    return false;
  }
}

void Client::keep_alive() {
  if (session_ == 0 || steady_now() - last_sent_ < 0.25) return;
  cpm_msgs::control_command_t c{};
  c.command = cpm_msgs::control_command_t::CMD_PING;
  c.id = next_id();
  stamp(c);
  pings_.insert(c.id);
  lcm_->publish(cfg_.control_channel, &c);
}

std::int64_t Client::next_id() { return ++next_id_; }

void Client::refused(Trust t, const char* what) {
  if (refused_cb_) return refused_cb_(t, what);
  if (told_[static_cast<int>(t)]) return;
  told_[static_cast<int>(t)] = true;
  std::fprintf(stderr, "cpm: %s refused: %s (docs/security.md, \"Signed state\"); said once, counted after\n", what,
               trust_text(t));
}

void Client::unverified() {
  if (std::exchange(told_unverified_, true)) return;
  std::fprintf(stderr,
               "cpm: warning: no public key of cpmd (--daemon-key, $CPM_DAEMON_KEY, ~/.config/cpm/cpmd.pub): its state, "
               "acks and the rest CANNOT BE VERIFIED and are shown as sent, forged or not (docs/security.md, \"Signed "
               "state\")\n");
}

namespace {
const char* what_of(Stream s) noexcept {
  constexpr const char* kWhat[kStreams] = {"a state", "an ack", "a drives message", "a statistics message",
                                           "a parameter table", "a security count"};
  return kWhat[static_cast<int>(s)];
}
}  // namespace

void Client::receive(Stream s, const lcm::ReceiveBuffer* rbuf, Held&& m) {
  if (!verifier_) return std::visit([this](const auto& x) { use(x); }, m);
  // A state or ack with no counter comes from a cpmd that does not sign (or is forged as one).
  const bool no_counter = std::visit(
      [](const auto& x) {
        if constexpr (requires { x.sign_counter; }) return x.sign_counter == 0;
        return false;
      },
      m);
  if (no_counter) return refused(verifier_->refuse(Trust::unsigned_message), what_of(s));
  const std::uint64_t ticket = ++next_ticket_;
  const Trust t = verifier_->offer(s, rbuf->data, rbuf->data_size, ticket);
  if (t == Trust::ok) return std::visit([this](const auto& x) { use(x); }, m);
  if (t == Trust::pending) {
    held_.emplace(ticket, std::move(m));
    // The verifier let go of the oldest it held (too many waiting): so does this.
    while (held_.size() > verifier_->waiting()) {
      refused(Trust::unsealed, what_of(static_cast<Stream>(held_.begin()->second.index())));
      held_.erase(held_.begin());
    }
    return;
  }
  refused(t, what_of(s));
}

void Client::on_seal(const lcm::ReceiveBuffer* rbuf, const std::string&) {
  if (!verifier_) return;
  decided_.clear();
  const Trust t = verifier_->seal(rbuf->data, rbuf->data_size, decided_);
  if (t == Trust::other_boot)
    if (const auto s = decode_seal(rbuf->data, rbuf->data_size)) restarted_ = s->boot_id;
  if (t != Trust::ok) refused(t, "a seal");
  for (const auto& v : decided_) {
    const auto it = held_.find(v.ticket);
    if (it == held_.end()) continue;
    Held m = std::move(it->second);
    held_.erase(it);
    if (v.trust == Trust::ok)
      std::visit([this](const auto& x) { use(x); }, m);
    else
      refused(v.trust, what_of(v.stream));
  }
}

std::string Client::trust_note() const {
  if (!verifier_ || verifier_->refused_total() == 0) return "";
  constexpr const char* kCause[] = {"", "unsigned", "bad seal signature", "replayed or reordered", "another boot",
                                    "no seal lists them", ""};
  std::string s = "refused as not cpmd's: " + std::to_string(verifier_->refused_total()) + " (";
  bool first = true;
  for (int t = 1; t < 6; ++t)
    if (const auto n = verifier_->refused(static_cast<Trust>(t)); n > 0) {
      s += (first ? "" : ", ") + std::to_string(n) + " " + kCause[t];
      first = false;
    }
  return s + ")";
}

void Client::no_seal() {
  if (!verifier_ || verifier_->seals_verified() > 0 || verifier_->waiting() == 0 || std::exchange(told_no_seal_, true))
    return;
  std::fprintf(stderr,
               "cpm: %zu messages from cpmd wait for a seal and none came: what this cpmd publishes cannot be "
               "verified (an old cpmd, or one without security.signing_key); nothing unverified is shown "
               "(docs/security.md, \"Signed state\")\n",
               verifier_->waiting());
}

void Client::need_same_boot() const {
  if (restarted_ != 0)
    throw Error("cpmd restarted since this client began (boot id " + std::to_string(verifier_->boot()) + ", now " +
                std::to_string(restarted_) + "): its new state is not taken on trust; start again");
}

void Client::on_ack(const lcm::ReceiveBuffer* rbuf, const std::string&) {
  auto a = decode_ack(rbuf->data, rbuf->data_size);
  if (!a) return;  // not an ack: somebody else's bytes
  receive(Stream::ack, rbuf, std::move(*a));
}

void Client::use(const cpm_msgs::ack_t& a) {
  const cpm_msgs::ack_t* m = &a;
  if (pings_.erase(m->id)) {
    // A keep-alive refused: the session is gone (daemon restarted, or it
    // expired); the next command acquires a new one.
    if (lost_session(*m)) session_ = 0;
    return;
  }
  if (m->source == 1 && m->command == cpm_msgs::control_command_t::CMD_JOG && m->id != 0 &&
      std::find(jog_ids_.begin(), jog_ids_.end(), m->id) != jog_ids_.end()) {
    // One of this client's jogs: kept as the latest, never queued (a held key
    // sends 20 a second and nobody waits for most of them).
    if (lost_session(*m)) session_ = 0;
    if (!last_jog_ack_ || m->id >= last_jog_ack_->id) last_jog_ack_ = *m;
    return;
  }
  acks_[m->id] = *m;
}

void Client::use(const cpm_msgs::state_t& m) {
  last_state_ = m;
  if (state_cb_) state_cb_(m);
}
void Client::on_state_msg(const lcm::ReceiveBuffer* rbuf, const std::string&, const cpm_msgs::state_t* m) {
  receive(Stream::state, rbuf, *m);
}
void Client::on_stats_msg(const lcm::ReceiveBuffer* rbuf, const std::string&, const cpm_msgs::loop_stats_t* m) {
  receive(Stream::stats, rbuf, *m);
}
void Client::on_security_msg(const lcm::ReceiveBuffer* rbuf, const std::string&, const cpm_msgs::security_t* m) {
  receive(Stream::security, rbuf, *m);
}
void Client::on_drives_msg(const lcm::ReceiveBuffer* rbuf, const std::string&, const cpm_msgs::drives_t* m) {
  receive(Stream::drives, rbuf, *m);
}
void Client::on_params(const lcm::ReceiveBuffer* rbuf, const std::string&) {
  // lcm-gen's decoding takes the counts and string lengths as sent: a
  // negative one throws (std::length_error) instead of returning an error.
  cpm_msgs::params_t p;
  try {
    if (rbuf->data_size > (1u << 20) ||
        p.decode(rbuf->data, 0, static_cast<int>(rbuf->data_size)) != static_cast<int>(rbuf->data_size))
      return;
  } catch (const std::exception&) {
    return;
  }
  receive(Stream::params, rbuf, std::move(p));
}

template <class M>
std::optional<M> Client::next(std::optional<M>& slot, double timeout_s, int poll_ms) {
  slot.reset();
  const auto end = Clock::now() + std::chrono::duration<double>(timeout_s);
  while (!slot && Clock::now() < end) {
    keep_alive();
    lcm_->handleTimeout(poll_ms);
  }
  if (!slot) no_seal();
  return slot;
}

std::optional<cpm_msgs::security_t> Client::security(double timeout_s) { return next(last_security_, timeout_s, 50); }

int Client::handle(double timeout_s) {
  const auto end = Clock::now() + std::chrono::duration<double>(timeout_s);
  int n = 0;
  for (;;) {
    const auto left = std::chrono::duration_cast<std::chrono::milliseconds>(end - Clock::now()).count();
    if (left <= 0) break;
    keep_alive();
    const int rc = lcm_->handleTimeout(static_cast<int>(std::min<long>(left, 100)));
    if (rc < 0 && errno == EINTR) break;  // a signal (Ctrl-C): the caller looks at why
    if (rc < 0) throw Error("lcm: receive failed");
    if (rc == 0) continue;
    ++n;
  }
  return n;
}

cpm_msgs::ack_t Client::wait_ack(std::int64_t id, double timeout_s) {
  const auto end = Clock::now() + std::chrono::duration<double>(timeout_s);
  while (Clock::now() < end) {
    if (last_jog_ack_ && last_jog_ack_->id == id) return *last_jog_ack_;
    if (auto it = acks_.find(id); it != acks_.end()) {
      cpm_msgs::ack_t a = it->second;
      acks_.erase(it);
      return a;
    }
    keep_alive();
    lcm_->handleTimeout(20);
  }
  if (last_jog_ack_ && last_jog_ack_->id == id) return *last_jog_ack_;
  if (auto it = acks_.find(id); it != acks_.end()) return it->second;
  no_seal();
  throw Error("no answer from cpmd within " + std::to_string(timeout_s) + " s (is it running? LCM URL " +
              cfg_.url + ", channel " + cfg_.control_channel + ")");
}

cpm_msgs::ack_t Client::control(cpm_msgs::control_command_t cmd, double timeout_s) {
  using C = cpm_msgs::control_command_t;
  if (cmd.command == C::CMD_ACQUIRE) {
    acquire(timeout_s);
    cpm_msgs::ack_t a{};
    a.accepted = true;
    a.session = session_;
    return a;
  }
  const bool stop = cmd.command == C::CMD_STOP;
  need_key(cmd.command);
  for (int attempt = 0;; ++attempt) {
    if (session_ == 0 && !stop) acquire(timeout_s);
    cmd.id = next_id();
    stamp(cmd);  // a stop without a session goes out with session 0: cpmd takes it from anyone
    lcm_->publish(cfg_.control_channel, &cmd);
    cpm_msgs::ack_t a = wait_ack(cmd.id, timeout_s);
    if (cmd.command == C::CMD_RELEASE) session_ = 0;
    if (!lost_session(a) || attempt > 0 || stop) return a;
    session_ = 0;  // expired or the daemon restarted: acquire once more
  }
}

cpm_msgs::ack_t Client::control(std::int8_t command, double timeout_s) {
  cpm_msgs::control_command_t c{};
  c.command = command;
  return control(c, timeout_s);
}

cpm_msgs::ack_t Client::home(std::uint8_t axes, double timeout_s) {
  if (axes > 7) throw Error("home: actuators are bits 0-2 (1, 2, 4), not " + std::to_string(axes));
  cpm_msgs::control_command_t c{};
  c.command = cpm_msgs::control_command_t::CMD_HOME;
  c.home_axes = static_cast<std::int8_t>(axes);
  return control(c, timeout_s);
}

std::int64_t Client::jog(std::int8_t frame, const double v[3]) {
  using C = cpm_msgs::control_command_t;
  need_key(C::CMD_JOG);
  if (session_ == 0) acquire();
  C c{};
  c.command = C::CMD_JOG;
  c.jog_frame = frame;
  for (int i = 0; i < 3; ++i) c.jog_velocity[i] = v[i];
  c.id = next_id();
  jog_ids_[jog_next_++ % jog_ids_.size()] = c.id;
  stamp(c);
  lcm_->publish(cfg_.control_channel, &c);
  return c.id;
}

cpm_msgs::ack_t Client::set_param(const std::string& name, double value, double timeout_s) {
  cpm_msgs::control_command_t c{};
  if (name.empty() || name.size() >= sizeof c.param_name)
    throw Error("set: a parameter's name has 1 to " + std::to_string(sizeof c.param_name - 1) + " characters, '" + name +
                "' has " + std::to_string(name.size()));
  c.command = cpm_msgs::control_command_t::CMD_SET_PARAM;
  std::memcpy(c.param_name, name.data(), name.size());
  c.param_value = value;
  return control(c, timeout_s);
}

template <class M>
std::int64_t Client::send_motion(const std::string& channel, M& cmd) {
  need_key(0);
  if (session_ == 0) acquire();
  if (cmd.id == 0) cmd.id = next_id();
  stamp(cmd);
  lcm_->publish(channel, &cmd);
  return cmd.id;
}

std::int64_t Client::send_trajectory(cpm_msgs::trajectory_command_t cmd) {
  return send_motion(cfg_.trajectory_channel, cmd);
}

std::int64_t Client::send_path(cpm_msgs::path_command_t cmd) { return send_motion(cfg_.path_channel, cmd); }


cpm_msgs::ack_t Client::trajectory(cpm_msgs::trajectory_command_t cmd, double timeout_s) {
  cpm_msgs::ack_t a = wait_ack(send_trajectory(cmd), timeout_s);
  if (!lost_session(a)) return a;
  session_ = 0;  // expired or the daemon restarted: acquire once more
  return wait_ack(send_trajectory(cmd), timeout_s);
}

std::optional<cpm_msgs::state_t> Client::state(double timeout_s) { return next(last_state_, timeout_s, 20); }

std::optional<cpm_msgs::loop_stats_t> Client::stats(double timeout_s) { return next(last_stats_, timeout_s, 50); }

std::optional<cpm_msgs::drives_t> Client::drives(double timeout_s) { return next(last_drives_, timeout_s, 20); }

std::optional<cpm_msgs::params_t> Client::params(double timeout_s) { return next(last_params_, timeout_s, 50); }

}  // namespace cpm::daemon
