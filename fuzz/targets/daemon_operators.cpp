// SPDX-License-Identifier: Apache-2.0
// What cpmd reads from its operators directory (docs/security.md): a key
// file's bytes (daemon::parse_key) and roles.yaml (daemon::parse_roles). The
// first input byte picks which. Oracle: only cpm::Error escapes; a key
// parsed is 32 bytes that are not all zero, and hex keys read back to their
// own text; every role taken has a valid operator name.
#include <string>

#include "cpm/daemon/auth.hpp"
#include "fuzz_common.hpp"

using namespace cpm;

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  if (size == 0 || size > 64 * 1024) return 0;
  const std::string text(reinterpret_cast<const char*>(data) + 1, size - 1);
  if (data[0] & 1) {
    daemon::Key k{};
    if (!fuzz::refused_cleanly([&] { k = daemon::parse_key(text, "fuzz.key"); })) return 0;
    bool zero = true;
    for (auto b : k) zero = zero && b == 0;
    FUZZ_CHECK(!zero, "an all-zero key was accepted");
    if (text.size() != daemon::kKeyBytes) {
      const std::string hex = daemon::key_to_hex(k);
      FUZZ_CHECK(daemon::parse_key(hex, "again") == k, "a key does not read back from its hex");
    }
    return 0;
  }
  std::vector<std::string> problems;
  std::map<std::string, daemon::Role> roles;
  if (!fuzz::refused_cleanly([&] { roles = daemon::parse_roles(text, "roles.yaml", problems); })) return 0;
  for (const auto& [name, role] : roles) {
    FUZZ_CHECK(daemon::valid_operator_name(name), "a role for an invalid operator name");
    FUZZ_CHECK(role == daemon::Role::observer || role == daemon::Role::operator_ || role == daemon::Role::engineer,
               "a role that is none of the three");
  }
  return 0;
}
