// SPDX-License-Identifier: Apache-2.0
// The pure decoders of hal on one arbitrary frame: error frames, EMCY and
// its text, TPDO unpacking, statusword/controlword decoding, SDO abort text.
// Oracle: the texts are NUL-terminated within their buffers and never
// written past them; decoders accept only the lengths they are for.
#include <cstring>

#include "cpm/hal/cia402.hpp"
#include "cpm/hal/master.hpp"
#include "cpm/hal/pdo.hpp"
#include "fuzz_common.hpp"

using namespace cpm;
using namespace cpm::hal;

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  if (size < 5) return 0;
  fuzz::Bytes in(data, size);
  CanFrame f;
  f.id = in.u32();
  f.len = in.u8();
  in.take(f.data.data(), 8);
  const std::size_t bufsize = 1 + in.u8() % 160;  // 1..160 bytes: short buffers must truncate
  char buf[161];
  std::memset(buf, 'Z', sizeof buf);

  (void)decode_error_frame(f);
  canopen::Emcy e;
  if (canopen::decode_emcy(f, e)) {
    FUZZ_CHECK(f.len == 8, "decode_emcy accepted a frame of length " + std::to_string(f.len));
    const std::size_t n = canopen::describe_emcy(static_cast<std::uint8_t>(f.cob_id() & 0x7F), e, buf, bufsize);
    FUZZ_CHECK(n < bufsize && std::memchr(buf, 0, bufsize) != nullptr, "describe_emcy left no NUL");
    FUZZ_CHECK(buf[bufsize] == 'Z', "describe_emcy wrote past its buffer");
    (void)canopen::emcy_class_text(e.code);
    (void)canopen::emcy_code_text(e.code);
  }
  std::memset(buf, 'Z', sizeof buf);
  (void)canopen::error_register_text(f.data[0], buf, bufsize);
  FUZZ_CHECK(std::memchr(buf, 0, bufsize) != nullptr && buf[bufsize] == 'Z', "error_register_text overflow");
  std::memset(buf, 'Z', sizeof buf);
  (void)describe_drive_faults(f.id, buf, bufsize);
  FUZZ_CHECK(std::memchr(buf, 0, bufsize) != nullptr && buf[bufsize] == 'Z', "describe_drive_faults overflow");
  std::uint16_t sw = 0;
  std::int32_t pos = 0, vel = 0;
  if (pdo::unpack_tpdo1(f, sw, pos)) FUZZ_CHECK(f.len == 6, "unpack_tpdo1 accepted length " + std::to_string(f.len));
  if (pdo::unpack_tpdo2(f, vel)) FUZZ_CHECK(f.len == 4, "unpack_tpdo2 accepted length " + std::to_string(f.len));
  const auto state = cia402::decode_statusword(static_cast<std::uint16_t>(f.id));
  (void)cia402::state_name(state);
  (void)cia402::decode_controlword(static_cast<std::uint16_t>(f.id >> 16));
  const char* t = canopen::sdo_abort_text(f.id);
  FUZZ_CHECK(t != nullptr, "sdo_abort_text returned null");
  return 0;
}
