// SPDX-License-Identifier: Apache-2.0
// SIL smoke test of the simulated GPIO chip the runner provides, through
// libgpiod v1 (Debian's 1.6): lines found by name at their documented
// offsets, an input driven from the simulator's side (sysfs pull) and read,
// active-low inversion, an output driven and read back on the simulator's
// side (sysfs value), and edge events in both directions.
#include <gpiod.h>
#include <time.h>

#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include "sil_check.hpp"

namespace {

std::string sysfs_dir;  // $CPM_SIL_GPIO_SYSFS

bool write_pull(unsigned offset, const char* pull) {
  std::ofstream f(sysfs_dir + "/sim_gpio" + std::to_string(offset) + "/pull");
  f << pull;
  f.flush();
  return f.good();
}

int read_sim_value(unsigned offset) {
  std::ifstream f(sysfs_dir + "/sim_gpio" + std::to_string(offset) + "/value");
  int v = -1;
  f >> v;
  return f ? v : -1;
}

const timespec kGuard{10, 0};  // a hang guard, not a deadline: TCG is slow

// Waits for one edge event on line (or the hang guard) and returns its type,
// 0 if none came.
int next_event(gpiod_line* line, timespec* stamp) {
  if (gpiod_line_event_wait(line, &kGuard) != 1) return 0;
  gpiod_line_event ev{};
  if (gpiod_line_event_read(line, &ev) != 0) return 0;
  *stamp = ev.ts;
  return ev.event_type;
}

bool later(const timespec& a, const timespec& b) {
  return a.tv_sec > b.tv_sec || (a.tv_sec == b.tv_sec && a.tv_nsec > b.tv_nsec);
}

}  // namespace

int main() {
  const std::string chip_path = sil::env_or("CPM_SIL_GPIO_CHIP", "");
  sysfs_dir = sil::env_or("CPM_SIL_GPIO_SYSFS", "");
  SIL_REQUIRE(!chip_path.empty() && !sysfs_dir.empty(), "CPM_SIL_GPIO_CHIP / CPM_SIL_GPIO_SYSFS not set: run through tests/sil/run-in-vm.sh");

  gpiod_chip* chip = gpiod_chip_open(chip_path.c_str());
  SIL_REQUIRE(chip != nullptr, "gpiod_chip_open(" + chip_path + "): " + sil::errno_text());
  SIL_CHECK(std::string(gpiod_chip_label(chip)) == sil::env_or("CPM_SIL_GPIO_LABEL", "cpm-sil"));

  // Every documented line name is found, at its documented offset.
  std::vector<std::string> names;
  {
    std::istringstream in(sil::env_or("CPM_SIL_GPIO_LINES", ""));
    for (std::string n; in >> n;) names.push_back(n);
  }
  SIL_REQUIRE(names.size() >= 9, "fewer than 9 lines in CPM_SIL_GPIO_LINES");
  SIL_CHECK(gpiod_chip_num_lines(chip) == names.size());
  for (unsigned i = 0; i < names.size(); ++i) {
    gpiod_line* l = gpiod_chip_find_line(chip, names[i].c_str());
    SIL_CHECK_MSG(l != nullptr && gpiod_line_offset(l) == i, "line " + names[i]);
  }

  // Input: e-stop, driven by the simulator's pull.
  gpiod_line* estop = gpiod_chip_find_line(chip, "estop");
  SIL_REQUIRE(estop != nullptr, "no line estop");
  const unsigned estop_off = gpiod_line_offset(estop);
  SIL_REQUIRE(gpiod_line_request_input(estop, "smoke_gpio") == 0, "request estop as input: " + sil::errno_text());
  SIL_CHECK(write_pull(estop_off, "pull-up"));
  SIL_CHECK(gpiod_line_get_value(estop) == 1);
  SIL_CHECK(write_pull(estop_off, "pull-down"));
  SIL_CHECK(gpiod_line_get_value(estop) == 0);
  gpiod_line_release(estop);
  // Active low (a normally-closed e-stop chain reads 1 when the wire is low).
  SIL_REQUIRE(gpiod_line_request_input_flags(estop, "smoke_gpio", GPIOD_LINE_REQUEST_FLAG_ACTIVE_LOW) == 0,
              "request estop active-low: " + sil::errno_text());
  SIL_CHECK(gpiod_line_get_value(estop) == 1);
  SIL_CHECK(write_pull(estop_off, "pull-up"));
  SIL_CHECK(gpiod_line_get_value(estop) == 0);
  gpiod_line_release(estop);

  // Outputs: drive enable and the z brake, read back on the simulator's side.
  for (const char* name : {"enable", "brake_z"}) {
    gpiod_line* out = gpiod_chip_find_line(chip, name);
    SIL_REQUIRE(out != nullptr, std::string("no line ") + name);
    const unsigned off = gpiod_line_offset(out);
    SIL_REQUIRE(gpiod_line_request_output(out, "smoke_gpio", 0) == 0, std::string("request output ") + name);
    SIL_CHECK_MSG(read_sim_value(off) == 0, name);
    SIL_CHECK(gpiod_line_set_value(out, 1) == 0);
    SIL_CHECK_MSG(read_sim_value(off) == 1, name);
    SIL_CHECK(gpiod_line_set_value(out, 0) == 0);
    SIL_CHECK_MSG(read_sim_value(off) == 0, name);
    gpiod_line_release(out);
  }

  // Edge events: a limit switch closing then opening.
  gpiod_line* limit = gpiod_chip_find_line(chip, "limit_x_min");
  SIL_REQUIRE(limit != nullptr, "no line limit_x_min");
  const unsigned limit_off = gpiod_line_offset(limit);
  SIL_CHECK(write_pull(limit_off, "pull-down"));
  SIL_REQUIRE(gpiod_line_request_both_edges_events(limit, "smoke_gpio") == 0, "request events: " + sil::errno_text());
  timespec t_rise{}, t_fall{};
  SIL_CHECK(write_pull(limit_off, "pull-up"));
  SIL_CHECK(next_event(limit, &t_rise) == GPIOD_LINE_EVENT_RISING_EDGE);
  SIL_CHECK(gpiod_line_get_value(limit) == 1);
  SIL_CHECK(write_pull(limit_off, "pull-down"));
  SIL_CHECK(next_event(limit, &t_fall) == GPIOD_LINE_EVENT_FALLING_EDGE);
  SIL_CHECK(later(t_fall, t_rise));
  // No spurious event after that.
  const timespec none{0, 0};
  SIL_CHECK(gpiod_line_event_wait(limit, &none) == 0);
  gpiod_line_release(limit);

  gpiod_chip_close(chip);
  return sil::finish("smoke_gpio");
}
