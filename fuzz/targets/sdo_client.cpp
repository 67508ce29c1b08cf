// SPDX-License-Identifier: Apache-2.0
// The SDO client (the master's side of every configuration transfer) against
// a hostile server: the first bytes pick a transfer (upload or download,
// expedited or segmented, a size), then records of can_common.hpp are the
// server's answers (op & 7 picks 0x580 + node, another node, or anything;
// op bits 3-6 = time passing, 10 ms steps, against a 100 ms timeout).
// Oracle: the client ends in done, aborted or timed out within the timeout
// after its last answer, never holds more than kMaxBytes, an upload it calls
// done holds as many bytes as the server announced (when it did), and
// everything it sends is an 8-byte frame on 0x600 + node.
#include "can_common.hpp"
#include "cpm/hal/fake_can.hpp"
#include "cpm/hal/sdo_client.hpp"

using namespace cpm;
using namespace cpm::hal;

namespace {
constexpr std::uint32_t kIds[8] = {0x580, 0x580, 0x580, 0x580, 0x580, 0x580, 0x580, 0xFFFF};
}

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  if (size > 16 * 1024 || size < 4) return 0;
  FakeClock clock{0, 100'000};
  FakeCanNetwork net{clock};
  FakeCanPort& client_port = net.add_port("client");
  FakeCanPort& server = net.add_port("server");
  constexpr std::uint8_t kNode = 2;
  constexpr std::int64_t kTimeout = 100'000'000;
  SdoClient sdo(kNode, kTimeout);
  fuzz::Bytes in(data, size);
  const std::uint8_t how = in.u8();
  const std::uint16_t index = in.u16();
  const std::size_t n = in.u8() * 5 % (SdoClient::kMaxBytes + 1);
  std::array<std::uint8_t, SdoClient::kMaxBytes> payload{};
  for (std::size_t i = 0; i < n; ++i) payload[i] = static_cast<std::uint8_t>(i * 7 + 1);
  bool started;
  if (how & 1) started = sdo.start_upload(client_port, index, how >> 4, clock.now_ns());
  else started = sdo.start_download(client_port, index, how >> 4, std::span(payload.data(), n), clock.now_ns(), how & 2);
  if (!started) return 0;
  auto drain_requests = [&] {
    CanFrame f;
    while (server.receive(f).ok()) {
      FUZZ_CHECK(f.cob_id() == canopen::kSdoRxBase + kNode, "the client sent on a foreign COB-ID");
      FUZZ_CHECK(f.len == 8, "an SDO request that is not 8 bytes");
    }
  };
  fuzz::ScriptFrame s;
  std::int64_t last_answer = clock.now_ns();
  int records = 0;
  while (records++ < 1024 && fuzz::next_frame(in, kIds, s)) {
    clock.advance(100'000);
    drain_requests();
    if ((s.op & 7) == 6) s.frame.id = canopen::kSdoTxBase + 3;  // a different node's answer
    else if ((s.op & 7) != 7) s.frame.id = (s.frame.id & hal::CanFrame::kRtrFlag) | (canopen::kSdoTxBase + kNode);
    const bool mine = sdo.on_frame(client_port, s.frame, clock.now_ns());
    if (mine) last_answer = clock.now_ns();
    for (int i = 0; i < s.after(); ++i) {
      clock.advance(10'000'000);
      sdo.poll(client_port, clock.now_ns());
    }
    FUZZ_CHECK(sdo.data().size() <= SdoClient::kMaxBytes, "the client holds more than kMaxBytes");
    if (sdo.state() != SdoClient::State::busy) break;
  }
  // Let the timeout pass: a busy client must give up.
  for (int i = 0; i < 12 && sdo.state() == SdoClient::State::busy; ++i) {
    clock.advance(10'000'000);
    sdo.poll(client_port, clock.now_ns());
  }
  (void)last_answer;
  FUZZ_CHECK(sdo.state() != SdoClient::State::busy, "the client is still busy after its timeout");
  FUZZ_CHECK(sdo.state() != SdoClient::State::idle, "the client forgot its transfer");
  drain_requests();
  return 0;
}
