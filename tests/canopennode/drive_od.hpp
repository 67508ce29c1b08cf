// SPDX-License-Identifier: Apache-2.0
// The object dictionary of one CiA 402 drive node built on CANopenNode: the
// CiA 301 communication objects CANopenNode needs and the CiA 402 objects
// cpmd's master uses (docs/canopen-backend.md), each with the data type,
// access and PDO mappability of the profile. Built at run time so that one
// process can hold three nodes (CANopenNode's CO_MULTIPLE_OD), where the
// stack's own examples generate one global dictionary per program.
#pragma once

#include <cstdint>
#include <deque>
#include <vector>

// The object types an object dictionary is made of (CANopenNode shows them
// only to the file that defines a dictionary).
#define OD_DEFINITION
extern "C" {
#include "CANopen.h"
}

namespace cpm::canopennode {

// CiA 301 communication area (0x1000-0x1FFF): back to these values at NMT
// reset communication.
struct CommObjects {
  std::uint32_t x1000_device_type = 0x00020192;  // CiA 402, servo drive
  std::uint8_t x1001_error_register = 0;
  std::uint8_t x1003_count = 0;
  std::uint32_t x1005_cob_sync = 0x80;
  std::uint32_t x1006_cycle_period = 0;
  std::uint32_t x1007_sync_window = 0;
  char x1008_device_name[24] = "cpm CANopenNode drive";
  std::uint32_t x1014_cob_emcy = 0x80;           // + node id (CANopenNode adds it)
  std::uint16_t x1015_inhibit_emcy = 0;
  std::uint8_t x1016_count = 4;
  std::uint32_t x1016_consumer[4] = {};
  std::uint16_t x1017_producer_ms = 0;
  struct { std::uint8_t count = 4; std::uint32_t vendor = 0, product = 402, revision = 1, serial = 0; } x1018;
  std::uint8_t x1019_sync_overflow = 0;
  struct { std::uint8_t count = 2; std::uint32_t rx = 0x600, tx = 0x580; } x1200;
  struct RpdoComm { std::uint8_t count = 5; std::uint32_t cob; std::uint8_t type = 0xFF; std::uint16_t event_timer = 0; };
  struct TpdoComm {
    std::uint8_t count = 6; std::uint32_t cob; std::uint8_t type = 0xFF; std::uint16_t inhibit = 0;
    std::uint16_t event_timer = 0; std::uint8_t sync_start = 0;
  };
  struct Mapping { std::uint8_t count = 0; std::uint32_t entry[8] = {}; };
  // As drives ship: RPDO1 with the controlword, TPDO1 with the statusword,
  // both valid; the others invalid and empty. The master maps its own.
  RpdoComm x1400[4] = {{5, 0x00000200}, {5, 0x80000300}, {5, 0x80000400}, {5, 0x80000500}};
  Mapping x1600[4] = {{1, {0x60400010}}, {}, {}, {}};
  TpdoComm x1800[4] = {{6, 0x40000180}, {6, 0xC0000280}, {6, 0xC0000380}, {6, 0xC0000480}};
  Mapping x1A00[4] = {{1, {0x60410010}}, {}, {}, {}};
};

// CiA 402 objects (device profile area): back to these at NMT reset node.
struct DriveObjects {
  std::int16_t x6007_abort_connection = 1;  // fault
  std::uint16_t x603F_error_code = 0;
  std::uint16_t x6040_controlword = 0;
  std::uint16_t x6041_statusword = 0;
  std::int16_t x605A_quick_stop_option = 2;
  std::int8_t x6060_mode = 0;
  std::int8_t x6061_mode_display = 0;
  std::int32_t x6064_position = 0;
  std::int32_t x606C_velocity = 0;
  std::int16_t x6071_target_torque = 0;
  std::uint16_t x6072_max_torque = 1000;
  std::uint32_t x6076_rated_torque = 0;
  std::int16_t x6077_torque = 0;
  struct { std::uint8_t count = 2; std::uint8_t value = 1; std::int8_t exponent = -3; } x60C2;
  std::uint32_t x6502_supported_modes = 1u << 9;  // cyclic synchronous torque
};

class DriveOd {
 public:
  // `pdos`: the RPDOs and TPDOs the node has, 1..4 (CiA 301 makes each optional).
  explicit DriveOd(int pdos = 4);
  DriveOd(const DriveOd&) = delete;
  DriveOd& operator=(const DriveOd&) = delete;

  CommObjects comm;
  DriveObjects drive;

  [[nodiscard]] OD_t* od() noexcept { return &od_; }
  // The entries CANopenNode's CO_new() and CO_CANopenInit() take.
  [[nodiscard]] CO_config_t& config() noexcept { return config_; }

 private:
  OD_entry_t* entry(std::uint16_t index);
  void var(std::uint16_t index, void* data, OD_attr_t attr, OD_size_t length);
  void array(std::uint16_t index, std::uint8_t* count, void* data, std::uint8_t n, OD_attr_t attr, OD_size_t length);
  void record(std::uint16_t index, std::vector<OD_obj_record_t> subs);

  std::deque<OD_obj_var_t> vars_;
  std::deque<OD_obj_array_t> arrays_;
  std::deque<std::vector<OD_obj_record_t>> records_;
  std::vector<OD_entry_t> entries_;
  OD_t od_{};
  CO_config_t config_{};
};

}  // namespace cpm::canopennode
