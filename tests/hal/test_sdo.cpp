// SPDX-License-Identifier: Apache-2.0
// SDO client against the virtual drive's SDO server on the fake bus:
// expedited and segmented transfers both ways, aborts, timeouts.
#include <gtest/gtest.h>

#include <cstring>
#include <string>

#include "cpm/hal/canopen.hpp"
#include "cpm/hal/fake_can.hpp"
#include "cpm/hal/sdo_client.hpp"
#include "cpm/hal/virtual_drive.hpp"

using namespace cpm::hal;
using namespace cpm::hal::canopen;

namespace {

struct SdoRig {
  FakeClock clock{0, 100'000};
  FakeCanNetwork net{clock};
  FakeCanPort& client_port = net.add_port("client");
  FakeCanPort& drive_port = net.add_port("drive");
  FakeCanPort& spy = net.add_port("spy");
  VirtualDrive drive{drive_port, VirtualDriveConfig{}};
  SdoClient sdo{1, 50'000'000};  // 50 ms per answer

  SdoRig() { drive.power_on(0); drain_spy(); }
  void drain_spy() {
    CanFrame f;
    while (spy.receive(f).ok()) {
    }
  }
  // Run until the transfer ends; returns the number of 100 us steps taken.
  int run() {
    int steps = 0;
    while (sdo.state() == SdoClient::State::busy && steps < 100000) {
      drive.poll(clock.now_ns());
      CanFrame f;
      while (client_port.receive(f).ok()) sdo.on_frame(client_port, f, clock.now_ns());
      sdo.poll(client_port, clock.now_ns());
      clock.advance(100'000);
      ++steps;
    }
    return steps;
  }
  std::uint32_t upload_u32(std::uint16_t i, std::uint8_t s) {
    EXPECT_TRUE(sdo.start_upload(client_port, i, s, clock.now_ns()));
    run();
    EXPECT_EQ(sdo.state(), SdoClient::State::done);
    std::uint32_t v = 0;
    for (std::size_t k = 0; k < sdo.data().size(); ++k) v |= std::uint32_t{sdo.data()[k]} << (8 * k);
    return v;
  }
};

}  // namespace

TEST(Sdo, ExpeditedDownloadAndUploadOfEachSize) {
  SdoRig r;
  const std::uint8_t hb[] = {0x2C, 0x01};  // 300 ms
  ASSERT_TRUE(r.sdo.start_download(r.client_port, 0x1017, 0, hb, 0));
  r.run();
  ASSERT_EQ(r.sdo.state(), SdoClient::State::done);
  EXPECT_FALSE(r.sdo.was_segmented());
  EXPECT_EQ(r.drive.od_value(0x1017, 0), 300u);
  EXPECT_EQ(r.upload_u32(0x1017, 0), 300u);
  EXPECT_EQ(r.sdo.data().size(), 2u);  // the size the server indicated
  EXPECT_EQ(r.upload_u32(0x1000, 0), 0x00020192u);
  EXPECT_EQ(r.sdo.data().size(), 4u);
  const std::uint8_t mode = 10;
  ASSERT_TRUE(r.sdo.start_download(r.client_port, 0x6060, 0, {&mode, 1}, r.clock.now_ns()));
  r.run();
  ASSERT_EQ(r.sdo.state(), SdoClient::State::done);
  EXPECT_EQ(r.upload_u32(0x6061, 0), 10u);
  EXPECT_EQ(r.sdo.data().size(), 1u);
}

TEST(Sdo, SegmentedUploadOfAString) {
  SdoRig r;
  ASSERT_TRUE(r.sdo.start_upload(r.client_port, 0x1008, 0, 0));
  r.run();
  ASSERT_EQ(r.sdo.state(), SdoClient::State::done);
  EXPECT_TRUE(r.sdo.was_segmented());
  const std::string name(r.sdo.data().begin(), r.sdo.data().end());
  EXPECT_EQ(name, "cpm virtual CiA 402 drive");  // 25 bytes: 4 segments, the last one partial
}

TEST(Sdo, SegmentedDownloadThenUploadRoundTripsEveryLength) {
  for (std::size_t n : {1u, 4u, 5u, 7u, 8u, 14u, 15u, 63u, 64u}) {
    SdoRig r;
    std::vector<std::uint8_t> blob(n);
    for (std::size_t i = 0; i < n; ++i) blob[i] = static_cast<std::uint8_t>(i * 37 + 1);
    ASSERT_TRUE(r.sdo.start_download(r.client_port, 0x2000, 0, blob, 0, /*force_segmented=*/true));
    r.run();
    ASSERT_EQ(r.sdo.state(), SdoClient::State::done) << n << ": " << sdo_abort_text(r.sdo.abort_code());
    EXPECT_TRUE(r.sdo.was_segmented());
    EXPECT_EQ(r.drive.od_bytes(0x2000, 0), blob) << n;
    ASSERT_TRUE(r.sdo.start_upload(r.client_port, 0x2000, 0, r.clock.now_ns()));
    r.run();
    ASSERT_EQ(r.sdo.state(), SdoClient::State::done);
    EXPECT_EQ(std::vector<std::uint8_t>(r.sdo.data().begin(), r.sdo.data().end()), blob) << n;
  }
}

TEST(Sdo, ServerAbortsAreReportedWithTheStandardsText) {
  struct Case {
    std::uint16_t index;
    std::uint8_t sub;
    std::vector<std::uint8_t> data;
    bool upload;
    std::uint32_t code;
  };
  const Case cases[] = {
      {0x1234, 0, {}, true, 0x06020000},          // no object
      {0x1018, 9, {}, true, 0x06090011},          // no sub-index
      {0x1000, 0, {1, 2, 3, 4}, false, 0x06010002},  // read-only
      {0x1017, 0, {1, 2, 3, 4}, false, 0x06070012},  // too long for a u16
      {0x1017, 0, {1}, false, 0x06070013},        // too short
      {0x6060, 0, {3}, false, 0x06090030},        // unsupported mode
      {0x2000, 0, std::vector<std::uint8_t>(65, 0), false, 0x06070012},  // domain too long
  };
  for (const auto& c : cases) {
    SdoRig r;
    if (c.upload) ASSERT_TRUE(r.sdo.start_upload(r.client_port, c.index, c.sub, 0));
    else ASSERT_TRUE(r.sdo.start_download(r.client_port, c.index, c.sub, c.data, 0));
    r.run();
    ASSERT_EQ(r.sdo.state(), SdoClient::State::aborted) << std::hex << c.index;
    EXPECT_TRUE(r.sdo.aborted_by_server());
    EXPECT_EQ(r.sdo.abort_code(), c.code) << std::hex << c.index;
    EXPECT_STRNE(sdo_abort_text(r.sdo.abort_code()), "unknown abort code");
  }
  EXPECT_STREQ(sdo_abort_text(0x06020000), "Object does not exist in the object dictionary");
  EXPECT_STREQ(sdo_abort_text(0x12345678), "unknown abort code");
}

TEST(Sdo, TimeoutWhenTheServerIsSilentAndTheClientAbortsOnTheBus) {
  SdoRig r;
  r.drive.go_silent(true);
  ASSERT_TRUE(r.sdo.start_upload(r.client_port, 0x1000, 0, 0));
  const int steps = r.run();
  EXPECT_EQ(r.sdo.state(), SdoClient::State::timed_out);
  EXPECT_EQ(r.sdo.abort_code(), 0x05040000u);
  EXPECT_EQ(steps, 501);  // 50 ms of 100 us steps, then the first step past it
  // The client told the server: request, then abort 0x05040000.
  CanFrame f;
  ASSERT_TRUE(r.spy.receive(f).ok());
  EXPECT_EQ(f.data[0] >> 5, kCcsInitiateUpload);
  ASSERT_TRUE(r.spy.receive(f).ok());
  EXPECT_EQ(f.cob_id(), 0x601u);
  EXPECT_EQ(f.data[0], 0x80);
  EXPECT_EQ(get_u32(&f.data[4]), 0x05040000u);
}

TEST(Sdo, LateAnswersWithinTheTimeoutAreAcceptedLaterOnesTimeOut) {
  {
    SdoRig r;
    r.drive.answer_late(40'000'000);
    ASSERT_TRUE(r.sdo.start_upload(r.client_port, 0x1008, 0, 0));  // segmented: every answer 40 ms late
    r.run();
    EXPECT_EQ(r.sdo.state(), SdoClient::State::done);
    EXPECT_GE(r.clock.now_ns(), 5 * 40'000'000);  // initiate + 4 segments
  }
  {
    SdoRig r;
    r.drive.answer_late(60'000'000);
    ASSERT_TRUE(r.sdo.start_upload(r.client_port, 0x1000, 0, 0));
    r.run();
    EXPECT_EQ(r.sdo.state(), SdoClient::State::timed_out);
  }
}

TEST(Sdo, WrongToggleFromTheServerIsAbortedByTheClient) {
  // A hand-made server that answers the first upload segment with toggle 1.
  FakeClock clock;
  FakeCanNetwork net(clock);
  auto& c = net.add_port("client");
  auto& s = net.add_port("server");
  SdoClient sdo(5, 1'000'000);
  ASSERT_TRUE(sdo.start_upload(c, 0x2000, 0, 0));
  CanFrame f, r;
  ASSERT_TRUE(s.receive(f).ok());
  r.id = 0x585;
  r.len = 8;
  r.data = {0x41, 0x00, 0x20, 0x00, 20, 0, 0, 0};  // segmented, 20 bytes
  sdo.on_frame(c, r, 0);
  ASSERT_TRUE(s.receive(f).ok());
  EXPECT_EQ(f.data[0], 0x60);  // upload segment request, toggle 0
  r.data = {0x10, 1, 2, 3, 4, 5, 6, 7};  // toggle 1: wrong
  sdo.on_frame(c, r, 0);
  EXPECT_EQ(sdo.state(), SdoClient::State::aborted);
  EXPECT_FALSE(sdo.aborted_by_server());
  EXPECT_EQ(sdo.abort_code(), 0x05030000u);
  ASSERT_TRUE(s.receive(f).ok());
  EXPECT_EQ(f.data[0], 0x80);
  EXPECT_EQ(get_u32(&f.data[4]), 0x05030000u);
}

TEST(Sdo, ServerAbortInTheMiddleOfASegmentedDownload) {
  FakeClock clock;
  FakeCanNetwork net(clock);
  auto& c = net.add_port("client");
  SdoClient sdo(5, 1'000'000);
  const std::vector<std::uint8_t> blob(20, 7);
  ASSERT_TRUE(sdo.start_download(c, 0x2000, 0, blob, 0));
  CanFrame r;
  r.id = 0x585;
  r.len = 8;
  r.data = {0x60, 0x00, 0x20, 0x00, 0, 0, 0, 0};
  sdo.on_frame(c, r, 0);
  EXPECT_EQ(sdo.state(), SdoClient::State::busy);
  r = make_sdo_abort(0x585, 0x2000, 0, 0x08000020);
  sdo.on_frame(c, r, 0);
  EXPECT_EQ(sdo.state(), SdoClient::State::aborted);
  EXPECT_TRUE(sdo.aborted_by_server());
  EXPECT_EQ(sdo.abort_code(), 0x08000020u);
  // A transfer that is over ignores stray answers, and a new one can start.
  sdo.on_frame(c, r, 0);
  EXPECT_EQ(sdo.state(), SdoClient::State::aborted);
  EXPECT_TRUE(sdo.start_upload(c, 0x1000, 0, 0));
}

TEST(Sdo, RefusesTransfersItCannotHold) {
  FakeClock clock;
  FakeCanNetwork net(clock);
  auto& c = net.add_port("client");
  SdoClient sdo(5, 1'000'000);
  std::vector<std::uint8_t> big(SdoClient::kMaxBytes + 1);
  EXPECT_FALSE(sdo.start_download(c, 0x2000, 0, big, 0));
  EXPECT_FALSE(sdo.start_download(c, 0x2000, 0, {}, 0));
  ASSERT_TRUE(sdo.start_upload(c, 0x2000, 0, 0));
  EXPECT_FALSE(sdo.start_upload(c, 0x2000, 0, 0));  // one at a time
  CanFrame r;
  r.id = 0x585;
  r.len = 8;
  r.data = {0x41, 0x00, 0x20, 0x00, 0, 0, 1, 0};  // announces 65536 bytes
  sdo.on_frame(c, r, 0);
  EXPECT_EQ(sdo.state(), SdoClient::State::aborted);
  EXPECT_EQ(sdo.abort_code(), 0x05040005u);  // out of memory
}
