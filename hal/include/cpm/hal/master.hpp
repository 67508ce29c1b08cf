// SPDX-License-Identifier: Apache-2.0
// A CiA 301/402 master for a few servo drives in cyclic synchronous torque
// mode (the machine has three: one per linear actuator).
//
// Two halves, as ros2_control's hardware interfaces:
//  - non-real-time: construct (validates the config and the bus load, throws
//    Error), start() (NMT reset, boot-up, SDO configuration and PDO mapping
//    written then read back, NMT start), stop(), SDO helpers;
//  - per cycle: read() then write(), once each, allocation-free, never
//    throwing. read() takes every frame received since the last cycle into
//    Feedback (SI units); write() sends the controlwords and target torques
//    (RPDO1), then SYNC, then the master's heartbeat when due.
//
// The master never decides to move: it enables a drive only when asked
// (DriveCommand::target) and sends zero torque unless the drive reports
// operation enabled and the target is enabled. Faults it detects are latched
// in Feedback until reset_faults().
//
// A drive configured with DriveHomingConfig::enabled also gets its homing
// objects (0x6098, 0x607C, 0x6099, 0x609A) at start(), and the modes of
// operation in RPDO1 and its display in TPDO1 (pdo.hpp): DriveCommand::homing
// then runs it in homing mode (6) with zero torque, and start_homing makes
// controlword bit 4 rise once the drive shows mode 6; DriveFeedback::homing
// decodes its statusword.
#pragma once

#include <array>
#include <cstdint>
#include <span>
#include <string>
#include <vector>

#include "cpm/hal/bus_load.hpp"
#include "cpm/hal/can.hpp"
#include "cpm/hal/canopen.hpp"
#include "cpm/hal/cia402.hpp"
#include "cpm/hal/pdo.hpp"
#include "cpm/hal/sdo_client.hpp"

namespace cpm::hal {

inline constexpr std::size_t kMaxDrives = 8;

// The drive's own homing (CiA 402 homing mode 6), when the daemon's
// configuration homes this actuator with it (docs/operating.md): written to
// the drive by SDO at start(); the modes of operation 0x6060 then travel in
// RPDO1 and the modes display 0x6061 in TPDO1, so that the cycle can switch
// between homing and cyclic synchronous torque.
struct DriveHomingConfig {
  bool enabled = false;
  int method = 0;                   // 0x6098 (CiA 402 homing method, e.g. 19), in the drive's
                                    // directions (its counts: reversed by direction -1)
  double speed_search_mps = 0;      // 0x6099:1 speed during search for the switch (m/s, > 0)
  double speed_zero_mps = 0;        // 0x6099:2 speed during search for zero (m/s, > 0)
  double acceleration_mps2 = 0;     // 0x609A homing acceleration (m/s^2, > 0)
  double offset_m = 0;              // 0x607C home offset (m): the position the drive reports at its home
                                    // (written in counts: direction * (offset_m - position_offset_m) * counts_per_m)
};

struct DriveConfig {
  std::string name;               // "x", "y", "z": for messages
  int node_id = 0;                // 1..127
  double counts_per_m = 0;        // 0x6064 counts per metre of actuator travel (> 0)
  double velocity_units_per_mps = 0;  // 0x606C units per m/s; 0: counts per second (= counts_per_m)
  double rated_force_n = 0;       // the force 1000 per mille of 0x6071 stands for (> 0)
  int max_torque_permille = 1000;  // clamp of 0x6071, also written to 0x6072 (1..32767)
  int direction = 1;              // +1 or -1
  double position_offset_m = 0;   // actuator displacement at count 0
  DriveHomingConfig homing;
};

struct MasterConfig {
  int master_node_id = 127;       // node id of the master's heartbeat (0x700 + id)
  double rate_hz = 1000;          // cycle = SYNC rate
  double bitrate = 1e6;           // bit/s of the bus
  double max_bus_load = 0.8;      // refuse a configuration above this average load
  bool velocity_from_drive = true;  // map 0x606C (TPDO2); false: differentiate positions
  int master_heartbeat_ms = 50;   // the master's heartbeat period
  int drive_heartbeat_ms = 50;    // written to each drive's 0x1017
  int heartbeat_timeout_ms = 150; // a drive silent this long is lost (master side)
  int drive_consumer_timeout_ms = 150;  // written to each drive's 0x1016: master silent this long -> 0x6007 action
  int abort_connection_option = 3;  // 0x6007: 1 fault, 2 disable voltage, 3 quick stop
  int pdo_timeout_cycles = 3;     // consecutive cycles without a drive's TPDOs -> fault
  int sdo_timeout_ms = 100;       // per SDO answer
  int boot_timeout_ms = 2000;     // for boot-up and NMT state changes
  bool reset_on_start = true;     // NMT reset communication before configuring
  std::vector<DriveConfig> drives;
};

// Throws Error naming the key ("drives[1].counts_per_m: ...") of the first
// bad value. Does not check the bus load (see Master::bus_load()).
void validate(const MasterConfig& cfg);
// The bus load of this configuration's cyclic traffic and heartbeats.
BusLoad bus_load(const MasterConfig& cfg);

// Faults the master detects per drive (bit set). Latched until reset_faults().
enum DriveFault : std::uint32_t {
  kFaultNone = 0,
  kFaultHeartbeatLost = 1u << 0,   // no heartbeat for heartbeat_timeout_ms
  kFaultEmcy = 1u << 1,            // an EMCY with a non-zero code
  kFaultDrive = 1u << 2,           // statusword reports fault / fault reaction active
  kFaultPdoTimeout = 1u << 3,      // TPDOs missing pdo_timeout_cycles cycles in a row
  kFaultBadPdo = 1u << 4,          // a TPDO with the wrong length
  kFaultNmtState = 1u << 5,        // the drive left operational (heartbeat state, boot-up)
  kFaultUnknownState = 1u << 6,    // a statusword that decodes to no state
};
// "heartbeat lost, EMCY" for the bits set. No allocation.
std::size_t describe_drive_faults(std::uint32_t faults, char* out, std::size_t size) noexcept;

struct DriveFeedback {
  double position_m = 0;
  double velocity_mps = 0;
  std::int32_t position_counts = 0;
  std::int32_t velocity_units = 0;   // as received (0 when differentiated)
  std::uint16_t statusword = 0;
  cia402::State state = cia402::State::unknown;
  bool fresh = false;                // this cycle's TPDOs all arrived
  std::uint32_t missed_cycles = 0;   // consecutive cycles without them
  canopen::NmtState nmt = canopen::NmtState::unknown;
  std::int64_t heartbeat_age_ns = -1;  // -1: never heard
  canopen::Emcy last_emcy{};
  std::uint32_t emcy_count = 0;
  bool emcy_active = false;          // last EMCY had a non-zero code
  // The last EMCY with a non-zero code and how many there were: a drive may
  // follow an error with its "error reset" EMCY (code 0) before the next
  // cycle reads them (CANopenNode does for a transient error), and the error
  // must not be lost behind it.
  canopen::Emcy last_error_emcy{};
  std::uint32_t error_emcy_count = 0;
  std::uint32_t faults = kFaultNone; // DriveFault bits, latched
  std::uint16_t controlword = 0;     // last sent
  std::int16_t torque_permille = 0;  // last sent
  Code torque_code = Code::ok;       // saturated / not_finite for the last write
  std::int8_t mode_display = 0;      // 0x6061 (when mapped; 0 otherwise)
  // The homing status the statusword reports while the drive is in homing
  // mode (bits 10, 12, 13), when it displays mode 6 in operation enabled
  // (the bits mean nothing in another state); idle otherwise.
  cia402::HomingStatus homing = cia402::HomingStatus::idle;
  bool position_lost = false;        // the drive booted again since the last read() (its counts restart)
};

struct Feedback {
  std::array<DriveFeedback, kMaxDrives> drive{};
  std::size_t count = 0;
  std::uint64_t cycle = 0;           // write() calls since start()
  BusState bus_state = BusState::error_active;
  bool bus_off_seen = false;         // latched
  CanErrorInfo last_error{};         // last error frame received
  std::uint64_t error_frames = 0;
  std::uint64_t rx_dropped = 0;      // frames the bus lost before we read them
  std::uint64_t tx_failures = 0;     // sends that did not get queued
  [[nodiscard]] bool any_fault() const noexcept {
    if (bus_off_seen) return true;
    for (std::size_t i = 0; i < count; ++i)
      if (drive[i].faults != kFaultNone) return true;
    return false;
  }
};

struct DriveCommand {
  cia402::Target target = cia402::Target::disabled;
  double force_n = 0;                // applied only in operation enabled with target enabled
  bool reset_fault = false;          // send fault reset (edge made by the master) while in fault
  // Homing (only for drives configured with DriveHomingConfig::enabled):
  // the modes of operation 6 instead of 10 (with zero torque), and
  // controlword bit 4 (homing operation start) while start_homing in
  // operation enabled; the master keeps bit 4 low until the drive displays
  // mode 6 after an RPDO with bit 4 low, so the drive sees a rising edge.
  // Dropping start_homing drops bit 4: the drive interrupts the homing.
  bool homing = false;
  bool start_homing = false;
};

struct Commands {
  std::array<DriveCommand, kMaxDrives> drive{};
};

class Master {
 public:
  // Validates `cfg` and its bus load; throws Error with the figures when the
  // configuration does not fit the bus.
  Master(CanBus& bus, Clock& clock, MasterConfig cfg);

  [[nodiscard]] const MasterConfig& config() const noexcept { return cfg_; }
  [[nodiscard]] const BusLoad& load() const noexcept { return load_; }
  [[nodiscard]] bool started() const noexcept { return started_; }

  // ---- non-real-time
  // Bring every drive to NMT operational with the PDO mapping and
  // parameters in place and verified; drives end in switch on disabled with
  // zero torque. Throws Error naming the drive, node and object on failure.
  void start();
  // Disable every drive (controlword disable voltage, zero torque, one SYNC),
  // then NMT pre-operational. Does not throw for silent drives.
  void stop() noexcept;
  void send_nmt(canopen::NmtCommand c, std::uint8_t node);
  // Blocking SDO transfers (timeout sdo_timeout_ms per answer); throw Error
  // "node 2 (y): SDO write 0x6060:00 aborted: 0x06090030 Invalid value for ...".
  void sdo_write(std::uint8_t node, std::uint16_t index, std::uint8_t sub, std::span<const std::uint8_t> data,
                 bool force_segmented = false);
  void sdo_write_u8(std::uint8_t node, std::uint16_t index, std::uint8_t sub, std::uint8_t v);
  void sdo_write_u16(std::uint8_t node, std::uint16_t index, std::uint8_t sub, std::uint16_t v);
  void sdo_write_u32(std::uint8_t node, std::uint16_t index, std::uint8_t sub, std::uint32_t v);
  std::vector<std::uint8_t> sdo_read(std::uint8_t node, std::uint16_t index, std::uint8_t sub);
  std::uint32_t sdo_read_u32(std::uint8_t node, std::uint16_t index, std::uint8_t sub);
  // Process received frames outside the cycle (start-up loops).
  void service() noexcept;
  // Whether every drive's TPDOs answering the last SYNC have been received
  // (processed by service() or read()). Lets a caller wait a bounded time
  // for the feedback before read() (slow hosts, SIL). Allocation-free.
  [[nodiscard]] bool feedback_complete() const noexcept;

  // ---- per cycle (allocation-free, noexcept)
  Status read(Feedback& out) noexcept;
  Status write(const Commands& in) noexcept;
  // Clear latched faults (operator reset). The drives' own faults need
  // DriveCommand::reset_fault.
  void reset_faults() noexcept;

 private:
  struct Drive {
    DriveConfig cfg;
    pdo::Scaling scaling;
    std::uint8_t node = 0;
    DriveFeedback fb;
    bool got_tpdo1 = false, got_tpdo2 = false;
    std::int64_t last_heartbeat_ns = -1;
    std::uint64_t prev_cycle = 0;   // cycle of the previous position sample
    bool have_prev = false;
    // Homing: the last RPDO had mode 6 and bit 4 low; the drive has seen
    // bit 4 low in mode 6, so raising it is an edge.
    bool sent_mode6_low = false, homing_armed = false;
    SdoClient sdo;
    Drive(const DriveConfig& c, std::int64_t sdo_timeout_ns);
  };
  void dispatch(const CanFrame& f, std::int64_t now) noexcept;
  Drive& drive_by_node(std::uint8_t node);
  std::string who(std::uint8_t node) const;
  void wait_nmt_state(canopen::NmtState want, bool boot_up, const char* what);
  void configure_drive(Drive& d);
  void write_pdo(Drive& d, const pdo::Layout& l, bool enabled);
  void check_u32(Drive& d, std::uint16_t index, std::uint8_t sub, std::uint32_t want, const char* what);
  void disable_unused_pdos(Drive& d);
  // RPDO1 as this drive's mapping has it (with the mode for a homing drive).
  static CanFrame rpdo1(const Drive& d, std::uint16_t cw, std::int16_t torque, std::int8_t mode) noexcept;

  CanBus& bus_;
  Clock& clock_;
  MasterConfig cfg_;
  BusLoad load_;
  std::vector<Drive> drives_;
  bool started_ = false;
  std::uint64_t cycle_ = 0;
  std::int64_t next_heartbeat_ns_ = 0;
  std::int64_t period_ns_ = 0;
  BusState bus_state_ = BusState::error_active;
  bool bus_off_seen_ = false;
  CanErrorInfo last_error_{};
  std::uint64_t error_frames_ = 0, tx_failures_ = 0;
};

}  // namespace cpm::hal
