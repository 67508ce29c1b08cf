// SPDX-License-Identifier: Apache-2.0
// cpmd's configuration: one YAML file (see config/sim.yaml, docs/daemon.md).
//
// Loading is strict: an unknown key, a missing key, a value of the wrong type
// or out of range is refused with the file, line:column, the key's path and
// the reason, e.g.
//   "sim.yaml:12:9: limits.velocity: must be > 0 and <= 2 m/s, got -1".
// Relative file paths in the config are relative to the config file's folder.
#pragma once

#include <array>
#include <limits>
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
  // Accept a trajectory that starts with a velocity step when its command asks
  // (trajectory_command_t.allow_velocity_step) on a backend other than the
  // simulator: a bench whose drives are simulated (the SIL tests). Never on a
  // machine.
  bool allow_velocity_step = false;
};

struct ControllerConfig {
  ctl::ControlLaw law = ctl::ControlLaw::computed_torque;
  ctl::Gains gains = ctl::table3_gains(ctl::ControlLaw::computed_torque);
  // A controller switch while holding fades the force difference between the
  // old law and the new one out over this time (s), so the force does not jump.
  double transfer_time = 0.5;
};

// How an actuator finds its zero (docs/operating.md).
enum class HomingMethod : std::uint8_t {
  absolute,  // absolute encoder: known from the start, no motion
  switch_,   // the daemon moves the actuator to its home switch (GPIO home_x..), optionally to the index after it
  drive,     // the drive's own homing mode (CiA 402 mode 6), with the drive's method
};
const char* homing_method_name(HomingMethod m) noexcept;  // "absolute", "switch", "drive"

struct AxisHomingConfig {
  HomingMethod method = HomingMethod::absolute;
  // switch: velocity of the search for the switch (m/s; its sign is the
  // direction), of the slow approach that latches the switch's edge (and
  // then the index) (m/s, > 0; opposite to the search, leaving the switch),
  // whether to go on to the index after the edge, where the actuator is at
  // the homing event (m of d), how far the search may go before it gives up
  // (m), and where to go once homed (m of d; NaN: stay).
  // drive: search_velocity and latch_velocity are the drive's search speeds
  // (0x6099:1, :2; their magnitude), acceleration its 0x609A, drive_method
  // its 0x6098, home_position the position it reports at home (0x607C).
  double search_velocity = -0.02;
  double latch_velocity = 0.002;
  double acceleration = 0.2;        // m/s^2 of every homing move
  bool use_index = false;
  double home_position = 0.0;
  double max_travel = 0.45;
  double final_position = std::numeric_limits<double>::quiet_NaN();
  int drive_method = 0;
  double timeout = 60.0;            // s for the whole of this actuator's homing
};

struct HomingConfig {
  std::array<AxisHomingConfig, 3> axes{};  // actuators 1, 2, 3
  std::array<int, 3> order = {2, 0, 1};    // the order CMD_HOME with axes 0 homes them in (z first: away from the work)
  // As loaded, order[0 .. order_count) are exactly the actuators that are not
  // absolute (none without a homing section); the defaults here are for
  // configurations built in code.
  int order_count = 3;
  // The PD law each actuator is held by before every actuator is homed (N/m, N s/m).
  ctl::Gains actuator_gains{Vec3::Constant(12691.0), Vec3::Constant(436.0)};
  [[nodiscard]] bool all_absolute() const noexcept;
};

// Jogging (docs/operating.md): the deadman and how far a let-go jog may go.
struct JogConfig {
  double max_velocity = 0.05;       // m/s (per actuator, or of the platform)
  double acceleration = 0.5;        // m/s^2 to start, change and end a jog
  double keepalive = 0.2;           // s a jog command holds
  // When the jog commands stop coming at max_velocity, the platform is at
  // rest within this distance of where it was at the last one (m). Checked
  // at load: max_velocity * keepalive + max_velocity^2 / (2 acceleration).
  double stop_distance = 0.015;
};

// Who may command and what may be read for the network (docs/security.md).
struct SecurityConfig {
  // NAME.key per operator and roles.yaml; re-read on SIGHUP and when it changes.
  std::string operators_dir = "/etc/cpmd/operators.d";
  // The only directory CMD_LOAD_MODEL reads from (beneath it, no symlink out,
  // regular files of at most kMaxModelFileBytes).
  std::string model_dir = "/var/lib/cpmd/models";
  // cpmd's Ed25519 key (32-byte seed, a key file as `cpm keygen` writes; mode 0600):
  // every state and ack is signed with it (docs/security.md, "Signed state").
  // Empty: nothing is signed, and clients say that state cannot be verified.
  std::string signing_key;
  // An acquire's seq is the sender's wall clock (us since the epoch): one
  // farther than this from the daemon's clock is refused, so a recorded
  // acquire cannot be replayed later (s).
  double acquire_window = 30.0;
  // Refusals of unauthenticated or replayed commands answered per second at
  // most (the rest are counted, not answered: no amplification).
  double refusal_acks_per_second = 20.0;
};

// Files cpmd reads at start or over LCM are at most this big. A real model
// file is a few kB (the largest in the repository under 10 kB; a screw
// compensation table of 2000 rows stays under 100 kB): 1 MiB leaves room
// for that ten times over, and bounds the parse's memory and time (a 14 MB
// file once took 6.3 s and 1.66 GB, docs/security.md).
inline constexpr long kMaxConfigFileBytes = 1 << 20;
inline constexpr long kMaxModelFileBytes = 1 << 20;
// A model file's YAML: at most this many nodes (scalars, sequences, maps,
// aliases; a real model has a few hundred, a 2000-row table about 6000) and
// this deep (a real one nests 5 levels). Counted on the parser's events
// before any tree is built: what exceeds them costs no memory.
inline constexpr long kMaxModelNodes = 20000;
inline constexpr int kMaxModelDepth = 32;

// A model CMD_LOAD_MODEL could not load. what() is the whole story for the
// journal (paths, the parser's words quoting the file); `summary` is what
// may go back over LCM: the reason and, for a parse error, the line, never
// a byte of the file or more than a few of the path.
struct ModelLoadError : Error {
  ModelLoadError(const std::string& full, std::string summary_) : Error(full), summary(std::move(summary_)) {}
  std::string summary;
};

// Refuse (ModelLoadError: the limit, the line and `where`) YAML text with more nodes
// or deeper nesting than a model file has (kMaxModelNodes, kMaxModelDepth),
// or that is not YAML.
void check_model_yaml_bounds(const std::string& text, const std::string& where);

struct SimConfig {
  std::string truth_model_file;   // the true machine (model file); "" = same as model_file
  sim::PlantOptions plant;
  Vec3 initial_position = Vec3(0.600, 0.425, 0.300);
  double enable_delay = 0.005;    // s
  // Incremental encoders: what the encoders read is d - encoder_zero (m), so
  // until homed the daemon does not know where the platform is. 0 = absolute.
  Vec3 encoder_zero = Vec3::Zero();
  // Home switches in the plant: actuator i's switch is actuated while
  // d_i < home_switch[i] (m); NaN: none (YAML: null or .nan for that element).
  Vec3 home_switch = Vec3::Constant(std::numeric_limits<double>::quiet_NaN());
  // Encoder index marks: one every index_pitch of the true d (at d = k pitch,
  // k integer; m), the same on the three actuators; 0 = none. How the
  // simulator reports them: SimBackendOptions::index_pitch.
  double index_pitch = 0.0;
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
  HomingConfig homing;
  JogConfig jog;
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
