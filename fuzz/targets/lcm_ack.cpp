// The bytes of an ack_t as a client receives them on CPMD_ACK, where anyone
// on the bus may publish (docs/security.md): daemon::decode_ack, which the
// client uses instead of lcm-gen's typed decoding. Oracle: it never throws;
// what it accepts encodes back to exactly the bytes it came from.
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
  FUZZ_CHECK(std::equal(back.begin(), back.end(), data), "an accepted ack that does not encode back to its bytes");
  return 0;
}
