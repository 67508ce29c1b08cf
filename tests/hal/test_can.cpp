// SPDX-License-Identifier: Apache-2.0
// The CAN layer: the fake bus and its fault injection, error-frame decoding,
// and SocketCAN's report when the kernel has no CAN.
#include <gtest/gtest.h>
#include <linux/can.h>
#include <linux/can/error.h>

#include <cstring>

#include "cpm/hal/fake_can.hpp"
#include "cpm/hal/socketcan.hpp"

using namespace cpm::hal;

namespace {
CanFrame frame(std::uint32_t id, std::uint8_t len, std::uint8_t fill = 0xA5) {
  CanFrame f;
  f.id = id;
  f.len = len;
  for (int i = 0; i < len; ++i) f.data[static_cast<std::size_t>(i)] = static_cast<std::uint8_t>(fill + i);
  return f;
}
}  // namespace

TEST(FakeCan, DeliversToEveryOtherPortWithTimestampNotToSender) {
  FakeClock clock(1000);
  FakeCanNetwork net(clock);
  auto& a = net.add_port("a");
  auto& b = net.add_port("b");
  auto& c = net.add_port("c");
  ASSERT_TRUE(a.send(frame(0x123, 3)).ok());
  CanFrame f;
  EXPECT_EQ(a.receive(f).code, Code::would_block);
  ASSERT_TRUE(b.receive(f).ok());
  EXPECT_EQ(f.cob_id(), 0x123u);
  EXPECT_EQ(f.len, 3);
  EXPECT_EQ(f.data[2], 0xA7);
  EXPECT_EQ(f.timestamp_ns, 1000);
  ASSERT_TRUE(c.receive(f).ok());
  EXPECT_EQ(b.receive(f).code, Code::would_block);
  EXPECT_EQ(a.stats().tx_frames, 1u);
  EXPECT_EQ(b.stats().rx_frames, 1u);
}

TEST(FakeCan, FiltersAcceptOnlyMatchingIds) {
  FakeClock clock;
  FakeCanNetwork net(clock);
  auto& a = net.add_port("a");
  auto& b = net.add_port("b");
  const CanFilter only_node5[] = {{0x005, 0x07F}};
  b.set_filters(only_node5, false);
  a.send(frame(0x185, 2));
  a.send(frame(0x186, 2));
  a.send(frame(0x705, 1));
  CanFrame f;
  ASSERT_TRUE(b.receive(f).ok());
  EXPECT_EQ(f.cob_id(), 0x185u);
  ASSERT_TRUE(b.receive(f).ok());
  EXPECT_EQ(f.cob_id(), 0x705u);
  EXPECT_EQ(b.receive(f).code, Code::would_block);
}

TEST(FakeCan, DropDelayAndCorruptChosenFrames) {
  FakeClock clock;
  FakeCanNetwork net(clock);
  auto& a = net.add_port("a");
  auto& b = net.add_port("b");
  CanFrame f;
  net.drop(0x181, 0x7FF, 1);
  a.send(frame(0x181, 2));
  a.send(frame(0x181, 2));
  ASSERT_TRUE(b.receive(f).ok());  // only the second arrives
  EXPECT_EQ(b.receive(f).code, Code::would_block);

  net.delay(0x182, 0x7FF, 5'000'000);
  a.send(frame(0x182, 1));
  a.send(frame(0x183, 1));
  ASSERT_TRUE(b.receive(f).ok());
  EXPECT_EQ(f.cob_id(), 0x183u);  // overtaken by the undelayed frame
  EXPECT_EQ(b.receive(f).code, Code::would_block);
  clock.advance(4'999'999);
  EXPECT_EQ(b.receive(f).code, Code::would_block);
  clock.advance(1);
  ASSERT_TRUE(b.receive(f).ok());
  EXPECT_EQ(f.cob_id(), 0x182u);
  EXPECT_EQ(f.timestamp_ns, 5'000'000);

  net.corrupt(0x184, 0x7FF, Corruption::length);
  a.send(frame(0x184, 6));
  ASSERT_TRUE(b.receive(f).ok());
  EXPECT_EQ(f.len, 5);
  net.corrupt(0x184, 0x7FF, Corruption::data_bit);
  a.send(frame(0x184, 6, 0x10));
  ASSERT_TRUE(b.receive(f).ok());
  EXPECT_EQ(f.data[0], 0x11);

  // A CRC error: every node sees a protocol error frame, then the retransmitted frame intact.
  net.corrupt(0x185, 0x7FF, Corruption::crc);
  a.send(frame(0x185, 2));
  ASSERT_TRUE(b.receive(f).ok());
  ASSERT_TRUE(f.is_error());
  EXPECT_TRUE(decode_error_frame(f).protocol);
  ASSERT_TRUE(b.receive(f).ok());
  EXPECT_EQ(f.cob_id(), 0x185u);
  EXPECT_EQ(f.data[0], 0xA5);
}

TEST(FakeCan, RandomDropIsDeterministicForASeed) {
  auto run = [](std::uint64_t seed) {
    FakeClock clock;
    FakeCanNetwork net(clock);
    auto& a = net.add_port("a");
    auto& b = net.add_port("b");
    net.drop_randomly(0.3, seed);
    std::uint64_t got = 0, mask = 0;
    CanFrame f;
    for (int i = 0; i < 64; ++i) {
      a.send(frame(0x100, 1));
      if (b.receive(f).ok()) {
        ++got;
        mask |= 1ull << i;
      }
    }
    return std::pair{got, mask};
  };
  const auto r1 = run(42), r2 = run(42), r3 = run(7);
  EXPECT_EQ(r1, r2);
  EXPECT_NE(r1.second, r3.second);
  EXPECT_GT(r1.first, 30u);
  EXPECT_LT(r1.first, 60u);
}

TEST(FakeCan, QueueOverflowLosesNewestAndCounts) {
  FakeClock clock;
  FakeCanNetwork net(clock, 0, 4);
  auto& a = net.add_port("a");
  auto& b = net.add_port("b");
  for (int i = 0; i < 6; ++i) a.send(frame(0x100 + static_cast<std::uint32_t>(i), 0));
  EXPECT_EQ(b.stats().rx_dropped, 2u);
  CanFrame f;
  b.receive(f);
  EXPECT_EQ(f.cob_id(), 0x100u);
}

TEST(FakeCan, BusOffBlocksSendingAndIsAnnouncedThenRestarted) {
  FakeClock clock;
  FakeCanNetwork net(clock);
  auto& a = net.add_port("a");
  auto& b = net.add_port("b");
  net.set_bus_off(true);
  EXPECT_EQ(a.send(frame(0x100, 1)).code, Code::bus_off);
  CanFrame f;
  ASSERT_TRUE(b.receive(f).ok());
  ASSERT_TRUE(f.is_error());
  CanErrorInfo e = decode_error_frame(f);
  EXPECT_TRUE(e.bus_off);
  ASSERT_TRUE(e.has_state);
  EXPECT_EQ(e.state, BusState::bus_off);
  net.set_bus_off(false);
  ASSERT_TRUE(b.receive(f).ok());
  e = decode_error_frame(f);
  EXPECT_TRUE(e.restarted);
  EXPECT_EQ(e.state, BusState::error_active);
  EXPECT_TRUE(a.send(frame(0x100, 1)).ok());
}

TEST(ErrorFrames, DecodeTheKernelsEncoding) {
  // As the kernel's can-dev sends them (linux/can/error.h).
  CanFrame f;
  f.id = CAN_ERR_FLAG | CAN_ERR_CRTL | CAN_ERR_CNT;
  f.len = CAN_ERR_DLC;
  f.data[1] = CAN_ERR_CRTL_RX_PASSIVE;
  f.data[6] = 12;
  f.data[7] = 130;
  CanErrorInfo e = decode_error_frame(f);
  EXPECT_TRUE(e.controller);
  EXPECT_TRUE(e.passive);
  EXPECT_FALSE(e.bus_off);
  EXPECT_EQ(e.state, BusState::error_passive);
  EXPECT_EQ(e.rx_error_count, 130);
  char text[200];
  describe_error_frame(e, text, sizeof text);
  EXPECT_NE(std::strstr(text, "error passive"), nullptr) << text;
  EXPECT_NE(std::strstr(text, "rx errors 130"), nullptr) << text;

  f = CanFrame{};
  f.id = CAN_ERR_FLAG | CAN_ERR_CRTL;
  f.len = 8;
  f.data[1] = CAN_ERR_CRTL_TX_WARNING;
  EXPECT_EQ(decode_error_frame(f).state, BusState::error_warning);

  f.id = CAN_ERR_FLAG | CAN_ERR_PROT | CAN_ERR_BUSERROR;
  f.data[1] = 0;
  f.data[2] = CAN_ERR_PROT_STUFF;
  e = decode_error_frame(f);
  EXPECT_TRUE(e.protocol);
  EXPECT_FALSE(e.has_state);
  describe_error_frame(e, text, sizeof text);
  EXPECT_NE(std::strstr(text, "stuff error"), nullptr) << text;

  f.id = CAN_ERR_FLAG | CAN_ERR_ACK;
  describe_error_frame(decode_error_frame(f), text, sizeof text);
  EXPECT_NE(std::strstr(text, "no ACK"), nullptr) << text;

  f.id = CAN_ERR_FLAG | CAN_ERR_CRTL;
  f.data[1] = CAN_ERR_CRTL_RX_OVERFLOW;
  EXPECT_TRUE(decode_error_frame(f).rx_overflow);

  // A data frame is not an error frame.
  EXPECT_FALSE(decode_error_frame(frame(0x80, 0)).has_state);
  // A tiny buffer is still NUL-terminated.
  char tiny[5];
  describe_error_frame(decode_error_frame(make_error_frame(CAN_ERR_BUSOFF)), tiny, sizeof tiny);
  EXPECT_EQ(std::strlen(tiny), 4u);
}

TEST(SocketCan, ReportsClearlyWhenTheKernelHasNoCan) {
  std::string why;
  if (SocketCanBus::available(&why)) GTEST_SKIP() << "this kernel has SocketCAN; the smoke program tests it on vcan0";
  EXPECT_NE(why.find("EAFNOSUPPORT"), std::string::npos) << why;
  try {
    SocketCanBus bus("vcan0");
    FAIL() << "opened a CAN socket on a kernel without CAN";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("SocketCAN is not available"), std::string::npos) << e.what();
  }
}

TEST(SocketCan, RefusesABadInterfaceName) {
  EXPECT_THROW(SocketCanBus(""), Error);
  EXPECT_THROW(SocketCanBus("a_name_much_too_long_for_ifnamsiz"), Error);
}
