// SPDX-License-Identifier: Apache-2.0
// PDO packing and scaling at the limits, and the bus-load figures.
#include <gtest/gtest.h>

#include <cmath>
#include <limits>

#include "cpm/hal/bus_load.hpp"
#include "cpm/hal/fake_can.hpp"
#include "cpm/hal/master.hpp"
#include "cpm/hal/pdo.hpp"

using namespace cpm::hal;
using namespace cpm::hal::pdo;

namespace {
Scaling scaling() {
  Scaling s;
  s.counts_per_m = 1e6;
  s.velocity_units_per_mps = 1e6;
  s.rated_force_n = 400;
  s.max_torque_permille = 2000;
  return s;
}
}  // namespace

TEST(Pdo, TorqueScalingRoundsAndSaturatesBothWays) {
  const Scaling s = scaling();
  Code c;
  EXPECT_EQ(torque_permille(100.0, s, c), 250);  // 100 N of 400 N rated
  EXPECT_EQ(c, Code::ok);
  EXPECT_EQ(torque_permille(-100.0, s, c), -250);
  EXPECT_EQ(torque_permille(0.2, s, c), 1);      // 0.5 per mille rounds away from zero
  EXPECT_EQ(torque_permille(0.19, s, c), 0);
  EXPECT_EQ(torque_permille(800.0, s, c), 2000);  // exactly the limit
  EXPECT_EQ(c, Code::ok);
  EXPECT_EQ(torque_permille(800.5, s, c), 2000);
  EXPECT_EQ(c, Code::saturated);
  EXPECT_EQ(torque_permille(-1e12, s, c), -2000);
  EXPECT_EQ(c, Code::saturated);
  EXPECT_EQ(torque_permille(std::numeric_limits<double>::quiet_NaN(), s, c), 0);
  EXPECT_EQ(c, Code::not_finite);
  EXPECT_EQ(torque_permille(-std::numeric_limits<double>::infinity(), s, c), 0);
  EXPECT_EQ(c, Code::not_finite);
  // The widest limit the 16-bit object allows: no overflow of int16.
  Scaling w = s;
  w.max_torque_permille = 32767;
  w.rated_force_n = 1;
  EXPECT_EQ(torque_permille(1e9, w, c), 32767);
  EXPECT_EQ(torque_permille(-1e9, w, c), -32767);
  EXPECT_EQ(c, Code::saturated);
  // A drive counting the other way gets the opposite sign, and reports back in ours.
  Scaling r = s;
  r.direction = -1;
  EXPECT_EQ(torque_permille(100.0, r, c), -250);
  EXPECT_DOUBLE_EQ(force_n(-250, r), 100.0);
}

TEST(Pdo, PositionAndVelocityAtTheLimitsOfInt32) {
  Scaling s = scaling();
  EXPECT_DOUBLE_EQ(position_m(1'000'000, s), 1.0);
  EXPECT_DOUBLE_EQ(position_m(std::numeric_limits<std::int32_t>::max(), s), 2147.483647);
  EXPECT_DOUBLE_EQ(position_m(std::numeric_limits<std::int32_t>::min(), s), -2147.483648);
  s.direction = -1;
  s.position_offset_m = 0.25;
  EXPECT_DOUBLE_EQ(position_m(250'000, s), 0.0);
  EXPECT_DOUBLE_EQ(velocity_mps(-2'000'000, s), 2.0);
}

TEST(Pdo, PackingIsLittleEndianAndLengthChecked) {
  const CanFrame r = pack_rpdo1(3, 0x000F, -2);
  EXPECT_EQ(r.cob_id(), 0x203u);
  ASSERT_EQ(r.len, 4);
  EXPECT_EQ(r.data[0], 0x0F);
  EXPECT_EQ(r.data[1], 0x00);
  EXPECT_EQ(r.data[2], 0xFE);
  EXPECT_EQ(r.data[3], 0xFF);

  CanFrame t;
  t.id = 0x181;
  t.len = 6;
  const std::uint8_t bytes[] = {0x37, 0x16, 0xFF, 0xFF, 0xFF, 0x7F};
  std::copy(std::begin(bytes), std::end(bytes), t.data.begin());
  std::uint16_t sw = 0;
  std::int32_t pos = 0;
  ASSERT_TRUE(unpack_tpdo1(t, sw, pos));
  EXPECT_EQ(sw, 0x1637);
  EXPECT_EQ(pos, std::numeric_limits<std::int32_t>::max());
  t.data[5] = 0x80;
  t.data[2] = 0x00;
  t.data[3] = 0x00;
  t.data[4] = 0x00;
  ASSERT_TRUE(unpack_tpdo1(t, sw, pos));
  EXPECT_EQ(pos, std::numeric_limits<std::int32_t>::min());
  t.len = 5;
  EXPECT_FALSE(unpack_tpdo1(t, sw, pos));
  t.len = 8;
  EXPECT_FALSE(unpack_tpdo1(t, sw, pos));
  CanFrame v;
  v.id = 0x281;
  v.len = 4;
  v.data = {0x00, 0x00, 0x00, 0x80};
  std::int32_t vel = 0;
  ASSERT_TRUE(unpack_tpdo2(v, vel));
  EXPECT_EQ(vel, std::numeric_limits<std::int32_t>::min());
  v.len = 6;
  EXPECT_FALSE(unpack_tpdo2(v, vel));
  // The mapping entries written by SDO.
  EXPECT_EQ(mapping_entry(kRpdo1.objects[0]), 0x60400010u);
  EXPECT_EQ(mapping_entry(kRpdo1.objects[1]), 0x60710010u);
  EXPECT_EQ(mapping_entry(kTpdo1.objects[1]), 0x60640020u);
  EXPECT_EQ(mapping_entry(kTpdo2.objects[0]), 0x606C0020u);
}

TEST(BusLoad, WorstCaseFrameLengths) {
  // Davis et al. (2007): 55 + 10 n bits is exact for n = 0 and 8 with 11-bit ids.
  EXPECT_EQ(can_frame_bits_worst(0), 55);
  EXPECT_EQ(can_frame_bits_worst(8), 135);
  EXPECT_EQ(can_frame_bits_worst(4), 95);
  EXPECT_EQ(can_frame_bits_worst(8, true), 160);
  for (int n = 0; n <= 8; ++n) {
    // Without stuffing a standard frame is 44 + 8n bits + 3 of interframe space;
    // stuffing adds at most one bit per four of the 34 + 8n stuffable ones.
    EXPECT_GE(can_frame_bits_worst(n), 47 + 8 * n);
    EXPECT_LE(can_frame_bits_worst(n), 47 + 8 * n + (34 + 8 * n) / 4);
  }
}

TEST(BusLoad, ThreeDrivesAt1kHzOn1Mbit) {
  MasterConfig c;
  c.rate_hz = 1000;
  c.bitrate = 1e6;
  for (int i = 1; i <= 3; ++i) c.drives.push_back(DriveConfig{"d", i, 1e6, 0, 400, 1000, 1, 0, {}});
  // Full mapping: SYNC 55 + 3 x (RPDO1 4 B = 95, TPDO1 6 B = 115, TPDO2 4 B = 95) = 970 bits per 1000.
  c.velocity_from_drive = true;
  BusLoad l = bus_load(c);
  EXPECT_EQ(l.frames_per_cycle, 10);
  EXPECT_EQ(l.bits_per_cycle, 970);
  EXPECT_DOUBLE_EQ(l.bits_available, 1000.0);
  // 4 heartbeats of 65 bits every 50 ms = 5.2 bits per ms.
  EXPECT_NEAR(l.periodic_bits_per_cycle, 5.2, 1e-9);
  EXPECT_NEAR(l.load, 0.9752, 1e-9);
  EXPECT_FALSE(l.fits);
  EXPECT_NEAR(l.max_rate_hz, (0.8e6 - 5200) / 970, 1e-6);  // 819 Hz
  // Velocity from positions: 685 bits.
  c.velocity_from_drive = false;
  l = bus_load(c);
  EXPECT_EQ(l.frames_per_cycle, 7);
  EXPECT_EQ(l.bits_per_cycle, 685);
  EXPECT_TRUE(l.fits);
  EXPECT_NEAR(l.load, 0.6902, 1e-9);
  EXPECT_NEAR(l.worst_cycle_load, (685.0 + 135) / 1000, 1e-12);
  EXPECT_NEAR(l.max_rate_hz, (0.8e6 - 5200) / 685, 1e-6);  // 1160 Hz
  std::printf("bus load, 3 drives at 1 kHz on 1 Mbit/s: full mapping %s\n", bus_load([&] {
                auto k = c;
                k.velocity_from_drive = true;
                return k;
              }()).describe().c_str());
  std::printf("bus load, 3 drives at 1 kHz on 1 Mbit/s: velocity from positions %s\n", l.describe().c_str());
}

TEST(BusLoad, MasterRefusesAConfigurationThatDoesNotFitWithTheFigures) {
  MasterConfig c;
  c.rate_hz = 1000;
  for (int i = 1; i <= 3; ++i) c.drives.push_back(DriveConfig{"d", i, 1e6, 0, 400, 1000, 1, 0, {}});
  FakeClock clock;
  FakeCanNetwork net(clock);
  auto& port = net.add_port("m");
  try {
    Master m(port, clock, c);
    FAIL() << "accepted 97 % bus load";
  } catch (const Error& e) {
    const std::string w = e.what();
    EXPECT_NE(w.find("970 worst-case bits per cycle"), std::string::npos) << w;
    EXPECT_NE(w.find("97.5 %"), std::string::npos) << w;
    EXPECT_NE(w.find("819 Hz"), std::string::npos) << w;
    EXPECT_NE(w.find("velocity_from_drive: false"), std::string::npos) << w;
  }
  c.velocity_from_drive = false;
  EXPECT_NO_THROW(Master(port, clock, c));
  // 125 kbit/s cannot carry even that at 1 kHz.
  c.bitrate = 125e3;
  EXPECT_THROW(Master(port, clock, c), Error);
}
