// SPDX-License-Identifier: Apache-2.0
// The bytes of an ack_t as a client receives them on CPMD_ACK, where anyone
// on the bus may publish (docs/security.md): daemon::decode_ack, which the
// client uses instead of lcm-gen's typed decoding. Oracle: it never throws;
// what it accepts is exactly the message's size, and encodes to bytes that
// decode to the same ack (a boolean byte other than 0 or 1 reads as true and
// is written back as 1: the bytes may differ there, the ack may not).
#include <vector>

#include "cpm/daemon/client.hpp"
#include "fuzz_common.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  std::optional<cpm_msgs::ack_t> a;
  try {
    a = cpm::daemon::decode_ack(data, size);
  } catch (const std::exception& e) {
    cpm::fuzz::fail(__FILE__, __LINE__, std::string("decode_ack threw: ") + e.what());
  }
  if (!a) return 0;
  std::vector<std::uint8_t> back(static_cast<std::size_t>(a->getEncodedSize()));
  FUZZ_CHECK(back.size() == size, "an accepted ack of another size than its encoding");
  a->encode(back.data(), 0, static_cast<int>(back.size()));
  const auto again = cpm::daemon::decode_ack(back.data(), back.size());
  FUZZ_CHECK(again.has_value(), "an accepted ack whose own encoding is refused");
  FUZZ_CHECK(again->utime == a->utime && again->id == a->id && again->source == a->source &&
                 again->command == a->command && again->accepted == a->accepted && again->reason == a->reason &&
                 again->message == a->message && again->mode == a->mode && again->queue_depth == a->queue_depth &&
                 again->session == a->session,
             "an accepted ack that does not read back the same");
  return 0;
}
