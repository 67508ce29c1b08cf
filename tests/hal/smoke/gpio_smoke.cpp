// GPIO through libgpiod on a real kernel (gpio-sim in the SIL VM).
//   hal_gpio_smoke [--chip gpiochip0] [--in OFFSET] [--out OFFSET] [--expect-in 0|1] [--active-low]
// Requests OFFSET --in as the e-stop input and --out as the drive-enable
// output, sets the output, reads the input, prints both ("estop=1",
// "drive_enable=1"), checks the input against --expect-in, and leaves the
// output in its safe state (0) on exit. Exits 77 (skipped) where there is
// no GPIO chip, 0 on success, 1 on failure.
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string>

#include "cpm/hal/gpiod_io.hpp"

using namespace cpm::hal;

int main(int argc, char** argv) {
  std::string chip = "gpiochip0";
  int in = 0, out = 1, expect = -1;
  bool active_low = false;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    auto next = [&]() -> const char* {
      if (i + 1 >= argc) {
        std::fprintf(stderr, "hal_gpio_smoke: %s needs a value\n", a.c_str());
        std::exit(2);
      }
      return argv[++i];
    };
    if (a == "--chip") chip = next();
    else if (a == "--in") in = std::atoi(next());
    else if (a == "--out") out = std::atoi(next());
    else if (a == "--expect-in") expect = std::atoi(next());
    else if (a == "--active-low") active_low = true;
    else {
      std::fprintf(stderr, "hal_gpio_smoke: unknown option %s\n", a.c_str());
      return 2;
    }
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
