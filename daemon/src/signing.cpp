#include <cpm/daemon/signing.hpp>

#include <sodium.h>

#include <cstdio>
#include <fstream>
#include <sstream>
#include <stdexcept>

namespace cpm::daemon {
namespace {
void init_sodium() {
  if (sodium_init() < 0) throw Error("libsodium cannot start");
}
}  // namespace

PublicKey public_key_of(const Key& seed) {
  init_sodium();
  PublicKey pk{};
  std::array<std::uint8_t, 64> sk{};
  crypto_sign_seed_keypair(pk.data(), sk.data(), seed.data());
  sodium_memzero(sk.data(), sk.size());
  return pk;
}

PublicKey read_public_key_file(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw Error(path + ": cannot read cpmd's public key (docs/security.md, \"Signed state\")");
  std::ostringstream ss;
  ss << in.rdbuf();
  const std::string text = ss.str();
  if (text.size() > 200) throw Error(path + ": too big for a public key file (64 hexadecimal digits)");
  const Key k = parse_key(text, path);  // same format as a key: 32 bytes, hex
  PublicKey pk{};
  std::copy(k.begin(), k.end(), pk.begin());
  return pk;
}

void write_public_key_file(const std::string& path, const PublicKey& k) {
  Key as_key{};
  std::copy(k.begin(), k.end(), as_key.begin());
  std::ofstream out(path, std::ios::trunc);
  out << key_to_hex(as_key) << "\n";
  if (!out) throw Error(path + ": cannot write the public key");
}

Signer::~Signer() { sodium_memzero(secret_.data(), secret_.size()); }

Signer::Signer(const Key& seed) {
  init_sodium();
  PublicKey pk{};
  crypto_sign_seed_keypair(pk.data(), secret_.data(), seed.data());
  buf_.reserve(2048);
}

void Signer::sign_bytes(const std::uint8_t* data, std::size_t size, std::uint8_t (&sig)[kSignatureBytes]) const {
  crypto_sign_detached(sig, nullptr, data, size, secret_.data());
}

bool signature_valid_bytes(const std::uint8_t* data, std::size_t size, const std::uint8_t (&sig)[kSignatureBytes],
                           const PublicKey& pk) {
  static const bool ready = sodium_init() >= 0;
  return ready && crypto_sign_verify_detached(sig, data, size, pk.data()) == 0;
}

const char* trust_text(Trust t) noexcept {
  switch (t) {
    case Trust::ok: return "verified";
    case Trust::unsigned_message: return "unsigned (this cpmd does not sign, or the message is forged): cannot be verified";
    case Trust::bad_signature: return "its signature does not verify (forged or tampered)";
    case Trust::stale: return "not newer than the last verified one (replayed or reordered)";
    case Trust::other_boot: return "from another start of cpmd than the one this client began with (cpmd restarted)";
  }
  return "?";
}

std::int64_t Verifier::refused_total() const noexcept {
  std::int64_t n = 0;
  for (auto v : refused_) n += v;
  return n;
}

}  // namespace cpm::daemon
