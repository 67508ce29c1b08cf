// SPDX-License-Identifier: Apache-2.0
#include "cpm/sim/virtual_drives_control.hpp"

#include <cstdio>
#include <sstream>
#include <vector>

namespace cpm::sim {
namespace {

int axis_of(const std::string& s) {
  if (s == "1" || s == "x") return 0;
  if (s == "2" || s == "y") return 1;
  if (s == "3" || s == "z") return 2;
  throw Error("axis must be 1, 2, 3 or x, y, z, got '" + s + "'");
}
bool on_off(const std::string& s) {
  if (s == "on") return true;
  if (s == "off") return false;
  throw Error("expected on or off, got '" + s + "'");
}
unsigned long number(const std::string& s, unsigned long max, const char* what) {
  std::size_t used = 0;
  unsigned long v = 0;
  try {
    v = std::stoul(s, &used, 0);
  } catch (const std::exception&) {
    used = 0;
  }
  if (used != s.size() || v > max) throw Error(std::string(what) + " must be a number up to " + std::to_string(max) + ", got '" + s + "'");
  return v;
}
hal::cia402::Command command_of(const std::string& s) {
  using C = hal::cia402::Command;
  if (s == "shutdown") return C::shutdown;
  if (s == "switch_on") return C::switch_on;
  if (s == "enable_operation") return C::enable_operation;
  if (s == "disable_voltage") return C::disable_voltage;
  if (s == "quick_stop") return C::quick_stop;
  if (s == "fault_reset") return C::fault_reset;
  throw Error("unknown device control command '" + s + "'");
}

}  // namespace

std::string execute_control(VirtualMachine& vm, const std::string& line, std::int64_t now_ns, bool& quit) {
  std::istringstream is(line);
  std::vector<std::string> w;
  for (std::string t; is >> t;) w.push_back(t);
  if (w.empty() || w[0][0] == '#') return "ok";
  auto need = [&](std::size_t lo, std::size_t hi) {
    if (w.size() < lo || w.size() > hi) throw Error(w[0] + ": wrong number of arguments");
  };
  try {
    const std::string& c = w[0];
    if (c == "heartbeat") {
      need(3, 3);
      vm.drive(axis_of(w[1])).stop_heartbeat(!on_off(w[2]));
    } else if (c == "emcy") {
      need(3, 4);
      vm.drive(axis_of(w[1])).send_emcy(static_cast<std::uint16_t>(number(w[2], 0xFFFF, "CODE")),
                                        static_cast<std::uint8_t>(w.size() > 3 ? number(w[3], 0xFF, "REG") : 0x01));
    } else if (c == "fault") {
      need(3, 4);
      if (w.size() == 4 && w[3] != "persistent") throw Error("fault: the 4th word may only be 'persistent'");
      vm.drive(axis_of(w[1])).inject_fault(static_cast<std::uint16_t>(number(w[2], 0xFFFF, "CODE")), 0x01, w.size() == 4);
    } else if (c == "clear") {
      need(2, 2);
      vm.drive(axis_of(w[1])).clear_fault();
    } else if (c == "refuse") {
      need(4, 4);
      vm.drive(axis_of(w[1])).refuse(command_of(w[2]), on_off(w[3]));
    } else if (c == "late") {
      need(3, 3);
      vm.drive(axis_of(w[1])).answer_late(static_cast<std::int64_t>(number(w[2], 600000, "MS")) * 1'000'000);
    } else if (c == "silent") {
      need(3, 3);
      vm.drive(axis_of(w[1])).go_silent(on_off(w[2]));
    } else if (c == "home-switch") {
      need(3, 3);
      if (w[2] != "dead" && w[2] != "ok") throw Error("home-switch: expected dead or ok, got '" + w[2] + "'");
      vm.break_home_switch(axis_of(w[1]), w[2] == "dead");
    } else if (c == "disappear") {
      need(1, 1);
      vm.disappear(true, now_ns);
    } else if (c == "reappear") {
      need(1, 1);
      vm.disappear(false, now_ns);
    } else if (c == "status") {
      need(1, 1);
      const Vec3 p = vm.plant().position();
      char b[256];
      std::snprintf(b, sizeof b, "ok syncs %llu steps %llu position %.9f %.9f %.9f states %s %s %s%s",
                    static_cast<unsigned long long>(vm.syncs()), static_cast<unsigned long long>(vm.steps()), p.x(), p.y(),
                    p.z(), hal::cia402::state_name(vm.drive(0).state()), hal::cia402::state_name(vm.drive(1).state()),
                    hal::cia402::state_name(vm.drive(2).state()), vm.gone() ? " gone" : "");
      return b;
    } else if (c == "quit") {
      need(1, 1);
      quit = true;
    } else {
      throw Error("unknown command '" + c +
                  "' (heartbeat, emcy, fault, clear, refuse, late, silent, home-switch, disappear, reappear, status, quit)");
    }
  } catch (const std::exception& e) {
    return std::string("error: ") + e.what();
  }
  return "ok " + line;
}

}  // namespace cpm::sim
