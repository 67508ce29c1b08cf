// cpmd's configuration: one YAML file (see config/sim.yaml, docs/daemon.md).
//
// Loading is strict: an unknown key, a missing key, a value of the wrong type
// or out of range is refused with the file, line:column, the key's path and
// the reason, e.g.
//   "sim.yaml:12:9: limits.velocity: must be > 0 and <= 2 m/s, got -1".
// Relative file paths in the config are relative to the config file's folder.
#pragma once

#include <string>

#include "cpm/control/controller.hpp"
#include "cpm/daemon/lcm_config.hpp"
#include "cpm/hal/digital_io.hpp"
#include "cpm/hal/master.hpp"
#include "cpm/sim/plant.hpp"

namespace cpm::daemon {

struct LoopConfig {
  double rate_hz = 1000.0;          // control rate (Hz)
  int priority = 80;                // SCHED_FIFO priority (1..99); 0 = normal scheduling
  int cpu = -1;                     // CPU to pin the loop to; -1 = no pinning
  bool lock_memory = true;          // mlockall + pre-fault
  int max_consecutive_overruns = 5; // this many in a row is a fault
  // false: a late cycle runs at once instead of skipping the slots it
  // missed, so cycle k is always the k-th cycle run (simulated time, for the
  // SIL tests in an emulated VM whose plant steps one period per SYNC).
  bool skip_late_slots = true;
};

struct LimitsConfig {
  Vec3 workspace_min = Vec3(0.235, 0.235, 0.2378);  // task-space soft limits (m)
  Vec3 workspace_max = Vec3(0.615, 0.615, 0.5168);
  double velocity = 0.5;            // max trajectory speed (m/s)
  double acceleration = 5.0;        // max trajectory acceleration (m/s^2)
  double overspeed = 0.8;           // measured platform speed that is a fault (m/s)
  double force = 120.0;             // actuator force limit (N); <= the model's
  double following_error = 0.005;   // |p_ref - p| that is a fault (m)
  double stop_deceleration = 2.0;   // deceleration of a stop (m/s^2)
  double enable_timeout = 0.5;      // drives must report enabled within this (s)
  double saturation_time = 0.2;     // an actuator at the force limit longer than this is a fault (s)
};

struct ControllerConfig {
  ctl::ControlLaw law = ctl::ControlLaw::computed_torque;
  ctl::Gains gains = ctl::table3_gains(ctl::ControlLaw::computed_torque);
};

// Who may command and what may be read for the network (docs/security.md).
struct SecurityConfig {
  // NAME.key per operator and roles.yaml; re-read on SIGHUP and when it changes.
  std::string operators_dir = "/etc/cpmd/operators.d";
  // The only directory CMD_LOAD_MODEL reads from (beneath it, no symlink out,
  // regular files of at most kMaxModelFileBytes).
  std::string model_dir = "/var/lib/cpmd/models";
  // An acquire's seq is the sender's wall clock (us since the epoch): one
  // farther than this from the daemon's clock is refused, so a recorded
  // acquire cannot be replayed later (s).
  double acquire_window = 30.0;
  // Refusals of unauthenticated or replayed commands answered per second at
  // most (the rest are counted, not answered: no amplification).
  double refusal_acks_per_second = 20.0;
};

// Files cpmd reads at start or over LCM are at most this big.
inline constexpr long kMaxConfigFileBytes = 1 << 20;
inline constexpr long kMaxModelFileBytes = 16 << 20;

struct SimConfig {
  std::string truth_model_file;   // the true machine (model file); "" = same as model_file
  sim::PlantOptions plant;
  Vec3 initial_position = Vec3(0.600, 0.425, 0.300);
  double enable_delay = 0.005;    // s
};

// The CANopen backend (docs/canopen-backend.md): three CiA 402 drives in
// cyclic synchronous torque on a SocketCAN interface, and the machine's GPIO.
struct CanopenConfig {
  std::string interface = "can0";   // SocketCAN interface
  hal::MasterConfig master;         // rate_hz = loop.rate_hz; drives[i] = actuator i + 1
  hal::DigitalIoConfig gpio;        // e-stop, drive enable, limit switches, z brake
  double feedback_wait = 0.0;       // s read() waits for this cycle's TPDOs (0: take what is there)
  hal::BusLoad load;                // computed at load time
};

struct DaemonConfig {
  std::string source;             // the file it came from
  std::string model_file;         // the model the controller believes; "builtin:elkady" = docs/model.md
  std::string backend = "sim";    // "sim" or "canopen"
  SimConfig sim;
  CanopenConfig canopen;
  LoopConfig loop;
  ControllerConfig controller;
  LimitsConfig limits;
  LcmConfig lcm;
  SecurityConfig security;
};

DaemonConfig load_config(const std::string& path);
DaemonConfig parse_config(const std::string& text, const std::string& name,
                          const std::string& base_dir = ".");

// Load a model file ("builtin:elkady" is the nominal machine of docs/model.md),
// throws Error naming the file. A configuration or model file must be a
// regular file of at most kMaxConfigFileBytes / kMaxModelFileBytes.
ctl::MachineModel load_model(const std::string& path);

// A model CMD_LOAD_MODEL could not load. what() is the whole story for the
// journal (paths, the parser's words quoting the file); `summary` is what
// may go back over LCM: the reason and, for a parse error, the line, never
// a byte of the file or more than a few of the path.
struct ModelLoadError : Error {
  ModelLoadError(const std::string& full, std::string summary_) : Error(full), summary(std::move(summary_)) {}
  std::string summary;
};

// The model a CMD_LOAD_MODEL names: "builtin:elkady", or a path relative to
// `model_dir` or absolute beneath it. Read through openat2(RESOLVE_BENEATH):
// nothing outside the directory, no symlink out of it, no /proc magic link;
// only a regular file named *.yaml or *.yml of at most kMaxModelFileBytes,
// opened without blocking (a FIFO does not hang). Throws ModelLoadError.
ctl::MachineModel load_model_beneath(const std::string& model_dir, const std::string& request);

// The bytes of the open file `fd`, refusing (Error naming `path` and `what`)
// a directory, anything but a regular file, or more than `limit` bytes.
std::string read_regular_file(int fd, const std::string& path, long limit, const char* what);

}  // namespace cpm::daemon
