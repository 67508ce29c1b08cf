// SPDX-License-Identifier: Apache-2.0
#include "cpm/daemon/fault_report.hpp"

#include <cstdio>
#include <cstring>
#include <numbers>

#include "cpm/daemon/modes.hpp"
#include "cpm/daemon/text.hpp"

namespace cpm::daemon {

namespace {

// The figures in the units on the machine's screens (SI inside).
std::string mm(double m) { return printf_text("%.3f mm", m * 1e3); }
std::string mm_s(double m_s) { return printf_text("%.1f mm/s", m_s * 1e3); }
std::string ms(double s) { return printf_text("%.0f ms", s * 1e3); }
std::string deg(double rad) { return printf_text("%.2f deg", rad * 180.0 / std::numbers::pi); }

// Axes (and actuators: one along each) are 1-3 on the machine, x, y, z.
std::string axis_name(int axis) {
  if (axis < 0 || axis > 2) return "";
  return printf_text("axis %d (%c)", axis + 1, "xyz"[axis]);
}

// What the report says about one fault: where, the figures, what happened, what to do.
struct Words {
  std::string where;    // "axis 2 (y)", "limb 1", or "" for none in particular
  std::string figures;  // "the platform was 5.046 mm from its reference against a limit of 5.000 mm"
  const char* what;     // what happened, why it may have
  const char* todo;     // what the operator does next
};

Words soft_limit(const cpm_msgs::state_t& s, const std::string& cause) {
  const int a = s.fault_axis;
  const std::string limb = a >= 0 && a <= 2 ? printf_text("limb %d", a + 1) : "";
  const char* todo = "bring the platform back inside (drives off), or send a path that stays inside, then reset and enable";
  if (cause == "stroke_low" || cause == "stroke_high")
    return {axis_name(a), printf_text("the actuator would be at %s, beyond its stroke end %s", mm(s.fault_value).c_str(), mm(s.fault_limit).c_str()),
            "the path (or the platform) ran past the actuator's stroke", todo};
  if (cause == "limb_unreachable")
    return {limb, printf_text("the limb would have to span %s against its reach of %s", mm(s.fault_value).c_str(), mm(s.fault_limit).c_str()),
            "the path (or the platform) left the limbs' reach", todo};
  if (cause == "near_singularity")
    return {limb, printf_text("its elbow came within %s of straight or folded against a margin of %s", deg(s.fault_value).c_str(), deg(s.fault_limit).c_str()),
            "the path (or the platform) ran into a singularity, where the limb cannot hold the platform", todo};
  if (!cause.empty()) return {"", "the pose is " + cause, "the workspace check could not place the platform", todo};
  return {axis_name(a), printf_text("the platform reached %c = %s, beyond the soft limit %s", a >= 0 && a <= 2 ? "xyz"[a] : '?',
                               mm(s.fault_value).c_str(), mm(s.fault_limit).c_str()),
          "it left the configured workspace (limits.workspace_min/max)", todo};
}

Words homing_words(const cpm_msgs::state_t& s, const std::string& cause) {
  const std::string where = axis_name(s.fault_axis);
  const char* todo = "check the switch, its wiring and the homing configuration, then reset, enable and home again";
  if (cause == "switch_not_found")
    return {where, printf_text("the home switch was not found after %s of travel against a limit of %s", mm(s.fault_value).c_str(), mm(s.fault_limit).c_str()),
            "the search passed where the switch should be (a switch not wired, broken, or searched in the wrong direction)", todo};
  if (cause == "switch_stuck")
    return {where, printf_text("the home switch did not release after %s of travel against a limit of %s", mm(s.fault_value).c_str(), mm(s.fault_limit).c_str()),
            "the switch stays actuated (stuck, or wired the other way: active_low)", todo};
  if (cause == "index_not_found")
    return {where, printf_text("no index mark after %s of travel against a limit of %s", mm(s.fault_value).c_str(), mm(s.fault_limit).c_str()),
            "the index line gave nothing past the switch", todo};
  if (cause == "timeout")
    return {where, printf_text("homing took %.1f s against a limit of %.1f s", s.fault_value, s.fault_limit),
            "the axis did not finish its sequence in time (too slow, blocked, or the drive never reported the end)",
            "check the axis and the homing speeds (homing.axes timeout), then reset, enable and home again"};
  if (cause == "drive_error")
    return {where, printf_text("the drive reported a homing error after %.1f s", s.fault_value),
            "the drive's own homing failed (its switch not found, a limit reached)",
            "read the drive's error, check its home switch and method (homing.axes drive_method), then reset, enable and home again"};
  return {where, "homing failed (" + (cause.empty() ? std::string("no cause given") : cause) + ")",
          "the homing sequence could not complete", todo};
}

Words motion_words(std::uint32_t bit, const cpm_msgs::state_t& s, const std::string& cause) {
  switch (bit) {
    case kFaultFollowingError:
      return {"", printf_text("the platform was %s from its reference against a limit of %s", mm(s.fault_value).c_str(), mm(s.fault_limit).c_str()),
              "the actuators could not follow the command (a collision, a drive without power, gains too soft)",
              "check the axes, then reset and enable"};
    case kFaultSoftLimit:
      return soft_limit(s, cause);
    case kFaultOverspeed:
      return {"", printf_text("the platform moved at %s against a limit of %s", mm_s(s.fault_value).c_str(), mm_s(s.fault_limit).c_str()),
              "it ran away (a drive or gain fault, a collision let go) or the path was too fast",
              "check the drives, the gains and the path's speed, then reset and enable"};
    case kFaultController:
      return {axis_name(s.fault_axis), "the forces could not be computed (" + (cause.empty() ? std::string("no cause given") : cause) + ")",
              "the reference has no actuator position or the controller's figures are not numbers",
              "check the model file and the path, then reset and enable"};
    case kFaultSaturation:
      return {axis_name(s.fault_axis), printf_text("the actuator held its force limit for %s against a limit of %s", ms(s.fault_value).c_str(), ms(s.fault_limit).c_str()),
              "the axis could not follow (blocked, overloaded, or a gain too high)",
              "check the axis for a collision or a load, and the gains, then reset and enable"};
    case kFaultHoming:
      return homing_words(s, cause);
    case kFaultStreamUnderrun:
      return {"", printf_text("the setpoint stream ran dry at %s: its next chunk came late", mm_s(s.fault_value).c_str()),
              "cpmd stopped the platform along the path, then latched this",
              "send the chunks earlier (or longer ones), then reset and enable"};
    default:
      return {"", "", nullptr, nullptr};
  }
}

Words machine_words(std::uint32_t bit, const cpm_msgs::state_t& s, const std::string& cause) {
  switch (bit) {
    case kFaultEstimate:
      return {axis_name(s.fault_axis), "the actuator positions give no platform pose (" + (cause.empty() ? std::string("no cause given") : cause) + ")",
              "an encoder reads wrong, or the model does not fit the machine", "check the encoders and the model file, then reset"};
    case kFaultDrive:
      return {axis_name(s.fault_axis), printf_text("the drive reports a fault (statusword 0x%04X)", static_cast<unsigned>(s.fault_value) & 0xFFFFu),
              "the drive stopped on a fault of its own", "read the drive's error code, clear its cause, then reset and enable"};
    case kFaultBackendIo:
      return {"", s.fault_value == 2 ? "the drives did not answer in time" : "reading or writing the drives failed",
              "the loop lost its link to the drives (bus cable, drive power, interface)", "check the bus and the drives' power, then reset"};
    case kFaultEstop:
      return {"", "the e-stop chain is open", "an e-stop was pressed, or the chain is broken",
              "make the machine safe, release the e-stop, then reset and enable"};
    case kFaultOverrun:
      return {"", printf_text("%.0f cycles in a row ended late against a limit of %.0f", s.fault_value, s.fault_limit),
              "the loop could not keep its rate (the computer is overloaded, or real-time scheduling is off)",
              "check `cpm stats` and the computer's load, then reset"};
    case kFaultEnableTimeout:
      return {"", printf_text("the drives were not all enabled after %s against a limit of %s", ms(s.fault_value).c_str(), ms(s.fault_limit).c_str()),
              "a drive without power, its enable chain open, or a drive fault", "check the drives' power and enable, then reset and enable"};
    case kFaultLimitSwitch:
      return {axis_name(s.fault_axis), "the limit switch is open", "the axis ran onto its end stop",
              "move the axis off the switch (drives off), then reset and enable"};
    default:
      return motion_words(bit, s, cause);
  }
}

}  // namespace

std::string fault_report(const cpm_msgs::state_t& s) {
  if (s.first_fault == 0) return "";
  const auto bit = static_cast<std::uint32_t>(s.first_fault);
  const auto* text = reinterpret_cast<const char*>(s.fault_text);
  const std::string cause(text, strnlen(text, sizeof s.fault_text));
  const Words w = machine_words(bit, s, cause);
  std::string r = fault_bit_name(bit);
  if (!w.where.empty()) r += " on " + w.where;
  if (!w.what) return r + ": a fault this client does not know (bit " + std::to_string(bit) + ")";
  r += ": " + w.figures + ": " + w.what + "; " + w.todo;
  // The backend's own words (which drive, which message) close the line.
  const bool cause_used =
      bit == kFaultSoftLimit || bit == kFaultController || bit == kFaultEstimate || bit == kFaultHoming;
  if (!cause.empty() && !cause_used) r += " (" + cause + ")";
  return r;
}

}  // namespace cpm::daemon
