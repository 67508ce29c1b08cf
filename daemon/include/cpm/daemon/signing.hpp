// Signed state and acks (docs/security.md, "Signed state"): cpmd signs every
// state_t and ack_t it publishes with its Ed25519 key, so that any observer
// can check them with the public half alone, and a client refuses what does
// not verify, is not newer than the last one, or comes from another boot.
#pragma once

#include <array>
#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include <cpm/daemon/auth.hpp>

namespace cpm::daemon {

using PublicKey = std::array<std::uint8_t, 32>;
inline constexpr std::size_t kSignatureBytes = 64;

// The public half of a daemon key (its 32-byte seed, a key file as `cpm keygen` writes).
PublicKey public_key_of(const Key& seed);
// A public key file: 64 hexadecimal digits. Unlike a secret key it may be world-readable.
PublicKey read_public_key_file(const std::string& path);
void write_public_key_file(const std::string& path, const PublicKey& k);

// Signs in the publishing thread (never the control cycle). One counter for
// state and acks, so that their order is provable too.
class Signer {
 public:
  explicit Signer(const Key& seed);
  ~Signer();
  Signer(const Signer&) = delete;
  Signer& operator=(const Signer&) = delete;
  // Sets m.sign_counter (next value) and m.signature; ack_t's boot_id too.
  template <class M>
  void sign(M& m) {
    m.sign_counter = ++counter_;
    for (auto& b : m.signature) b = 0;
    buf_.resize(static_cast<std::size_t>(m.getEncodedSize()));
    m.encode(buf_.data(), 0, static_cast<int>(buf_.size()));
    sign_bytes(buf_.data(), buf_.size(), m.signature);
  }
  [[nodiscard]] std::int64_t counter() const noexcept { return counter_; }

 private:
  void sign_bytes(const std::uint8_t* data, std::size_t size, std::uint8_t (&sig)[kSignatureBytes]) const;
  std::array<std::uint8_t, 64> secret_{};
  std::int64_t counter_ = 0;
  std::vector<std::uint8_t> buf_;
};

// Whether m's signature verifies with `pk` (m's encoding with its signature zeroed).
template <class M>
bool signature_valid(const M& m, const PublicKey& pk);
bool signature_valid_bytes(const std::uint8_t* data, std::size_t size, const std::uint8_t (&sig)[kSignatureBytes],
                           const PublicKey& pk);

template <class M>
bool signature_valid(const M& m, const PublicKey& pk) {
  M z = m;
  for (auto& b : z.signature) b = 0;
  std::vector<std::uint8_t> buf(static_cast<std::size_t>(z.getEncodedSize()));
  z.encode(buf.data(), 0, static_cast<int>(buf.size()));
  return signature_valid_bytes(buf.data(), buf.size(), m.signature, pk);
}

// What a client makes of one signed message.
enum class Trust { ok, unsigned_message, bad_signature, stale, other_boot };
const char* trust_text(Trust t) noexcept;

// A client's view of one cpmd: the boot it started with (the first verified
// message's) and the highest counter seen. Messages that are not `ok` are
// counted per cause and must be dropped by the caller.
class Verifier {
 public:
  explicit Verifier(const PublicKey& pk) : pk_(pk) {}
  // `boot`: the message's boot id. `stream`: 0 state, 1 acks (the counter is
  // shared, so each stream's rises with gaps; LCM does not order across channels).
  template <class M>
  Trust check(const M& m, std::int64_t boot, int stream) {
    if (m.sign_counter == 0) return count(Trust::unsigned_message);
    if (!signature_valid(m, pk_)) return count(Trust::bad_signature);
    if (boot_ == 0) boot_ = boot;
    if (boot != boot_) return count(Trust::other_boot);
    if (m.sign_counter <= last_[stream]) return count(Trust::stale);
    last_[stream] = m.sign_counter;
    return Trust::ok;
  }
  [[nodiscard]] std::int64_t boot() const noexcept { return boot_; }
  // Refused so far, by cause (index: Trust), and in all.
  [[nodiscard]] std::int64_t refused(Trust t) const noexcept { return refused_[static_cast<int>(t)]; }
  [[nodiscard]] std::int64_t refused_total() const noexcept;

 private:
  Trust count(Trust t) noexcept {
    ++refused_[static_cast<int>(t)];
    return t;
  }
  PublicKey pk_;
  std::int64_t boot_ = 0;
  std::array<std::int64_t, 2> last_{};
  std::array<std::int64_t, 5> refused_{};
};

}  // namespace cpm::daemon
