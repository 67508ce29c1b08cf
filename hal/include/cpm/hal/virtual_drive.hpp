// A virtual CiA 402 servo drive: the slave side of the protocol, with no
// plant. NMT, an SDO server over an object dictionary, PDOs mapped from that
// dictionary (so the master's mapping is really applied), the CiA 402 state
// machine in cyclic synchronous torque mode, heartbeat production and
// consumption, EMCY, and fault injection. Whoever owns the plant (a test, or
// the virtual-drives process of sim/) sets the actual values in the SYNC
// hook and reads the torque the drive applies.
#pragma once

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
  void transmit_sync_pdos();
  void set_actual(std::int32_t position, std::int32_t velocity, std::int16_t torque = 0);
  // The torque (per mille) the drive applies now: the target in operation
  // enabled, 0 otherwise.
  [[nodiscard]] std::int16_t applied_torque() const;

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
};

}  // namespace cpm::hal
