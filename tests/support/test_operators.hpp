// SPDX-License-Identifier: Apache-2.0
// Operators for in-process tests of the server (docs/security.md): a table
// as cpmd would load it from operators.d, with fixed keys, and helpers that
// sign commands as a given operator.
//   alice: engineer   bob: operator   olga: observer
// A key derived from a name is fine for a test and nothing else.
#pragma once

#include <cstring>
#include <memory>
#include <string>
#include <vector>

#include "cpm/daemon/auth.hpp"

namespace cpm::daemon::test {

// The boot id of the servers of in-process tests (Server::set_boot_id):
// acquires are signed for it.
inline constexpr std::int64_t kTestBoot = 0x0B0071D;

inline Credentials credentials(const std::string& name) {
  Credentials c;
  c.name = name;
  c.boot = kTestBoot;
  for (std::size_t i = 0; i < c.key.size(); ++i)
    c.key[i] = static_cast<std::uint8_t>(0x5a ^ (i * 7) ^ static_cast<unsigned char>(name[i % name.size()]));
  return c;
}

inline std::shared_ptr<const OperatorTable> operator_table() {
  auto t = std::make_shared<OperatorTable>();
  t->dir = "(test)";
  for (auto [name, role] : {std::pair{"alice", Role::engineer}, {"bob", Role::operator_}, {"olga", Role::observer}}) {
    Operator op;
    op.name = name;
    op.role = role;
    op.key = credentials(name).key;
    t->operators.emplace(name, op);
  }
  return t;
}

// An encoded command signed as `who`: its operator name written into the
// message first (so the name is inside what the MAC covers).
template <class M>
std::vector<std::uint8_t> encode_signed(M m, const Credentials& who) {
  sign(m, who);
  std::vector<std::uint8_t> b(static_cast<std::size_t>(m.getEncodedSize()));
  m.encode(b.data(), 0, static_cast<int>(b.size()));
  return b;
}

// Wall clock for acquires (us since the epoch): the server's clock in these
// tests is set to kWallClock s, and an acquire's seq must be near it and rising.
inline constexpr double kWallClock = 1.8e9;
inline std::int64_t acquire_seq() {
  static std::int64_t n = 0;
  return static_cast<std::int64_t>(kWallClock * 1e6) + ++n;
}

}  // namespace cpm::daemon::test
