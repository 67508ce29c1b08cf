// SPDX-License-Identifier: Apache-2.0
// A virtual CiA 402 servo drive: the slave side of the protocol, with no
// plant. NMT, an SDO server over an object dictionary, PDOs mapped from that
// dictionary (so the master's mapping is really applied), the CiA 402 state
// machine in cyclic synchronous torque mode and in homing mode, heartbeat
// production and consumption, EMCY, and fault injection. Whoever owns the
// plant (a test, or the virtual-drives process of sim/) sets the actual
// values and the drive's inputs (switches, index) in the SYNC hook and reads
// the torque the drive applies.
//
// Homing mode (0x6060 = 6, CiA 402-2 homing): in operation enabled, a rising
// edge of controlword bit 4 starts the method of 0x6098 with the speeds of
// 0x6099:1 (search for switch) and :2 (search for zero), the acceleration
// 0x609A and the home offset 0x607C. The drive then makes the torque itself:
// an acceleration-limited speed profile and a PI velocity loop (so a load
// such as gravity is held), a position loop when it holds a position or
// returns to the home position. Methods: 1-6 (limit or home switch, then the
// index), 17-22 (the same on the switch's edge), 33, 34 (index only), 35 and
// 37 (the current position); the first motion of a method runs at the speed
// for switch, every motion after a reversal and every search for the index at
// the speed for zero. At the homing event the counts are redefined (the
// position actual value is the home offset at the home position), the drive
// reports "attained" while it stops and returns to the home position, then
// "completed" at rest there. A limit switch reached in the direction of a
// search that is not the method's own switch ends in homing error (bit 13;
// the drive stops and holds); bit 4 falling interrupts (the drive stops;
// bit 10 set, 12 and 13 clear). docs/hal.md has the table.
#pragma once

#include <array>
#include <cstdint>
#include <functional>
#include <string>
#include <vector>

#include "cpm/hal/can.hpp"
#include "cpm/hal/canopen.hpp"
#include "cpm/hal/cia402.hpp"

namespace cpm::hal {

struct VirtualDriveConfig {
  std::uint8_t node_id = 1;
  std::uint32_t vendor_id = 0x00000CAD;
  std::uint32_t product_code = 0x402;
  std::string device_name = "cpm virtual CiA 402 drive";
  std::uint32_t rated_torque = 1000;      // 0x6076 (mN for a linear drive)
  std::int16_t quick_stop_option = 2;     // 0x605A: 1-4 end in switch on disabled, 5-8 stay
  int quick_stop_syncs = 5;               // SYNCs a quick stop takes before the drive stands still
  // RPDOs and TPDOs the drive has (1..4): CiA 301 makes every one optional,
  // and drives with fewer than four of each are common.
  int pdos = 4;
  // The drive's own loops, used in homing mode: torque (per mille of rated)
  // = velocity_kp e + velocity_ki * integral of e dt, e the velocity error in
  // 0x606C units; the velocity reference of a position the drive holds or
  // returns to is position_kp (1/s) times the position error. 0: no motion.
  // tune_loops() sets them from the axis's mass.
  double velocity_kp = 0;          // per mille per velocity unit
  double velocity_ki = 0;          // per mille per (velocity unit s)
  double position_kp = 0;          // 1/s
  double velocity_per_count = 1;   // 0x606C units per (0x6064 count per s)
  // Gains for an axis of `mass_kg` moved by `rated_force_n` per 1000 per
  // mille, `velocity_units_per_mps` 0x606C units per m/s, sampled every
  // `period_s`: a velocity loop of min(20 Hz, rate / 20) bandwidth (the
  // owner's plant answers a torque one SYNC later), its integral and the
  // position loop a fifth of that.
  void tune_loops(double mass_kg, double rated_force_n, double velocity_units_per_mps, double period_s);
};

// The drive's own inputs (wired to the drive, as a real drive's limit and
// home switches and its encoder's index are), in the drive's directions
// (its counts): the owner of the plant sets them at each SYNC.
struct DriveInputs {
  bool home_switch = false;        // actuated
  bool negative_limit = false;     // the limit switch toward lower counts, actuated
  bool positive_limit = false;     // toward higher counts
  bool index_pulse = false;        // the encoder's index passed since the last SYNC
  std::int32_t index_position = 0; // where, in the counts of set_actual (the drive's capture)
};

class VirtualDrive {
 public:
  VirtualDrive(CanBus& bus, VirtualDriveConfig cfg);

  // Power on: boot, send the boot-up message, enter pre-operational.
  void power_on(std::int64_t now_ns);
  // Process every received frame and let time pass (heartbeats, consumer
  // timeout, late answers). Call often.
  void poll(std::int64_t now_ns);

  // ---- the plant side
  // Called at each SYNC while operational, after the received controlword
  // and target torque took effect and before the TPDOs go out: step the
  // plant by one period here, then set_actual().
  std::function<void(VirtualDrive&)> on_sync;
  // When true, a SYNC applies the RPDOs and calls on_sync but holds the
  // TPDOs until transmit_sync_pdos(): a plant that couples several drives
  // (one rigid platform on three axes) steps once every drive has applied
  // this SYNC's torque, then sets each drive's actual values and sends.
  bool hold_tpdos = false;
  // Sample: run the homing procedure one period on the actual values and
  // inputs now set, then send the TPDOs of this SYNC.
  void transmit_sync_pdos();
  // The encoder as counted since power-on (a homing redefines what 0x6064
  // reports from it: position actual = position + the homing's shift).
  void set_actual(std::int32_t position, std::int32_t velocity, std::int16_t torque = 0);
  void set_inputs(const DriveInputs& in) noexcept { inputs_ = in; }
  [[nodiscard]] const DriveInputs& inputs() const noexcept { return inputs_; }
  // The torque (per mille) the drive applies now: in operation enabled, the
  // target torque in cyclic synchronous torque, its own in homing mode; 0
  // otherwise.
  [[nodiscard]] std::int16_t applied_torque() const;
  // 0x6064 minus the counts of set_actual: what the last homing redefined.
  [[nodiscard]] std::int64_t position_shift() const noexcept { return shift_; }

  // ---- what it is
  [[nodiscard]] cia402::State state() const noexcept { return state_; }
  [[nodiscard]] canopen::NmtState nmt_state() const noexcept { return nmt_; }
  [[nodiscard]] std::uint8_t node_id() const noexcept { return cfg_.node_id; }
  [[nodiscard]] std::uint64_t sync_count() const noexcept { return syncs_; }
  [[nodiscard]] int last_transition() const noexcept { return last_transition_; }
  [[nodiscard]] std::uint16_t statusword() const;
  [[nodiscard]] std::int8_t mode_display() const;
  // Object dictionary access for tests (value of a 1-4 byte entry; throws on a missing one).
  [[nodiscard]] std::uint32_t od_value(std::uint16_t index, std::uint8_t sub) const;
  void od_set(std::uint16_t index, std::uint8_t sub, std::uint32_t value);
  [[nodiscard]] std::vector<std::uint8_t> od_bytes(std::uint16_t index, std::uint8_t sub) const;
  // Counters of what the drive saw.
  std::uint64_t bad_pdos = 0;       // RPDOs with a wrong length (EMCY 0x8210 sent)
  std::uint64_t master_heartbeat_timeouts = 0;

  // ---- fault injection
  // A drive fault: fault reaction active, then fault at the next SYNC; EMCY
  // with `code` sent. When `persistent`, fault reset is refused until
  // clear_fault().
  void inject_fault(std::uint16_t emcy_code, std::uint8_t error_register, bool persistent = false);
  void clear_fault() noexcept { fault_persistent_ = false; }
  void stop_heartbeat(bool stop) noexcept { heartbeat_stopped_ = stop; }
  // Ignore this device control command (the drive stays where it is).
  void refuse(cia402::Command c, bool refuse_it) noexcept;
  // Send every SDO answer this late.
  void answer_late(std::int64_t delay_ns) noexcept { sdo_delay_ns_ = delay_ns; }
  // Neither receive nor send anything (the drive is unplugged).
  void go_silent(bool silent) noexcept { silent_ = silent; }
  // Send an arbitrary EMCY (no state change).
  void send_emcy(std::uint16_t code, std::uint8_t error_register);

 private:
  struct Entry {
    std::uint16_t index;
    std::uint8_t sub;
    std::uint8_t size;       // 1, 2, 4; 0: variable length (domain, string)
    bool writable, readable, mappable;
    std::uint32_t value, initial;
    std::vector<std::uint8_t> bytes, initial_bytes;
  };
  Entry* find(std::uint16_t index, std::uint8_t sub);
  const Entry* find(std::uint16_t index, std::uint8_t sub) const;
  bool index_exists(std::uint16_t index) const;
  void add(std::uint16_t index, std::uint8_t sub, std::uint8_t size, bool writable, std::uint32_t value,
           bool mappable = false, bool readable = true);
  void build_dictionary();
  void reset(bool application);
  void send(const CanFrame& f);
  void send_sdo(const CanFrame& f, std::int64_t now_ns);
  void on_nmt(const CanFrame& f, std::int64_t now_ns);
  void on_sdo(const CanFrame& f, std::int64_t now_ns);
  void handle_sync(std::int64_t now_ns);
  void on_rpdo(int n, const CanFrame& f);
  // SDO write of one entry with the checks of the standard; 0 or an abort code.
  std::uint32_t write_entry(std::uint16_t index, std::uint8_t sub, const std::uint8_t* data, std::size_t n);
  std::uint32_t check_pdo_write(std::uint16_t index, std::uint8_t sub, std::uint32_t v) const;
  void apply_command(cia402::Command c);
  void enter_fault(std::uint16_t code, std::uint8_t reg);
  // A received RPDO's values into the dictionary, then their effects (the
  // mode before the controlword, as a drive takes one PDO at once).
  void apply_rpdo(std::size_t n, const CanFrame& f);
  // `torque_before`: what the drive applied before (taken over on entering mode 6).
  void set_mode(std::int8_t mode, std::int16_t torque_before);
  void activate_loops(std::int16_t torque);
  void on_controlword(std::uint16_t cw);
  void set_position_actual();
  [[nodiscard]] double period_s() const;
  // Homing mode, once per SYNC on the fresh sample.
  void homing_step();
  void start_homing();
  void home_event(std::int32_t raw_home);
  [[nodiscard]] bool homing_signal() const;
  [[nodiscard]] bool moving_into_foreign_limit(double direction) const;
  // One period of the profile and the velocity loop, toward a velocity
  // (0x606C units) or, when `position_target`, toward a position (raw counts).
  void run_loops(double v_target, bool position_target, std::int64_t target_raw);

  CanBus& bus_;
  VirtualDriveConfig cfg_;
  std::vector<Entry> od_;
  canopen::NmtState nmt_ = canopen::NmtState::boot_up;
  cia402::State state_ = cia402::State::not_ready_to_switch_on;
  bool powered_ = false;
  std::uint64_t syncs_ = 0;
  int last_transition_ = 0;
  std::uint16_t last_controlword_ = 0;
  int quick_stop_left_ = 0;
  std::int64_t next_heartbeat_ns_ = 0;
  std::int64_t master_last_hb_ns_ = -1;   // -1: consumer not started
  bool master_timed_out_ = false;
  bool heartbeat_stopped_ = false;
  bool silent_ = false;
  bool fault_persistent_ = false;
  unsigned refused_ = 0;  // bit per cia402::Command
  std::int64_t sdo_delay_ns_ = 0;
  struct Late {
    CanFrame f;
    std::int64_t due;
  };
  std::vector<Late> late_;
  // SDO server transfer in progress.
  struct SdoTransfer {
    bool active = false;
    bool download = false;
    std::uint16_t index = 0;
    std::uint8_t sub = 0;
    bool toggle = false;
    std::size_t offset = 0;
    std::size_t expected = 0;
    std::vector<std::uint8_t> data;
  } sdo_;
  // RPDO data received, applied at the next SYNC (synchronous RPDOs).
  std::array<CanFrame, 4> rpdo_buf_{};
  std::array<bool, 4> rpdo_pending_{};

  // ---- homing mode
  enum class Phase : std::uint8_t {
    idle,         // not started (holds where it entered the mode): 0 0 1
    search,       // first motion, away from the final direction, for the switch's state before its edge: 0 0 0
    approach,     // toward the edge in the final direction: 0 0 0
    index,        // on to the encoder's index: 0 0 0
    to_home,      // homing event passed: stop and return to the home position: 0 1 0
    done,         // at rest at the home position: 0 1 1
    error,        // stopped on an error: 1 0 0, then 1 0 1 at rest
    interrupted,  // bit 4 dropped: stops and holds: 0 0 1
  };
  struct Plan {
    int signal = 0;         // 0 none (index only), 1 home switch, 2 negative limit, 3 positive limit
    int direction = 1;      // of the final approach, in counts
    bool before = false;    // the signal's state before its edge, moving in `direction`
    bool index = false;     // after the edge (or at once), on to the first index pulse
    bool here = false;      // 35, 37: the current position is home
  };
  static bool plan_for(int method, Plan& plan) noexcept;
  DriveInputs inputs_{};
  std::int32_t raw_position_ = 0, raw_velocity_ = 0;
  std::int64_t shift_ = 0;             // position actual = raw + shift
  Phase phase_ = Phase::idle;
  Plan plan_{};
  bool reversed_ = false;              // the approach follows a reversal: speed for zero
  bool loop_active_ = false;           // operation enabled in mode 6: the drive's loops run
  bool start_pending_ = false, interrupt_pending_ = false;
  bool at_rest_ = false, saturated_ = false;
  bool holding_ = false;               // stopped: holds hold_raw_
  std::int16_t homing_torque_ = 0;
  double v_profile_ = 0;               // velocity reference, 0x606C units
  double integral_ = 0;                // per mille
  std::int64_t hold_raw_ = 0, home_raw_ = 0;
  double speed_search_ = 0, speed_zero_ = 0, acceleration_ = 0;  // 0x6099:1, :2, 0x609A, read each SYNC
};

}  // namespace cpm::hal
