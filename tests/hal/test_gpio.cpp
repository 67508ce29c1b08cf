// SPDX-License-Identifier: Apache-2.0
// Digital I/O: configuration checks, the fake, and libgpiod's report on a
// machine without GPIO chips (the real lines are tested in the SIL VM).
#include <gtest/gtest.h>

#include "cpm/hal/digital_io.hpp"
#include "cpm/hal/gpiod_io.hpp"

using namespace cpm::hal;

namespace {
DigitalIoConfig minimal() {
  DigitalIoConfig c;
  c[Line::estop] = LineConfig{true, "gpiochip0", "", 0, true};
  c[Line::drive_enable] = LineConfig{true, "gpiochip0", "", 1, false};
  return c;
}
std::string error_of(const DigitalIoConfig& c) {
  try {
    validate(c);
  } catch (const Error& e) {
    return e.what();
  }
  return "";
}
}  // namespace

TEST(DigitalIo, ConfigurationNeedsEstopAndDriveEnableAndDistinctLines) {
  EXPECT_EQ(error_of(minimal()), "");
  DigitalIoConfig c = minimal();
  c[Line::estop].present = false;
  EXPECT_EQ(error_of(c), "gpio.estop: the emergency-stop input is required");
  c = minimal();
  c[Line::drive_enable].present = false;
  EXPECT_EQ(error_of(c), "gpio.drive_enable: the drive-enable output is required");
  c = minimal();
  c[Line::limit_low_z] = LineConfig{true, "gpiochip0", "", 0, false};
  EXPECT_EQ(error_of(c), "gpio.limit_low_z: same line as gpio.estop");
  c = minimal();
  c[Line::brake_release_z] = LineConfig{true, "", "", -1, false};
  EXPECT_EQ(error_of(c), "gpio.brake_release_z: give a line name, or a chip and an offset");
  c = minimal();
  c[Line::limit_high_y] = LineConfig{true, "", "", 4, false};
  EXPECT_EQ(error_of(c), "gpio.limit_high_y: offset 4 needs a chip");
  c = minimal();
  c[Line::limit_high_y] = LineConfig{true, "", "Y_MAX", -1, true};  // by name, on any chip
  EXPECT_EQ(error_of(c), "");
  for (std::size_t i = 0; i < kLineCount; ++i) EXPECT_STRNE(line_name(static_cast<Line>(i)), "invalid");
}

TEST(DigitalIo, SafeStateIsAllOutputsOffAndReadFailureMeansEstop) {
  FakeDigitalIo io;
  ASSERT_TRUE(io.write(DigitalOutputs{true, true}).ok());
  EXPECT_TRUE(io.outputs.drive_enable);
  ASSERT_TRUE(io.safe_state().ok());
  EXPECT_FALSE(io.outputs.drive_enable);
  EXPECT_FALSE(io.outputs.brake_release_z);  // brake engaged

  io.inputs.limit_high[2] = true;
  DigitalInputs in;
  ASSERT_TRUE(io.read(in).ok());
  EXPECT_FALSE(in.estop);
  EXPECT_TRUE(in.limit_high[2]);
  io.fail_reads = true;
  EXPECT_EQ(io.read(in).code, Code::io_error);
  EXPECT_TRUE(in.estop);  // a broken input reads as the unsafe case
  // Default-constructed inputs are the unsafe case too.
  EXPECT_TRUE(DigitalInputs{}.estop);
}

TEST(DigitalIo, GpiodReportsTheLineAndChipItCannotOpen) {
  std::string why;
  if (GpiodIo::available(&why)) GTEST_SKIP() << "this machine has GPIO chips; the smoke program tests them";
  EXPECT_NE(why.find("/dev/gpiochip"), std::string::npos);
  DigitalIoConfig c = minimal();
  c[Line::estop].chip = "gpiochip9";
  try {
    GpiodIo io(c);
    FAIL() << "opened a GPIO chip that does not exist";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("gpio.estop (gpiochip9 offset 0): cannot open the GPIO chip"), std::string::npos)
        << e.what();
  }
  // Invalid configuration is refused before any device is touched.
  c[Line::drive_enable].present = false;
  EXPECT_THROW(GpiodIo{c}, Error);
}
