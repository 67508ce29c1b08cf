// SPDX-License-Identifier: Apache-2.0
// GPIO through libgpiod on a real kernel (gpio-sim in the SIL VM).
//   hal_gpio_smoke [--chip gpiochip0] [--in OFFSET] [--out OFFSET] [--expect-in 0|1] [--active-low]
// Requests OFFSET --in as the e-stop input and --out as the drive-enable
// output, sets the output, reads the input, prints both ("estop=1",
// "drive_enable=1"), checks the input against --expect-in, and leaves the
// output in its safe state (0) on exit. Exits 77 (skipped) where there is
// no GPIO chip, 0 on success, 1 on failure.
#include <cstdio>
#include <string>

#include "cpm/hal/gpiod_io.hpp"
#include "cpm/program_cli.hpp"

using namespace cpm::hal;

int main(int argc, char** argv) {
  std::string chip = "gpiochip0";
  int in = 0, out = 1, expect = -1;
  bool active_low = false;
  CLI::App app{"hal_gpio_smoke: the e-stop input and the drive-enable output through libgpiod on a real kernel",
               "hal_gpio_smoke"};
  cpm::program::setup(app);
  app.add_option("--chip", chip, "the GPIO chip")->type_name("CHIP");
  app.add_option("--in", in, "line offset of the e-stop input")->type_name("OFFSET");
  app.add_option("--out", out, "line offset of the drive-enable output")->type_name("OFFSET");
  app.add_option("--expect-in", expect, "the value the input must read (-1: any)")->type_name("0|1");
  app.add_flag("--active-low", active_low, "the input is active low");
  app.footer("Exit status: 0 passed, 1 failed, 2 a bad command line, 77 skipped (no GPIO chip).");
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return cpm::program::parse_exit(app, e, "hal_gpio_smoke");
  }
  std::string why;
  if (!GpiodIo::available(&why)) {
    std::printf("SKIP: %s\n", why.c_str());
    return 77;
  }
  try {
    DigitalIoConfig cfg;
    cfg.consumer = "cpm-gpio-smoke";
    cfg[Line::estop] = LineConfig{true, chip, "", in, active_low};
    cfg[Line::drive_enable] = LineConfig{true, chip, "", out, false};
    GpiodIo io(cfg);
    const Status w = io.write(DigitalOutputs{true, false});
    DigitalInputs inputs;
    const Status r = io.read(inputs);
    std::printf("drive_enable=%d\nestop=%d\n", w.ok() ? 1 : -1, r.ok() ? (inputs.estop ? 1 : 0) : -1);
    if (!w.ok() || !r.ok()) {
      std::printf("FAIL: %s %s\n", code_name(w.code), code_name(r.code));
      return 1;
    }
    if (expect >= 0 && (inputs.estop ? 1 : 0) != expect) {
      std::printf("FAIL: estop read %d, expected %d\n", inputs.estop ? 1 : 0, expect);
      return 1;
    }
  } catch (const Error& e) {
    std::printf("FAIL: %s\n", e.what());
    return 1;
  }
  std::printf("gpio smoke: passed\n");
  return 0;
}
