// SPDX-License-Identifier: Apache-2.0
#include "cpm/daemon/server.hpp"

#include <malloc.h>
#include <pthread.h>
#include <sys/socket.h>
#include <sys/un.h>
#include <unistd.h>

#include <chrono>
#include <cmath>
#include <condition_variable>
#include <optional>
#include <thread>
#include <cstdio>
#include <cstdlib>
#include <cstdint>
#include <cstring>
#include <map>
#include <memory>
#include <lcm/lcm-cpp.hpp>
#include <random>
#include <sstream>
#include <stdexcept>

#include "cpm/daemon/fault_report.hpp"
#include "cpm/daemon/log.hpp"
#include "cpm/daemon/params.hpp"
#include "cpm/daemon/rt.hpp"
#include "cpm/daemon/path_message.hpp"
#include "path_service.hpp"

namespace cpm::daemon {

using cpm_msgs::ack_t;
using cpm_msgs::control_command_t;
using cpm_msgs::trajectory_command_t;

ModelStore::ModelStore(std::unique_ptr<ctl::Machine> first) : current_(first.get()) {
  models_.push_back(std::move(first));
}

const ctl::Machine* ModelStore::add(std::unique_ptr<ctl::Machine> m) {
  models_.push_back(std::move(m));
  return models_.back().get();
}

void ModelStore::release(const ctl::Machine* m) {
  if (m == current_) return;
  for (auto it = models_.begin(); it != models_.end(); ++it)
    if (it->get() == m) {
      models_.erase(it);
      return;
    }
}

namespace {

std::string mm(const Vec3& p) {
  char b[96];
  std::snprintf(b, sizeof b, "(%.3f, %.3f, %.3f) mm", p.x() * 1e3, p.y() * 1e3, p.z() * 1e3);
  return b;
}

std::string mm_s(double v) {
  char b[48];
  std::snprintf(b, sizeof b, "%.1f mm/s", v * 1e3);
  return b;
}

// The name as the journal may print it (only valid names reach here, but
// the journal is no place to trust that).
std::string printable(std::string s, std::size_t max = 64) {
  if (s.size() > max) s.resize(max);
  for (char& c : s)
    if (static_cast<unsigned char>(c) < 0x20 || static_cast<unsigned char>(c) > 0x7e) c = '?';
  return s;
}

bool finite3(const double* v) { return std::isfinite(v[0]) && std::isfinite(v[1]) && std::isfinite(v[2]); }

Validation reject(std::int16_t reason, std::string msg) {
  Validation v;
  v.reason = reason;
  v.message = std::move(msg);
  return v;
}

// Every sample inside the soft-limit box.
std::string box_violation(const ctl::Trajectory& tr, const LimitsConfig& limits, double dt) {
  const long n = static_cast<long>(std::ceil(tr.duration() / dt));
  for (long k = 0; k <= n; ++k) {
    const double t = std::min(k * dt, tr.duration());
    const Vec3 p = tr.sample(t).p;
    for (int i = 0; i < 3; ++i)
      if (p[i] < limits.workspace_min[i] - 1e-9 || p[i] > limits.workspace_max[i] + 1e-9) {
        std::ostringstream os;
        os << "at t = " << t << " s the platform would be at " << mm(p) << ", outside the soft limits on "
           << "xyz"[i] << " [" << limits.workspace_min[i] * 1e3 << ", " << limits.workspace_max[i] * 1e3 << "] mm";
        return os.str();
      }
  }
  return {};
}

}  // namespace

// One model load at a time, on its own thread: the file is read, its YAML
// bounded and parsed, the machine built and checked there. What the parse
// allocated is handed back to the system before the result is (malloc_trim):
// cpmd locks memory as it is touched (rt.cpp), and a parse's heap left
// mapped would stay locked and resident for the daemon's life.
class ModelLoader {
 public:
  struct Result {
    std::int64_t id = 0;
    std::unique_ptr<ctl::Machine> machine;  // nullptr: refused
    std::string summary;                    // for the bus: the reason and the line, never the file's bytes
    std::string journal;                    // for cpmd's journal: the path too
    std::string operator_name;              // who asked (the journal)
  };
  ~ModelLoader() {
    {
      const std::lock_guard<std::mutex> lock(mu_);
      quit_ = true;
    }
    cv_.notify_all();
    if (started_) pthread_join(thread_, nullptr);
  }
  // Whether a load is in progress or its result not yet taken.
  [[nodiscard]] bool busy() const {
    const std::lock_guard<std::mutex> lock(mu_);
    return pending_ || result_.has_value();
  }
  void start(std::int64_t id, std::string path, std::string operator_name, const DaemonConfig& cfg) {
    {
      const std::lock_guard<std::mutex> lock(mu_);
      id_ = id;
      operator_name_ = std::move(operator_name);
      path_ = std::move(path);
      model_dir_ = cfg.security.model_dir;
      force_limit_ = cfg.limits.force;
      rate_hz_ = cfg.loop.rate_hz;
      pending_ = true;
    }
    // Started by the first load, from the LCM thread: it inherits that
    // thread's CPUs (never loop.cpu, main.cpp).
    if (!started_) started_ = spawn();
    cv_.notify_all();
  }
  // The finished load, if any (never waits for one).
  std::optional<Result> take() {
    const std::unique_lock<std::mutex> lock(mu_, std::try_to_lock);
    if (!lock.owns_lock() || !result_) return std::nullopt;
    std::optional<Result> r = std::move(result_);
    result_.reset();
    return r;
  }

 private:
  // The loader's stack is mapped locked (mlockall MCL_FUTURE) for cpmd's
  // life: 1 MiB, not glibc's 8 MiB. The parse never recurses deeper than
  // kMaxModelDepth; a load of the largest files touches well under this.
  static constexpr std::size_t kStackBytes = 1024 * 1024;
  bool spawn() {
    pthread_attr_t attr;
    if (pthread_attr_init(&attr) != 0) throw std::runtime_error("model loader: pthread_attr_init failed");
    pthread_attr_setstacksize(&attr, kStackBytes);
    const int rc = pthread_create(
        &thread_, &attr,
        [](void* self) -> void* {
          static_cast<ModelLoader*>(self)->run();
          return nullptr;
        },
        this);
    pthread_attr_destroy(&attr);
    if (rc != 0) throw std::runtime_error(std::string("model loader: cannot start its thread: ") + std::strerror(rc));
    return true;
  }
  void run() {
    std::unique_lock<std::mutex> lock(mu_);
    for (;;) {
      cv_.wait(lock, [this] { return quit_ || (pending_ && !result_); });
      if (quit_) return;
      Result r;
      r.id = id_;
      r.operator_name = operator_name_;
      const std::string path = path_, dir = model_dir_;
      const double force = force_limit_, rate = rate_hz_;
      lock.unlock();
      // The parse's heap is not locked while it lives, so that malloc_trim
      // hands it back (locked pages it cannot); the model built is locked
      // again at the end (docs/security.md, "Model loads").
      std::optional<FutureLocksPaused> unlocked(std::in_place);
      try {
        ctl::MachineModel model = load_model_beneath(dir, path);
        model.force_limit = std::min(model.force_limit, force);
        auto machine = std::make_unique<ctl::Machine>(model);
        ctl::check_delay_fits(machine->actuation_delay(), rate);
        r.machine = std::move(machine);
      } catch (const ModelLoadError& e) {
        r.summary = e.summary;
      } catch (const std::exception& e) {
        // Not the file's words (they may quote it): what failed is in the model's checks.
        r.summary = "the model cannot be used on this machine";
        r.journal = e.what();
      }
      if (!r.machine) r.journal = "load_model '" + path + "': " + (r.journal.empty() ? r.summary : r.journal);
      malloc_trim(0);
      unlocked.reset();
      lock.lock();
      pending_ = false;
      result_ = std::move(r);
    }
  }
  mutable std::mutex mu_;
  std::condition_variable cv_;
  pthread_t thread_{};
  bool started_ = false;  // touched only by start() and the destructor (the LCM thread's side)
  bool quit_ = false, pending_ = false;
  std::int64_t id_ = 0;
  std::string path_, model_dir_, operator_name_;
  double force_limit_ = 0.0, rate_hz_ = 0.0;
  std::optional<Result> result_;
};

// Long (about 80 lines) on purpose: one switch over the trajectory kinds,
// each checked before the segment is built, then the checks every kind shares.
Validation validate_segment(const trajectory_command_t& c, const Vec3& start, const ctl::Machine& machine,
                            const LimitsConfig& limits, double dt) {
  Validation out;
  out.segment.id = c.id;
  out.segment.start = start;
  try {
    if (c.kind == trajectory_command_t::KIND_MOVE) {
      if (!finite3(c.target)) return reject(ack_t::REASON_INVALID, "move: target is not finite");
      if (!std::isfinite(c.max_velocity) || !std::isfinite(c.max_acceleration) || !std::isfinite(c.max_jerk) ||
          c.max_velocity <= 0 || c.max_acceleration <= 0 || c.max_jerk <= 0)
        return reject(ack_t::REASON_INVALID, "move: max_velocity, max_acceleration and max_jerk must be finite and > 0");
      if (c.max_velocity > limits.velocity)
        return reject(ack_t::REASON_LIMIT, "move: max_velocity " + std::to_string(c.max_velocity) +
                                               " m/s exceeds limits.velocity " + std::to_string(limits.velocity) +
                                               " m/s");
      if (c.max_acceleration > limits.acceleration)
        return reject(ack_t::REASON_LIMIT, "move: max_acceleration " + std::to_string(c.max_acceleration) +
                                               " m/s^2 exceeds limits.acceleration " +
                                               std::to_string(limits.acceleration) + " m/s^2");
      const Vec3 target(c.target[0], c.target[1], c.target[2]);
      if (Status s = kin::check_pose(machine.kinematics(), machine.model().strokes, target, {}); !s)
        return reject(ack_t::REASON_WORKSPACE, "move: target " + mm(target) + " is outside the workspace: " + describe(s));
      ctl::MotionLimits lim;
      lim.velocity = c.max_velocity;
      lim.acceleration = c.max_acceleration;
      lim.jerk = c.max_jerk;
      out.segment.traj.emplace<ctl::PointToPoint>(start, target, lim);
    } else if (c.kind == trajectory_command_t::KIND_CIRCLE) {
      if (!finite3(c.centre) || !std::isfinite(c.radius) || !std::isfinite(c.angular_speed) ||
          !std::isfinite(c.start_angle) || !std::isfinite(c.cruise_time) || !std::isfinite(c.ramp_time))
        return reject(ack_t::REASON_INVALID, "circle: a parameter is not finite");
      if (c.plane < 0 || c.plane > 2) return reject(ack_t::REASON_INVALID, "circle: plane must be 0 (xy), 1 (yz) or 2 (zx)");
      const double speed = std::abs(c.radius * c.angular_speed);
      if (speed > limits.velocity)
        return reject(ack_t::REASON_LIMIT, "circle: speed " + std::to_string(speed) + " m/s exceeds limits.velocity " +
                                               std::to_string(limits.velocity) + " m/s");
      ctl::CircleSpec s;
      s.centre = Vec3(c.centre[0], c.centre[1], c.centre[2]);
      s.radius = c.radius;
      s.plane = static_cast<ctl::CirclePlane>(c.plane);
      s.angular_speed = c.angular_speed;
      s.start_angle = c.start_angle;
      s.cruise_time = c.cruise_time;
      s.ramp_time = c.ramp_time;
      out.segment.traj.emplace<ctl::CircleTrajectory>(s);
    } else if (c.kind == trajectory_command_t::KIND_STREAM) {
      if (c.count < 2 || c.count > StreamTrajectory::kMaxPoints)
        return reject(ack_t::REASON_INVALID, "stream: count must be 2..100, got " + std::to_string(c.count));
      out.segment.traj.emplace<StreamTrajectory>(c.count, c.time, c.position, c.velocity);
    } else {
      return reject(ack_t::REASON_INVALID, "unknown trajectory kind " + std::to_string(c.kind));
    }
  } catch (const Error& e) {
    return reject(ack_t::REASON_INVALID, e.what());
  }
  const ctl::Trajectory& tr = *out.segment.get();
  // Bounded before anything samples it: the checks below walk the segment
  // at the loop's period, in the thread that also publishes the state.
  const double duration = tr.duration();
  if (!std::isfinite(duration) || duration < 0.0)
    return reject(ack_t::REASON_INVALID, "the segment's duration is not a finite time >= 0 s");
  if (duration > kMaxSegmentDuration)
    return reject(ack_t::REASON_LIMIT, "the segment lasts " + std::to_string(duration) + " s, more than the " +
                                           std::to_string(kMaxSegmentDuration) +
                                           " s one segment may last; send a long motion as consecutive segments");
  const Vec3 p0 = tr.sample(0.0).p;
  if ((p0 - start).norm() > 1e-6)
    return reject(ack_t::REASON_NOT_CONTINUOUS,
                  "the segment starts at " + mm(p0) + " but the queue ends at " + mm(start));
  if (std::string b = box_violation(tr, limits, dt); !b.empty()) return reject(ack_t::REASON_WORKSPACE, b);
  try {
    ctl::validate_trajectory(tr, machine, dt, limits.velocity * (1 + 1e-9), limits.acceleration * (1 + 1e-9));
  } catch (const Error& e) {
    const std::string m = e.what();
    const bool limit = m.find("velocity") != std::string::npos || m.find("acceleration") != std::string::npos ||
                       m.find("speed") != std::string::npos;
    return reject(limit ? ack_t::REASON_LIMIT : ack_t::REASON_WORKSPACE, m);
  }
  out.segment.end = tr.sample(tr.duration()).p;
  out.ok = true;
  return out;
}

namespace {

// "" when v is finite and zero or normal; else the field's name.
bool bad(double v) noexcept { return !std::isfinite(v) || (v != 0.0 && !std::isnormal(v)); }
template <std::size_t N>
std::string bad_in(const double (&v)[N], const char* field) {
  for (std::size_t i = 0; i < N; ++i)
    if (bad(v[i])) return std::string(field) + "[" + std::to_string(i) + "]";
  return {};
}
template <std::size_t N>
std::string bad_in(const double (&v)[N][3], const char* field) {
  for (std::size_t i = 0; i < N; ++i)
    for (std::size_t j = 0; j < 3; ++j)
      if (bad(v[i][j])) return std::string(field) + "[" + std::to_string(i) + "][" + std::to_string(j) + "]";
  return {};
}

}  // namespace

std::string bad_number(const trajectory_command_t& c) {
  for (auto [v, name] : {std::pair{c.max_velocity, "max_velocity"}, {c.max_acceleration, "max_acceleration"},
                         {c.max_jerk, "max_jerk"}, {c.radius, "radius"}, {c.angular_speed, "angular_speed"},
                         {c.start_angle, "start_angle"}, {c.cruise_time, "cruise_time"}, {c.ramp_time, "ramp_time"}})
    if (bad(v)) return name;
  for (const std::string& b : {bad_in(c.target, "target"), bad_in(c.centre, "centre"), bad_in(c.time, "time"),
                               bad_in(c.position, "position"), bad_in(c.velocity, "velocity")})
    if (!b.empty()) return b;
  return {};
}

std::string bad_number(const control_command_t& c) {
  for (const std::string& b : {bad_in(c.kp, "kp"), bad_in(c.kd, "kd"), bad_in(c.jog_velocity, "jog_velocity")})
    if (!b.empty()) return b;
  if (bad(c.param_value)) return "param_value";
  return {};
}

std::string bad_number(const cpm_msgs::path_command_t& c) {
  if (bad(c.tolerance)) return "tolerance";
  for (const std::string& b : {bad_in(c.start, "start"), bad_in(c.end, "end"), bad_in(c.centre, "centre"),
                               bad_in(c.normal, "normal"), bad_in(c.feed, "feed"), bad_in(c.dwell, "dwell")})
    if (!b.empty()) return b;
  return {};
}

Server::Server(const DaemonConfig& cfg, ControlLoop& loop, ModelStore& models)
    : cfg_(cfg), loop_(loop), models_(models), law_(cfg.controller.law), gains_(cfg.controller.gains),
      scratch_(std::make_unique<Command>()) {
  now_ = [] {
    return std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch()).count();
  };
  wall_now_ = [] {
    return std::chrono::duration<double>(std::chrono::system_clock::now().time_since_epoch()).count();
  };
  refusal_tokens_ = cfg_.security.refusal_acks_per_second;
  std::random_device rd;
  session_salt_ = (std::uint64_t{rd()} << 32) ^ rd();
  boot_id_ = static_cast<std::int64_t>(((std::uint64_t{rd()} << 32) ^ rd()) & 0x7FFFFFFFFFFFFFFFull) | 1;
  if (!cfg_.security.signing_key.empty())
    signer_ = std::make_unique<Signer>(read_key_file(cfg_.security.signing_key), boot_id_);
  else
    log::warning("security.signing_key is not set: what cpmd publishes goes out unsealed; clients cannot verify it "
                 "(docs/security.md, \"Signed state\")");
  lcm_ = std::make_unique<lcm::LCM>(cfg_.lcm.url);
  if (!lcm_->good()) throw Error("lcm: cannot open '" + cfg_.lcm.url + "' (is there a multicast route? see docs/daemon.md)");
  // Untyped subscriptions: receive() decodes. lcm-gen's typed decoding
  // trusts a string's length prefix (a length of 0 or below throws
  // std::length_error out of the LCM callback and ends the daemon).
  lcm_->subscribe(cfg_.lcm.control_channel, &Server::on_raw, this);
  lcm_->subscribe(cfg_.lcm.trajectory_channel, &Server::on_raw, this);
  lcm_->subscribe(cfg_.lcm.path_channel, &Server::on_raw, this);
  paths_ = std::make_unique<PathService>(cfg_.limits);
  loader_ = std::make_unique<ModelLoader>();
}

bool Server::loading_model() const { return loader_->busy(); }

void Server::drain_model_load() {
  std::optional<ModelLoader::Result> r = loader_->take();
  if (!r) return;
  if (!r->machine) {
    log::warning("operator %s: %s", printable(r->operator_name).c_str(), printable(r->journal, 1024).c_str());
    publish_ack(r->id, kControlSource, control_command_t::CMD_LOAD_MODEL, false, ack_t::REASON_LOAD_FAILED,
                "load_model: " + r->summary, loop_.mode(), latest_.queue_depth);
    return;
  }
  Command& c = *scratch_;
  c = Command{};
  c.id = r->id;
  c.source = kControlSource;
  c.code = control_command_t::CMD_LOAD_MODEL;
  c.kind = CommandKind::load_model;
  c.controller.emplace(*r->machine, law_, gains_);
  c.machine = models_.add(std::move(r->machine));
  send(c);
}

void Server::on_raw(const lcm::ReceiveBuffer* rbuf, const std::string& channel) {
  receive(channel, rbuf->data, rbuf->data_size);
}

void Server::set_operators(std::shared_ptr<const OperatorTable> table) {
  const std::lock_guard<std::mutex> lock(ops_mu_);
  if (ops_) ++reloads_;
  ops_ = std::move(table);
  ops_loaded_utime_ = std::chrono::duration_cast<std::chrono::microseconds>(
                          std::chrono::system_clock::now().time_since_epoch()).count();
}

void Server::note_reload_failure() {
  const std::lock_guard<std::mutex> lock(ops_mu_);
  ++reload_failures_;
}

std::shared_ptr<const OperatorTable> Server::operators() const {
  const std::lock_guard<std::mutex> lock(ops_mu_);
  return ops_;
}

cpm_msgs::security_t Server::security() const {
  cpm_msgs::security_t s = counts_;
  s.undecodable = undecodable_;
  const std::lock_guard<std::mutex> lock(ops_mu_);
  s.operators = ops_ ? static_cast<std::int32_t>(ops_->operators.size()) : 0;
  s.operators_loaded_utime = ops_loaded_utime_;
  s.reloads = reloads_;
  s.reload_failures = reload_failures_;
  return s;
}

namespace {

std::int32_t be32(const std::uint8_t* p) {
  return static_cast<std::int32_t>((std::uint32_t{p[0]} << 24) | (std::uint32_t{p[1]} << 16) |
                                   (std::uint32_t{p[2]} << 8) | std::uint32_t{p[3]});
}

// control_command_t's only string, model_path, follows 173 fixed bytes;
// after it come operator_name and mac (64 bytes). Its int32 length prefix
// counts the NUL. A length below 1 makes the generated decoder call
// std::string::assign with a negative size; any other length that does not
// account for the message's exact size is not a message we sent (nor one the
// MAC covers).
bool control_layout_ok(const void* data, std::size_t size) {
  constexpr std::size_t kFixed = kControlModelPathOffset;
  constexpr std::size_t kTail = kOperatorNameBytes + kMacBytes;
  if (size < kFixed + 4 + 1 + kTail) return false;
  const std::int32_t len = be32(static_cast<const std::uint8_t*>(data) + kFixed);
  return len >= 1 && static_cast<std::size_t>(len) == size - kFixed - 4 - kTail;
}

std::size_t trajectory_size() {
  static const std::size_t n = static_cast<std::size_t>(trajectory_command_t{}.getEncodedSize());
  return n;
}

std::size_t path_size() {
  static const std::size_t n = static_cast<std::size_t>(cpm_msgs::path_command_t{}.getEncodedSize());
  return n;
}

}  // namespace

bool Server::receive(const std::string& channel, const void* data, std::size_t size) {
  if (size > static_cast<std::size_t>(INT32_MAX)) return ++undecodable_, false;
  const int n = static_cast<int>(size);
  const auto* raw = static_cast<const std::uint8_t*>(data);
  try {
    if (channel == cfg_.lcm.control_channel) {
      control_command_t m;
      if (!control_layout_ok(data, size) || m.decode(data, 0, n) != n) return ++undecodable_, false;
      on_control(raw, size, &m);
      return true;
    }
    if (channel == cfg_.lcm.trajectory_channel) {
      // Decoded on the heap: the message is about 5.6 kB.
      if (size != trajectory_size()) return ++undecodable_, false;
      auto m = std::make_unique<trajectory_command_t>();
      if (m->decode(data, 0, n) != n) return ++undecodable_, false;
      on_trajectory(raw, size, m.get());
      return true;
    }
    if (channel == cfg_.lcm.path_channel) {
      if (size != path_size()) return ++undecodable_, false;
      auto m = std::make_unique<cpm_msgs::path_command_t>();
      if (m->decode(data, 0, n) != n) return ++undecodable_, false;
      on_path(raw, size, m.get());
      return true;
    }
  } catch (const std::exception& e) {
    // Nothing a sender writes may end the daemon; a message that cannot be
    // handled is dropped, loudly.
    log::warning("dropped a message on %s: %s", channel.c_str(), e.what());
    ++undecodable_;
    return false;
  }
  return false;
}

Server::~Server() {
  listener_quit_ = true;
  if (stop_listener_.joinable()) stop_listener_.join();
}

void Server::publish_ack(std::int64_t id, std::int8_t source, std::int8_t code, bool ok, std::int16_t reason,
                         const std::string& message, Mode mode, std::int16_t depth, std::int64_t session) {
  ack_t a;
  a.utime = std::chrono::duration_cast<std::chrono::microseconds>(
                std::chrono::system_clock::now().time_since_epoch()).count();
  a.id = id;
  a.source = source;
  a.command = code;
  a.accepted = ok;
  a.reason = reason;
  a.message = message;
  a.mode = static_cast<std::int8_t>(mode);
  a.queue_depth = depth;
  a.session = session;
  a.boot_id = boot_id_;
  publish_sealed(cfg_.lcm.ack_channel, a, /*ack=*/true);
}

template <class M>
void Server::publish_sealed(const std::string& channel, M& m, bool ack) {
  if (!signer_) {
    lcm_->publish(channel, &m);
    return;
  }
  // This thread, never the control cycle: a digest here, one signature per
  // seal (on the sealing thread under run()). A drain publishing more than a
  // seal's worth seals first.
  if (signer_->unsealed() >= kSealEvery) seal();
  const auto& bytes = signer_->add(m, now_(), ack);
  lcm_->publish(channel, bytes.data(), static_cast<unsigned>(bytes.size()));
}

void Server::seal() {
  if (!signer_) return;
  const auto& bytes = signer_->seal(std::chrono::duration_cast<std::chrono::microseconds>(
                                        std::chrono::system_clock::now().time_since_epoch()).count());
  if (!bytes.empty()) lcm_->publish(cfg_.lcm.seal_channel, bytes.data(), static_cast<unsigned>(bytes.size()));
}

void Server::set_boot_id(std::int64_t id) noexcept {
  boot_id_ = id;
  if (signer_) signer_->set_boot_id(id);
}

bool Server::send(Command& c) {
  if (loop_.commands().push(c)) {
    record_pending(c);
    return true;
  }
  publish_ack(c.id, c.source, c.code, false, ack_t::REASON_BUSY, "the loop's command queue is full; retry",
              loop_.mode(), latest_.queue_depth);
  if (c.machine) models_.release(c.machine);  // a model load the loop never saw
  return false;
}

void Server::record_pending(const Command& c) {
  // (This thread drains the loop's acks too: recorded before any answer.)
  switch (c.kind) {
    case CommandKind::load_model: pending_models_[c.id] = c.machine; break;
    case CommandKind::select_controller: pending_laws_[c.id] = {c.controller->law(), c.controller->gains()}; break;
    case CommandKind::set_params: pending_settings_[c.id] = c.settings; break;
    default: break;
  }
}

void Server::settle_pending(const Ack& a) {
  if (a.source != kControlSource) return;
  if (const auto it = pending_models_.find(a.id);
      a.code == control_command_t::CMD_LOAD_MODEL && it != pending_models_.end()) {
    if (a.accepted) models_.make_current(it->second);
    pending_models_.erase(it);
  }
  if (const auto it = pending_laws_.find(a.id); it != pending_laws_.end()) {  // a selection, or gains set
    if (a.accepted) {
      law_ = it->second.first;
      gains_ = it->second.second;
      cfg_.controller.law = law_;
      cfg_.controller.gains = gains_;
      params_changed_ = true;
    }
    pending_laws_.erase(it);
  }
  if (const auto it = pending_settings_.find(a.id); it != pending_settings_.end()) {
    if (a.accepted) {
      cfg_.limits = it->second.limits;
      cfg_.jog = it->second.jog;
      cfg_.controller.transfer_time = it->second.transfer_time;
      params_changed_ = true;
    }
    pending_settings_.erase(it);
  }
}

std::int64_t Server::session() const {
  if (session_ == 0 || now_() - last_heard_ > cfg_.lcm.session_timeout) return 0;
  return session_;
}

namespace {
std::string seconds(double s) {
  char b[32];
  std::snprintf(b, sizeof b, "%.2f s", s);
  return b;
}
}  // namespace

namespace {


const char* control_name(std::int8_t c) {
  switch (c) {
    case control_command_t::CMD_ENABLE: return "enable";
    case control_command_t::CMD_DISABLE: return "disable";
    case control_command_t::CMD_STOP: return "stop";
    case control_command_t::CMD_RESET: return "reset";
    case control_command_t::CMD_SELECT_CONTROLLER: return "select a controller";
    case control_command_t::CMD_LOAD_MODEL: return "load a model";
    case control_command_t::CMD_PING: return "ping";
    case control_command_t::CMD_ACQUIRE: return "acquire the session";
    case control_command_t::CMD_RELEASE: return "release the session";
    default: return "send this command";
  }
}

// Said to whoever sent a command that does not prove its operator: the same
// words for no name, an unknown name and a wrong MAC, so that a stranger
// learns neither names nor whether a guess came close.
constexpr const char* kNotAuthorized = "not authorized (docs/security.md)";

}  // namespace

void Server::refuse_limited(std::int64_t id, std::int8_t source, std::int8_t code, std::int16_t reason,
                            const std::string& message) {
  // Token bucket: a flood of strangers' commands earns no flood of answers.
  const double now = now_();
  const double rate = cfg_.security.refusal_acks_per_second;
  refusal_tokens_ = std::min(rate, refusal_tokens_ + (now - refusal_tokens_at_) * rate);
  refusal_tokens_at_ = now;
  if (refusal_tokens_ < 1.0) {
    ++counts_.refusals_unanswered;
    return;
  }
  refusal_tokens_ -= 1.0;
  publish_ack(id, source, code, false, reason, message, loop_.mode(), latest_.queue_depth);
}

const Operator* Server::authenticate(const OperatorTable* table, const std::uint8_t* raw, std::size_t size,
                                     const std::uint8_t (&name)[kOperatorNameBytes], std::int64_t id,
                                     std::int8_t source, std::int8_t code) {
  const std::string who = operator_name_of(name);
  const Operator* op = table && !who.empty() ? table->find(who) : nullptr;
  if (!op) {
    ++counts_.refused_no_operator;
    last_stranger_ = who.empty() ? "(none)" : who;
    refuse_limited(id, source, code, ack_t::REASON_NOT_AUTHORIZED, kNotAuthorized);
    return nullptr;
  }
  if (!verify_encoded(raw, size, op->key, boot_id_)) {
    ++counts_.refused_bad_mac;
    last_stranger_ = who + " (wrong MAC)";
    refuse_limited(id, source, code, ack_t::REASON_NOT_AUTHORIZED, kNotAuthorized);
    return nullptr;
  }
  return op;
}

bool Server::admit(std::int64_t id, std::int8_t source, std::int8_t code, std::int64_t session, std::int64_t seq,
                   const Operator& op) {
  const double now = now_();
  const std::int64_t held = this->session();
  auto refuse = [&](std::int16_t reason, const std::string& why) {
    ++counts_.refused_not_holder;
    publish_ack(id, source, code, false, reason, why, loop_.mode(), latest_.queue_depth);
    return false;
  };
  if (held == 0) {
    if (session_ != 0 && session == session_ && op.name == session_operator_)
      return refuse(ack_t::REASON_NOT_HOLDER, "the session expired: nothing heard from its holder for " +
                                                  seconds(now - last_heard_) + " (lcm.session_timeout " +
                                                  seconds(cfg_.lcm.session_timeout) + "); acquire it again");
    return refuse(ack_t::REASON_NOT_HOLDER,
                  "no session: acquire one with CMD_ACQUIRE before commanding (the cpm tools do)");
  }
  // The session is the operator's who acquired it: another operator who
  // read its id off the bus cannot use it.
  if (session != held || op.name != session_operator_)
    return refuse(ack_t::REASON_NOT_HOLDER,
                  "another commander holds the machine (last heard " + seconds(now - last_heard_) +
                      " ago; its session ends when it releases it or after " + seconds(cfg_.lcm.session_timeout) +
                      " of silence)");
  if (seq <= last_seq_) {
    ++counts_.refused_replay;
    refuse_limited(id, source, code, ack_t::REASON_STALE_SEQ,
                   "seq " + std::to_string(seq) + " is not above " + std::to_string(last_seq_) +
                       ", the session's last accepted one: a replayed, duplicated or reordered command is not played");
    return false;
  }
  last_seq_ = seq;
  last_heard_ = now;
  return true;
}

void Server::acquire(const control_command_t& m, const Operator& op) {
  const double now = now_();
  // An acquire's seq is its sender's wall clock (us): fresh, and rising per
  // operator, so a recorded acquire played back later takes nothing.
  const double skew = static_cast<double>(m.seq) * 1e-6 - wall_now_();
  auto& last = last_acquire_seq_[op.name];
  if (!(std::abs(skew) <= cfg_.security.acquire_window) || m.seq <= last) {
    ++counts_.refused_replay;
    refuse_limited(m.id, kControlSource, m.command, ack_t::REASON_STALE_SEQ,
                   m.seq <= last ? "this acquire is not newer than operator " + op.name +
                                       "'s last one: a replayed acquire is not played"
                                 : "the acquire's seq (the sender's clock) is " + seconds(std::abs(skew)) +
                                       " from cpmd's clock, more than security.acquire_window (" +
                                       seconds(cfg_.security.acquire_window) +
                                       "): a replayed acquire, or a clock to set right");
    return;
  }
  last = m.seq;
  const std::int64_t held = session();
  if (held != 0 && (m.session != session_nonce_ || op.name != session_operator_)) {
    ++counts_.refused_not_holder;
    publish_ack(m.id, kControlSource, m.command, false, ack_t::REASON_NOT_HOLDER,
                "another commander holds the machine (last heard " + seconds(now - last_heard_) +
                    " ago); it is free again when that commander releases it or after " +
                    seconds(cfg_.lcm.session_timeout) + " of silence",
                loop_.mode(), latest_.queue_depth);
    return;
  }
  if (held == 0) {
    // splitmix64 of salt, nonce and time: a name for the session, not a
    // secret (it is on the bus; the MAC is what keeps others out).
    std::uint64_t z = session_salt_ ^ static_cast<std::uint64_t>(m.session) ^
                      (static_cast<std::uint64_t>(now * 1e9) * 0x9E3779B97F4A7C15ull);
    z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
    z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
    z ^= z >> 31;
    session_ = static_cast<std::int64_t>(z & 0x7FFFFFFFFFFFFFFFull);
    if (session_ == 0) session_ = 1;
    session_nonce_ = m.session;
    session_operator_ = op.name;
    last_seq_ = 0;
  }
  // else: the holder's acquire repeated (its ack was lost): the same session.
  last_heard_ = now;
  publish_ack(m.id, kControlSource, m.command, true, ack_t::REASON_NONE, "", loop_.mode(), latest_.queue_depth, session_);
}

void Server::on_control(const std::uint8_t* raw, std::size_t size, const control_command_t* m) {
  if (!authorize_control(raw, size, *m)) return;
  Command& c = *scratch_;
  c = Command{};
  c.id = m->id;
  c.source = kControlSource;
  c.code = m->command;
  if (const std::optional<Refused> r = decode_control(*m, c)) {
    publish_ack(m->id, kControlSource, m->command, false, r->reason, r->why, loop_.mode(), latest_.queue_depth);
    return;
  }
  if (c.kind != CommandKind::none) send(c);
}

bool Server::authorize_control(const std::uint8_t* raw, std::size_t size, const control_command_t& m) {
  const std::shared_ptr<const OperatorTable> table = operators();
  if (m.command == control_command_t::CMD_STOP) {
    // A stop is taken from anyone: it only brings the platform to rest, and
    // whoever sees a danger must be able to stop it. It does not take the
    // session; from its holder, proven by the MAC, it counts as a sign of life.
    const std::int64_t held = session();
    const std::string who = operator_name_of(m.operator_name);
    const Operator* op = table && !who.empty() ? table->find(who) : nullptr;
    if (held != 0 && m.session == held && op && op->name == session_operator_ && m.seq > last_seq_ &&
        verify_encoded(raw, size, op->key, boot_id_)) {
      last_seq_ = m.seq;
      last_heard_ = now_();
    } else {
      ++counts_.stops_from_anyone;
    }
    return true;
  }
  const Operator* op = authenticate(table.get(), raw, size, m.operator_name, m.id, kControlSource, m.command);
  if (!op) return false;
  if (const auto need = role_needed(m.command); need && op->role < *need) {
    // The sender proved who it is: it may learn what its role allows.
    ++counts_.refused_role;
    publish_ack(m.id, kControlSource, m.command, false, ack_t::REASON_NOT_AUTHORIZED,
                std::string("operator ") + op->name + " (role " + role_name(op->role) + ") may not " +
                    control_name(m.command) + ": that needs role " + role_name(*need),
                loop_.mode(), latest_.queue_depth);
    return false;
  }
  if (m.command == control_command_t::CMD_ACQUIRE) {
    acquire(m, *op);
    return false;
  }
  if (!admit(m.id, kControlSource, m.command, m.session, m.seq, *op)) return false;
  if (m.command == control_command_t::CMD_RELEASE) {
    session_ = 0;
    session_nonce_ = 0;
    session_operator_.clear();
    publish_ack(m.id, kControlSource, m.command, true, ack_t::REASON_NONE, "", loop_.mode(), latest_.queue_depth);
    return false;
  }
  return true;
}

std::optional<Server::Refused> Server::decode_control(const control_command_t& m, Command& c) {
  if (m.command != control_command_t::CMD_STOP) {
    if (const std::string b = bad_number(m); !b.empty())
      return Refused{ack_t::REASON_INVALID, b + " is not a finite number, zero or normal"};
  }
  switch (m.command) {
    case control_command_t::CMD_ENABLE: c.kind = CommandKind::enable; return {};
    case control_command_t::CMD_DISABLE: c.kind = CommandKind::disable; return {};
    case control_command_t::CMD_STOP: c.kind = CommandKind::stop; return {};
    case control_command_t::CMD_RESET: c.kind = CommandKind::reset; return {};
    case control_command_t::CMD_PING: c.kind = CommandKind::ping; return {};
    case control_command_t::CMD_HOME: return decode_home(m, c);
    case control_command_t::CMD_SET_PARAM: return decode_set_param(m, c);
    case control_command_t::CMD_JOG: return decode_jog(m, c);
    case control_command_t::CMD_SELECT_CONTROLLER: return decode_select(m, c);
    case control_command_t::CMD_LOAD_MODEL: return decode_load_model(m);
    default: return Refused{ack_t::REASON_INVALID, "unknown command " + std::to_string(m.command)};
  }
}

std::optional<Server::Refused> Server::decode_home(const control_command_t& m, Command& c) const {
  if (m.home_axes < 0 || m.home_axes > 7)
    return Refused{ack_t::REASON_INVALID, "home_axes must be a mask of actuators 1-3 (bits 0-2), or 0 for all"};
  c.kind = CommandKind::home;
  c.home_axes = static_cast<std::uint8_t>(m.home_axes);
  return {};
}

std::optional<Server::Refused> Server::decode_set_param(const control_command_t& m, Command& c) const {
  // The name: NUL-padded printable ASCII, as the operator's name is.
  std::string name;
  for (const std::uint8_t b : m.param_name) {
    if (b == 0) break;
    if (b < 0x21 || b > 0x7e) return Refused{ack_t::REASON_INVALID, "param_name is not printable ASCII"};
    name.push_back(static_cast<char>(b));
  }
  const Param* param = nullptr;
  DaemonConfig next = cfg_;
  try {
    param = &find_param(name);
    set_param(next, name, m.param_value);
  } catch (const Error& e) {
    return Refused{param ? ack_t::REASON_LIMIT : ack_t::REASON_INVALID, std::string("set ") + e.what()};
  }
  if (next.controller.gains.kp != cfg_.controller.gains.kp || next.controller.gains.kd != cfg_.controller.gains.kd) {
    // New gains are a new controller: checked as a selection is, taken as
    // one (when disabled, or bumpless while holding).
    const ctl::GainVerdict verdict = check_gains_for(models_.current(), next.controller.law, next.controller.gains);
    if (!verdict.ok) return Refused{ack_t::REASON_LIMIT, "set " + name + ": " + verdict.reason};
    c.kind = CommandKind::select_controller;
    c.controller.emplace(models_.current(), next.controller.law, next.controller.gains);
    return {};
  }
  c.kind = CommandKind::set_params;
  c.settings.limits = next.limits;
  c.settings.jog = next.jog;
  c.settings.transfer_time = next.controller.transfer_time;
  c.while_moving = param->while_moving;
  c.param = param->name;
  return {};
}

std::optional<Server::Refused> Server::decode_jog(const control_command_t& m, Command& c) const {
  if (m.jog_frame != control_command_t::JOG_ACTUATOR && m.jog_frame != control_command_t::JOG_MACHINE)
    return Refused{ack_t::REASON_INVALID, "jog_frame must be 0 (actuators) or 1 (machine frame)"};
  c.kind = CommandKind::jog;
  c.jog_frame = m.jog_frame;
  c.jog_velocity = Vec3(m.jog_velocity[0], m.jog_velocity[1], m.jog_velocity[2]);
  const double v =
      m.jog_frame == control_command_t::JOG_MACHINE ? c.jog_velocity.norm() : c.jog_velocity.cwiseAbs().maxCoeff();
  if (v > cfg_.jog.max_velocity * (1.0 + 1e-9))
    return Refused{ack_t::REASON_LIMIT, "jog: " + mm_s(v) + " is faster than jog.max_velocity " + mm_s(cfg_.jog.max_velocity)};
  return {};
}

std::optional<Server::Refused> Server::decode_select(const control_command_t& m, Command& c) const {
  if (m.law < 0 || m.law > 3) return Refused{ack_t::REASON_INVALID, "law must be 0..3"};
  const auto law = static_cast<ctl::ControlLaw>(m.law);
  ctl::Gains g = ctl::table3_gains(law);
  if (!m.use_table3_gains) {
    g.kp = Vec3(m.kp[0], m.kp[1], m.kp[2]);
    g.kd = Vec3(m.kd[0], m.kd[1], m.kd[2]);
  }
  try {
    g.validate();
    // A law and gains that cannot hold this machine at this rate are
    // refused before anything changes, with the figure.
    const ctl::GainVerdict verdict = check_gains_for(models_.current(), law, g);
    if (!verdict.ok) return Refused{ack_t::REASON_LIMIT, "select_controller: " + verdict.reason};
    c.controller.emplace(models_.current(), law, g);
  } catch (const Error& e) {
    return Refused{ack_t::REASON_INVALID, std::string("select_controller: ") + e.what()};
  }
  c.kind = CommandKind::select_controller;
  return {};
}

std::optional<Server::Refused> Server::decode_load_model(const control_command_t& m) {
  // Only when disabled, said before the file is touched; then read, bounded
  // and parsed on the loader's thread (this one must hear the next stop).
  // Only from the model directory, a regular file of at most
  // kMaxModelFileBytes; what goes back on the bus names the reason and the
  // line, never the file's bytes.
  if (loop_.mode() != Mode::disabled)
    return Refused{ack_t::REASON_ILLEGAL_IN_MODE, std::string("load_model: the machine is ") + mode_name(loop_.mode()) +
                                                      "; load a model only when it is disabled (cpm disable), nothing was read"};
  if (loader_->busy())
    return Refused{ack_t::REASON_BUSY, "load_model: another model is being loaded; wait for its answer"};
  loader_->start(m.id, m.model_path, session_operator_, cfg_);
  return {};
}

ctl::GainVerdict Server::check_gains_for(const ctl::Machine& model, ctl::ControlLaw law, const ctl::Gains& g) const {
  return check_daemon_gains(cfg_, model, law, g);
}

std::int16_t ack_reason(Refusal r) noexcept {
  switch (r) {
    case Refusal::none: return ack_t::REASON_NONE;
    case Refusal::illegal_in_mode: return ack_t::REASON_ILLEGAL_IN_MODE;
    case Refusal::fault_active: return ack_t::REASON_FAULT_ACTIVE;
    case Refusal::not_homed: return ack_t::REASON_NOT_HOMED;
    case Refusal::queue_full: return ack_t::REASON_QUEUE_FULL;
    case Refusal::not_continuous: return ack_t::REASON_NOT_CONTINUOUS;
    case Refusal::limit: return ack_t::REASON_LIMIT;
    case Refusal::workspace: return ack_t::REASON_WORKSPACE;
  }
  return ack_t::REASON_INVALID;  // not reached: every refusal is named above
}

ctl::GainVerdict check_daemon_gains(const DaemonConfig& cfg, const ctl::Machine& model, ctl::ControlLaw law,
                                    const ctl::Gains& gains) {
  // The velocity the law sees: differenced positions on drives that send no
  // velocity (the stricter case), the encoders' own otherwise.
  const bool differenced = cfg.backend == "canopen" && !cfg.canopen.master.velocity_from_drive;
  return ctl::check_gains(model, law, gains, cfg.loop.rate_hz, cfg.limits.following_error,
                          differenced ? ctl::VelocityMeasurement::difference : ctl::VelocityMeasurement::exact);
}

void Server::on_trajectory(const std::uint8_t* raw, std::size_t size, const trajectory_command_t* m) {
  const std::shared_ptr<const OperatorTable> table = operators();
  const Operator* op = authenticate(table.get(), raw, size, m->operator_name, m->id, kTrajectorySource, m->kind);
  if (!op) return;
  if (op->role < Role::operator_) {
    ++counts_.refused_role;
    publish_ack(m->id, kTrajectorySource, m->kind, false, ack_t::REASON_NOT_AUTHORIZED,
                "operator " + op->name + " (role " + role_name(op->role) + ") may not move the machine: that needs role operator",
                loop_.mode(), latest_.queue_depth);
    return;
  }
  if (!admit(m->id, kTrajectorySource, m->kind, m->session, m->seq, *op)) return;
  if (const std::string b = bad_number(*m); !b.empty()) {
    publish_ack(m->id, kTrajectorySource, m->kind, false, ack_t::REASON_INVALID, b + " is not a finite number, zero or normal",
                loop_.mode(), latest_.queue_depth);
    return;
  }
  auto refuse = [&](std::int16_t reason, const std::string& why) {
    publish_ack(m->id, kTrajectorySource, m->kind, false, reason, why, loop_.mode(), latest_.queue_depth);
  };
  if (const std::string why = not_homed(); !why.empty()) return refuse(ack_t::REASON_NOT_HOMED, why);
  // Where and how the queue will end when this segment arrives.
  const QueueEnd end = queue_end_now();
  const Vec3 start = end.position, end_v = end.velocity;
  const double dt = 1.0 / cfg_.loop.rate_hz;
  Validation v = validate_segment(*m, start, models_.current(), cfg_.limits, dt);
  if (!v.ok) return refuse(v.reason, v.message);
  // The start must meet the motion the queue ends with, unless the step is
  // asked for where it may be granted (the paper's test on the simulator).
  const bool grant = m->allow_velocity_step && (cfg_.backend == "sim" || cfg_.limits.allow_velocity_step);
  if (const StartCheck sc = check_start(*v.segment.get(), end_v, cfg_.limits, dt); !sc.ok() && !grant) {
    char b[400];
    if (sc.velocity_step > sc.velocity_allowed)
      std::snprintf(b, sizeof b,
                    "the segment starts with a velocity step of %.1f mm/s from the %.1f mm/s the queue ends with; "
                    "limits.acceleration (%.3g m/s^2) allows %.1f mm/s in one period: ramp it in%s",
                    sc.velocity_step * 1e3, end_v.norm() * 1e3, cfg_.limits.acceleration, sc.velocity_allowed * 1e3,
                    m->allow_velocity_step ? " (allow_velocity_step is granted only on the simulator backend, or with "
                                             "limits.allow_velocity_step on a bench with simulated drives)"
                                           : "");
    else
      std::snprintf(b, sizeof b, "the segment starts with an acceleration of %.3f m/s^2, more than limits.acceleration %.3g m/s^2",
                    sc.acceleration, cfg_.limits.acceleration);
    return refuse(ack_t::REASON_NOT_CONTINUOUS, b);
  }
  v.segment.allow_step = grant;
  Command& c = *scratch_;
  c = Command{};
  c.kind = CommandKind::segment;
  c.id = m->id;
  c.source = kTrajectorySource;
  c.code = m->kind;
  c.segment = v.segment;
  if (send(c)) {
    inflight_segments_++;
    planned_end_ = v.segment.end;
    Vec3 end_a;
    segment_end_motion(v.segment, planned_end_v_, end_a);
  }
}

void Server::log_security(double now) {
  // One journal line a second at most, with what changed since the last.
  if (now - last_security_log_ < 1.0) return;
  const cpm_msgs::security_t s = security();
  const std::int64_t no_op = s.refused_no_operator - logged_.refused_no_operator,
                     mac = s.refused_bad_mac - logged_.refused_bad_mac, role = s.refused_role - logged_.refused_role,
                     replay = s.refused_replay - logged_.refused_replay,
                     holder = s.refused_not_holder - logged_.refused_not_holder,
                     junk = s.undecodable - logged_.undecodable,
                     quiet = s.refusals_unanswered - logged_.refusals_unanswered;
  if (no_op + mac + role + replay + holder + junk == 0) return;
  log::warning("security: refused %lld without an operator, %lld with a wrong MAC (last: %s), %lld beyond the "
               "role, %lld replayed, %lld not from the holder; %lld undecodable; %lld refusals not answered (rate limit)",
               static_cast<long long>(no_op), static_cast<long long>(mac), printable(last_stranger_).c_str(),
               static_cast<long long>(role), static_cast<long long>(replay), static_cast<long long>(holder),
               static_cast<long long>(junk), static_cast<long long>(quiet));
  logged_ = s;
  last_security_log_ = now;
}

void Server::publish_params(double now) {
  // Once a second, and at once after a change.
  if (!params_changed_ && now - last_params_publish_ < 1.0) return;
  params_changed_ = false;
  last_params_publish_ = now;
  cpm_msgs::params_t m = params_message(cfg_);
  m.utime = std::chrono::duration_cast<std::chrono::microseconds>(
                std::chrono::system_clock::now().time_since_epoch()).count();
  publish_sealed(cfg_.lcm.params_channel, m);
}

void Server::publish_security(double now) {
  if (now - last_security_publish_ < 1.0) return;
  last_security_publish_ = now;
  cpm_msgs::security_t s = security();
  s.utime = std::chrono::duration_cast<std::chrono::microseconds>(
                std::chrono::system_clock::now().time_since_epoch()).count();
  publish_sealed(cfg_.lcm.security_channel, s);
}

std::string Server::not_homed() const {
  if (!have_state_ || (latest_.homed[0] && latest_.homed[1] && latest_.homed[2])) return {};
  std::string which;
  for (int i = 0; i < 3; ++i)
    if (!latest_.homed[i]) which += (which.empty() ? "" : ", ") + std::to_string(i + 1) + " (" + "xyz"[i] + ")";
  return "actuator " + which +
         " not homed: the platform's position is not known; home the machine first (cpm home), jog the actuators "
         "meanwhile";
}

Server::QueueEnd Server::queue_end_now() const {
  if (inflight_segments_ > 0) return {planned_end_, planned_end_v_};
  if (ack_newer_than_state_ || !have_state_) return {ack_end_, ack_end_v_};
  return {Vec3(latest_.queue_end[0], latest_.queue_end[1], latest_.queue_end[2]),
          Vec3(latest_.queue_end_velocity[0], latest_.queue_end_velocity[1], latest_.queue_end_velocity[2])};
}

int Server::drain() {
  int n = 0;
  drain_paths();
  drain_model_load();
  Ack a;
  while (loop_.acks().pop(a)) {
    ++n;
    if (a.source == kTrajectorySource || a.source == kPathAckSource) inflight_segments_ = std::max(0, inflight_segments_ - 1);
    if (a.source == kPathAckSource) paths_->answered(a.id, a.accepted);
    ack_newer_than_state_ = true;
    ack_cycle_ = std::max(ack_cycle_, a.cycle);
    ack_end_ = a.queue_end;
    ack_end_v_ = a.queue_end_velocity;
    settle_pending(a);
    // A model the loop no longer uses (the old one after a load, or the new
    // one of a refused load) is freed here, outside the loop.
    if (a.retired) models_.release(a.retired);
    std::string msg = a.message;
    publish_ack(a.id, a.source, a.code, a.accepted, ack_reason(a.refusal), msg, a.mode, a.queue_depth);
  }
  const auto* s = loop_.snapshots().front();
  while (s) {
    cpm_msgs::state_t st = *s;
    loop_.snapshots().release();
    st.utime = std::chrono::duration_cast<std::chrono::microseconds>(
                   std::chrono::system_clock::now().time_since_epoch()).count();
    st.boot_id = boot_id_;
    publish_sealed(cfg_.lcm.state_channel, st);
    latest_ = st;
    have_state_ = true;
    journal_fault(st);
    // Only a state of the ack's cycle or later knows the acked segment (a
    // stream chunk was refused as "not continuous" against the queue end
    // of a state drained after the ack of the chunk before it).
    if (st.cycle >= ack_cycle_) ack_newer_than_state_ = false;
    ++n;
    s = loop_.snapshots().front();
  }
  cpm_msgs::drives_t drives;
  while (loop_.drives().pop(drives)) {
    drives.utime = std::chrono::duration_cast<std::chrono::microseconds>(
                       std::chrono::system_clock::now().time_since_epoch()).count();
    publish_sealed(cfg_.lcm.drives_channel, drives);
    ++n;
  }
  cpm_msgs::loop_stats_t stats;
  while (loop_.stats().pop(stats)) {
    stats.utime = std::chrono::duration_cast<std::chrono::microseconds>(
                      std::chrono::system_clock::now().time_since_epoch()).count();
    publish_sealed(cfg_.lcm.stats_channel, stats);
    ++n;
  }
  const double now = now_();
  publish_security(now);
  publish_params(now);
  if (signer_ && signer_->due(now)) seal();
  log_security(now);
  return n;
}

void Server::journal_fault(const cpm_msgs::state_t& st) {
  // The loop never logs; its first fault (cycle, figures) stays in the state
  // until a reset, so each latched fault is written once, when first seen.
  if (st.first_fault == 0 || st.fault_cycle == journaled_fault_cycle_) return;
  journaled_fault_cycle_ = st.fault_cycle;
  log::warning("fault at cycle %lld: %s", static_cast<long long>(st.fault_cycle), fault_report(st).c_str());
}

void Server::start_stop_listener(const std::atomic<bool>& stop) {
  if (stop_listener_.joinable()) return;
  // Its own handle: the LCM thread's handle is not to be shared, and its
  // subscriptions' work (authentication, validation) is what this avoids.
  auto bus = std::make_shared<lcm::LCM>(cfg_.lcm.url);
  if (!bus->good()) {
    log::warning("lcm: the stop listener cannot open '%s'; stops go through the command queue only",
                 cfg_.lcm.url.c_str());
    return;
  }
  struct Listener {
    Server* self;
    void on(const lcm::ReceiveBuffer* rb, const std::string&) {
      // Only a whole control command whose command byte says stop: the
      // layout check is the server's; nothing else is decoded here.
      if (!control_layout_ok(rb->data, rb->data_size)) return;
      control_command_t m;
      try {
        if (m.decode(rb->data, 0, static_cast<int>(rb->data_size)) != static_cast<int>(rb->data_size)) return;
      } catch (const std::exception&) {
        return;
      }
      if (m.command != control_command_t::CMD_STOP) return;
      self->loop_.request_stop();
      self->stops_heard_.fetch_add(1);
    }
  };
  auto listener = std::make_shared<Listener>(Listener{this});
  bus->subscribe(cfg_.lcm.control_channel, &Listener::on, listener.get());
  stop_listener_ = std::thread([this, bus, listener, &stop] {
    while (!stop.load(std::memory_order_acquire) && !listener_quit_.load(std::memory_order_acquire))
      bus->handleTimeout(50);
  });
}

void Server::run(const std::atomic<bool>& stop) {
  start_stop_listener(stop);  // from this thread: it inherits its CPUs (never loop.cpu)
  // Seals are signed on a thread of their own, started here for the same
  // reason; this thread then pays only for the digests (docs/security.md).
  if (signer_)
    signer_->start_thread([this](const std::uint8_t* data, std::size_t size) {
      lcm_->publish(cfg_.lcm.seal_channel, data, static_cast<unsigned>(size));
    });
  while (!stop.load(std::memory_order_acquire)) {
    lcm_->handleTimeout(1);
    drain();
  }
  drain();
  seal();  // the last messages' seal goes out before the end
  if (signer_) {
    signer_->stop_thread();
    seal();  // what the sealing thread was too far behind to be handed
  }
  listener_quit_ = true;
  if (stop_listener_.joinable()) stop_listener_.join();
}

bool bus_has_another_daemon(const LcmConfig& cfg, double rate_hz) {
  lcm::LCM bus(cfg.url);
  if (!bus.good()) return false;  // the server's own start says why
  struct Heard {
    int n = 0;
    void on(const lcm::ReceiveBuffer*, const std::string&) { ++n; }
  } heard;
  for (const std::string* ch : {&cfg.state_channel, &cfg.stats_channel, &cfg.security_channel})
    bus.subscribe(*ch, &Heard::on, &heard);
  // Several state periods, at least 0.3 s; 1.2 s catches the 1 Hz statistics
  // when the state is decimated that far.
  const double listen = std::clamp(3.0 * cfg.state_decimation / rate_hz, 0.3, 1.2);
  const auto end = std::chrono::steady_clock::now() + std::chrono::duration<double>(listen);
  while (heard.n == 0 && std::chrono::steady_clock::now() < end) bus.handleTimeout(20);
  return heard.n > 0;
}

bool sd_notify(const std::string& message) {
  const char* path = std::getenv("NOTIFY_SOCKET");
  if (!path || !*path) return false;
  sockaddr_un addr{};
  addr.sun_family = AF_UNIX;
  const std::size_t len = std::strlen(path);
  if (len >= sizeof addr.sun_path) return false;
  std::memcpy(addr.sun_path, path, len);
  if (path[0] == '@') addr.sun_path[0] = '\0';  // abstract socket
  const int fd = ::socket(AF_UNIX, SOCK_DGRAM | SOCK_CLOEXEC, 0);
  if (fd < 0) return false;
  const auto alen = static_cast<socklen_t>(offsetof(sockaddr_un, sun_path) + len);
  const bool ok = ::sendto(fd, message.data(), message.size(), MSG_NOSIGNAL,
                           reinterpret_cast<const sockaddr*>(&addr), alen) == static_cast<ssize_t>(message.size());
  ::close(fd);
  return ok;
}

double sd_watchdog_interval() {
  const char* usec = std::getenv("WATCHDOG_USEC");
  if (!usec) return 0.0;
  const char* pid = std::getenv("WATCHDOG_PID");
  if (pid && std::atol(pid) != static_cast<long>(::getpid())) return 0.0;
  return std::atof(usec) * 1e-6;
}

}  // namespace cpm::daemon
