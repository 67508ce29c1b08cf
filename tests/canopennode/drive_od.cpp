// SPDX-License-Identifier: Apache-2.0
#include "drive_od.hpp"

#include <algorithm>
#include <stdexcept>
#include <string>

namespace cpm::canopennode {

namespace {
constexpr OD_attr_t R = ODA_SDO_R, RW = ODA_SDO_RW, MB = ODA_MB, T = ODA_TPDO, Rx = ODA_RPDO;
template <class V>
OD_obj_record_t sub(V* data, std::uint8_t s, OD_attr_t attr) {
  return {data, s, static_cast<OD_attr_t>(attr | (sizeof(V) > 1 ? MB : 0)), sizeof(V)};
}
}  // namespace

void DriveOd::var(std::uint16_t index, void* data, OD_attr_t attr, OD_size_t length) {
  vars_.push_back({data, static_cast<OD_attr_t>(attr | (length > 1 && !(attr & ODA_STR) ? MB : 0)), length});
  entries_.push_back({index, 1, ODT_VAR, &vars_.back(), nullptr});
}

void DriveOd::array(std::uint16_t index, std::uint8_t* count, void* data, std::uint8_t n, OD_attr_t attr,
                    OD_size_t length) {
  arrays_.push_back({count, data, R, static_cast<OD_attr_t>(attr | (length > 1 ? MB : 0)), length, length});
  entries_.push_back({index, static_cast<std::uint8_t>(n + 1), ODT_ARR, &arrays_.back(), nullptr});
}

void DriveOd::record(std::uint16_t index, std::vector<OD_obj_record_t> subs) {
  records_.push_back(std::move(subs));
  entries_.push_back({index, static_cast<std::uint8_t>(records_.back().size()), ODT_REC, records_.back().data(), nullptr});
}

OD_entry_t* DriveOd::entry(std::uint16_t index) {
  for (auto& e : entries_)
    if (e.index == index) return &e;
  return nullptr;
}

DriveOd::DriveOd(int pdos) {
  if (pdos < 1 || pdos > 4) throw std::invalid_argument("a drive node has 1 to 4 RPDOs and TPDOs, not " + std::to_string(pdos));
  const auto n_pdos = static_cast<std::uint16_t>(pdos);
  CommObjects& c = comm;
  DriveObjects& d = drive;
  var(0x1000, &c.x1000_device_type, R, 4);
  var(0x1001, &c.x1001_error_register, R | T, 1);
  // The error history: CANopenNode's emergency object serves it (no data here).
  array(0x1003, nullptr, nullptr, 8, R, 4);
  arrays_.back().attribute0 = RW;
  var(0x1005, &c.x1005_cob_sync, RW, 4);
  var(0x1006, &c.x1006_cycle_period, RW, 4);
  var(0x1007, &c.x1007_sync_window, RW, 4);
  var(0x1008, c.x1008_device_name, R | ODA_STR, sizeof c.x1008_device_name - 1);
  var(0x1014, &c.x1014_cob_emcy, RW, 4);
  var(0x1015, &c.x1015_inhibit_emcy, RW, 2);
  array(0x1016, &c.x1016_count, c.x1016_consumer, 4, RW, 4);
  var(0x1017, &c.x1017_producer_ms, RW, 2);
  record(0x1018, {sub(&c.x1018.count, 0, R), sub(&c.x1018.vendor, 1, R), sub(&c.x1018.product, 2, R),
                  sub(&c.x1018.revision, 3, R), sub(&c.x1018.serial, 4, R)});
  var(0x1019, &c.x1019_sync_overflow, RW, 1);
  record(0x1200, {sub(&c.x1200.count, 0, R), sub(&c.x1200.rx, 1, R), sub(&c.x1200.tx, 2, R)});
  for (std::uint16_t n = 0; n < n_pdos; ++n) {
    auto& p = c.x1400[n];
    record(static_cast<std::uint16_t>(0x1400 + n),
           {sub(&p.count, 0, R), sub(&p.cob, 1, RW), sub(&p.type, 2, RW), sub(&p.event_timer, 5, RW)});
  }
  auto mapping = [&](std::uint16_t index, CommObjects::Mapping& m) {
    std::vector<OD_obj_record_t> s{sub(&m.count, 0, RW)};
    for (std::uint8_t i = 0; i < 8; ++i) s.push_back(sub(&m.entry[i], static_cast<std::uint8_t>(i + 1), RW));
    record(index, std::move(s));
  };
  for (std::uint16_t n = 0; n < n_pdos; ++n) mapping(static_cast<std::uint16_t>(0x1600 + n), c.x1600[n]);
  for (std::uint16_t n = 0; n < n_pdos; ++n) {
    auto& p = c.x1800[n];
    record(static_cast<std::uint16_t>(0x1800 + n),
           {sub(&p.count, 0, R), sub(&p.cob, 1, RW), sub(&p.type, 2, RW), sub(&p.inhibit, 3, RW),
            sub(&p.event_timer, 5, RW), sub(&p.sync_start, 6, RW)});
  }
  for (std::uint16_t n = 0; n < n_pdos; ++n) mapping(static_cast<std::uint16_t>(0x1A00 + n), c.x1A00[n]);
  var(0x6007, &d.x6007_abort_connection, RW, 2);
  var(0x603F, &d.x603F_error_code, R | T, 2);
  var(0x6040, &d.x6040_controlword, RW | Rx, 2);
  var(0x6041, &d.x6041_statusword, R | T, 2);
  var(0x605A, &d.x605A_quick_stop_option, RW, 2);
  var(0x6060, &d.x6060_mode, RW | Rx, 1);
  var(0x6061, &d.x6061_mode_display, R | T, 1);
  var(0x6064, &d.x6064_position, R | T, 4);
  var(0x606C, &d.x606C_velocity, R | T, 4);
  var(0x6071, &d.x6071_target_torque, RW | Rx, 2);
  var(0x6072, &d.x6072_max_torque, RW | Rx, 2);
  var(0x6076, &d.x6076_rated_torque, RW, 4);
  var(0x6077, &d.x6077_torque, R | T, 2);
  record(0x60C2, {sub(&d.x60C2.count, 0, R), sub(&d.x60C2.value, 1, RW), sub(&d.x60C2.exponent, 2, RW)});
  var(0x6502, &d.x6502_supported_modes, R, 4);
  std::sort(entries_.begin(), entries_.end(), [](const OD_entry_t& a, const OD_entry_t& b) { return a.index < b.index; });
  od_.size = static_cast<std::uint16_t>(entries_.size());
  entries_.push_back({0, 0, 0, nullptr, nullptr});  // CANopenNode's list ends with a blank entry
  od_.list = entries_.data();

  CO_config_t& k = config_;
  k.CNT_NMT = 1;
  k.ENTRY_H1017 = entry(0x1017);
  k.CNT_HB_CONS = 1;
  k.CNT_ARR_1016 = 4;
  k.ENTRY_H1016 = entry(0x1016);
  k.CNT_EM = 1;
  k.ENTRY_H1001 = entry(0x1001);
  k.ENTRY_H1014 = entry(0x1014);
  k.ENTRY_H1015 = entry(0x1015);
  k.CNT_ARR_1003 = 8;
  k.ENTRY_H1003 = entry(0x1003);
  k.CNT_SDO_SRV = 1;
  k.ENTRY_H1200 = entry(0x1200);
  k.CNT_SYNC = 1;
  k.ENTRY_H1005 = entry(0x1005);
  k.ENTRY_H1006 = entry(0x1006);
  k.ENTRY_H1007 = entry(0x1007);
  k.ENTRY_H1019 = entry(0x1019);
  k.CNT_RPDO = n_pdos;
  k.ENTRY_H1400 = entry(0x1400);
  k.ENTRY_H1600 = entry(0x1600);
  k.CNT_TPDO = n_pdos;
  k.ENTRY_H1800 = entry(0x1800);
  k.ENTRY_H1A00 = entry(0x1A00);
}

}  // namespace cpm::canopennode
