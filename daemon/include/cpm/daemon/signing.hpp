// SPDX-License-Identifier: Apache-2.0
// Signed state (docs/security.md, "Signed state"): cpmd seals what it
// publishes (state, acks, drives, statistics, parameters, security counts)
// with its Ed25519 key, so that any observer can check it with the public
// half alone. One signature covers many messages: each message's BLAKE2b
// digest goes into the next seal_t, which cpmd signs every 32 messages or
// within 10 ms, on a sealing thread (an ack's at once; 1 ms after an ack
// where the publishing thread signs). A client trusts a message once a seal
// that lists it has verified, and refuses what no seal lists, what is not
// newer than the last of its kind, and what comes from another boot.
#pragma once

#include <array>
#include <atomic>
#include <cstdint>
#include <functional>
#include <map>
#include <optional>
#include <string>
#include <thread>
#include <type_traits>
#include <utility>
#include <vector>

#include <cpm/daemon/auth.hpp>
#include <cpm_msgs/seal_t.hpp>

namespace cpm::daemon {

using PublicKey = std::array<std::uint8_t, 32>;
using Digest = std::array<std::uint8_t, 32>;  // BLAKE2b-256
inline constexpr std::size_t kSignatureBytes = 64;

// Whether message type M carries a sign_counter (state_t, ack_t). Written
// without C++20's requires-expression: this header is installed with the
// client library, whose users may build as C++17 (examples/client).
template <class M, class = void>
struct HasSignCounter : std::false_type {};
template <class M>
struct HasSignCounter<M, std::void_t<decltype(std::declval<M&>().sign_counter)>> : std::true_type {};

// The public half of a daemon key (its 32-byte seed, a key file as `cpm keygen` writes).
PublicKey public_key_of(const Key& seed);
// A public key file: 64 hexadecimal digits. Unlike a secret key it may be world-readable.
PublicKey read_public_key_file(const std::string& path);
void write_public_key_file(const std::string& path, const PublicKey& k);

// BLAKE2b-256 of a message's bytes as published (its whole LCM encoding).
Digest digest_of(const void* data, std::size_t size);

// When cpmd seals (seal_t): after this many messages, or once the oldest
// unsealed one is this old (s), or an unsealed ack is (a command waits for it).
inline constexpr std::size_t kSealEvery = 32;
inline constexpr double kSealWithin = 0.010;
inline constexpr double kSealAckWithin = 0.001;

// cpmd's side, in the publishing thread (never the control cycle): encodes
// each message, gives it the next counter (state_t and ack_t carry it),
// keeps its digest, and seals the digests when due(). The signature is made
// on the calling thread, or, once start_thread() ran, on a sealing thread of
// its own: the publishing thread then pays for the digests only.
class Signer {
 public:
  // What a seal lists at most (decode_seal's bound): digests are kept while
  // the sealing thread is behind, and sealed here beyond this.
  static constexpr std::size_t kMostDigests = 1024;
  // Seals handed to the sealing thread and not yet signed, at most.
  static constexpr std::size_t kHandoffSlots = 8;
  using Publish = std::function<void(const std::uint8_t* data, std::size_t size)>;

  Signer(const Key& seed, std::int64_t boot_id);
  ~Signer();  // stops the sealing thread after it published what it was handed
  Signer(const Signer&) = delete;
  Signer& operator=(const Signer&) = delete;
  void set_boot_id(std::int64_t boot) noexcept { boot_ = boot; }
  // m encoded (with its sign_counter set when it has one) and listed for the
  // next seal; the bytes to publish, valid until the next add or seal. `now`:
  // the publisher's monotonic clock (s); `ack`: a command waits for it.
  template <class M>
  const std::vector<std::uint8_t>& add(M& m, double now, bool ack = false) {
    if constexpr (HasSignCounter<M>::value) m.sign_counter = counter_ + 1;
    buf_.resize(static_cast<std::size_t>(m.getEncodedSize()));
    m.encode(buf_.data(), 0, static_cast<int>(buf_.size()));
    list(now, ack);
    return buf_;
  }
  // Whether a seal is due at `now` (kSealEvery, kSealWithin, kSealAckWithin;
  // with a sealing thread an ack is due at once: its signature costs this
  // thread nothing, and the command waiting for it waits less).
  [[nodiscard]] bool due(double now) const noexcept;
  [[nodiscard]] std::size_t unsealed() const noexcept { return unsealed_; }
  // The seal of every message added since the last one (`utime`: its wall
  // clock, us). Without a sealing thread: signed here, encoded, returned
  // (empty when there is nothing to seal). With one: handed to it without a
  // lock or a wait, and returned empty; when it is kHandoffSlots seals
  // behind, the digests wait for the next call (signed here beyond kMostDigests).
  const std::vector<std::uint8_t>& seal(std::int64_t utime);
  [[nodiscard]] std::int64_t counter() const noexcept { return counter_; }

  // Sign on a thread of its own from now on, which gives each seal to
  // `publish` (which must be safe to call beside the publishing thread, as
  // lcm::LCM::publish is). The thread inherits the caller's CPUs and
  // scheduling: cpmd starts it from its LCM thread (never loop.cpu, normal
  // scheduling), so it never competes with the loop's SCHED_FIFO thread.
  void start_thread(Publish publish);
  // Waits until the sealing thread published every seal handed to it, and
  // ends it. What is still listed (not handed over: the thread was behind)
  // goes into the next seal(), signed on the calling thread.
  void stop_thread();
  // Seals handed to the sealing thread and not yet published.
  [[nodiscard]] std::uint64_t seals_waiting() const noexcept {
    return handed_.load(std::memory_order_acquire) - signed_.load(std::memory_order_acquire);
  }
  // Seals signed on the publishing thread although a sealing thread runs (it was far behind).
  [[nodiscard]] std::int64_t sealed_here() const noexcept { return sealed_here_; }

 private:
  void list(double now, bool ack);
  // seal_ (its header filled) signed and encoded into `out`.
  void sign(cpm_msgs::seal_t& s, std::vector<std::uint8_t>& out) const;
  void run_thread();
  std::array<std::uint8_t, 64> secret_{};
  std::int64_t boot_ = 0;
  std::int64_t counter_ = 0;
  std::size_t unsealed_ = 0;
  double oldest_ = 0.0, oldest_ack_ = -1.0;  // -1: no ack waits
  double ack_within_ = kSealAckWithin;
  cpm_msgs::seal_t seal_{};
  std::vector<std::uint8_t> buf_, sealed_;
  std::int64_t sealed_here_ = 0;
  // The hand-off to the sealing thread: one producer (seal()), one consumer.
  // A slot's digests are swapped in, never copied or allocated.
  std::array<cpm_msgs::seal_t, kHandoffSlots> slots_{};
  std::atomic<std::uint64_t> handed_{0}, signed_{0};
  std::atomic<std::uint32_t> wake_{0};
  std::atomic<bool> quit_{false};
  Publish publish_;
  std::thread thread_;
};

// Whether m's signature verifies with `pk` (m's encoding with its signature zeroed).
bool signature_valid_bytes(const std::uint8_t* data, std::size_t size, const std::uint8_t (&sig)[kSignatureBytes],
                           const PublicKey& pk);
bool seal_valid(const cpm_msgs::seal_t& s, const PublicKey& pk);
// A seal_t as received: decoded only when its digests are whole (32 bytes
// each, at most 1024 of them) and the sizes account for the bytes exactly.
std::optional<cpm_msgs::seal_t> decode_seal(const void* data, std::size_t size);

// What a client makes of one message or seal. `pending`: no verified seal
// lists it yet (it is held, not shown). `unsealed`: verified seals came and
// none listed it (forged, tampered, or its seal was lost).
enum class Trust { ok, unsigned_message, bad_signature, stale, other_boot, unsealed, pending };
const char* trust_text(Trust t) noexcept;

// The kinds of message a client keeps apart: each must be newer than the last of its kind.
enum class Stream { state, ack, drives, stats, params, security };
inline constexpr int kStreams = 6;

// A client's view of one cpmd: the boot it started with (the first verified
// seal's), the seals verified, the messages waiting for theirs. The caller
// holds each waiting message under its `ticket` and acts on the verdicts.
class Verifier {
 public:
  // How many waiting messages are kept at most (the oldest is refused as unsealed beyond).
  static constexpr std::size_t kMaxWaiting = 1024;
  // A waiting message is refused as unsealed once this many verified seals came without it.
  static constexpr std::int64_t kSealsToWait = 3;

  struct Verdict {
    std::uint64_t ticket;
    Stream stream;
    Trust trust;
  };

  explicit Verifier(const PublicKey& pk) : pk_(pk) {}
  // A message as received (its bytes). ok: a verified seal already lists it
  // (it may be used now); pending: held under `ticket` until a seal decides
  // (seal() returns the verdict); otherwise refused (stale).
  Trust offer(Stream s, const void* data, std::size_t size, std::uint64_t ticket);
  // A seal as received: its own verdict (ok, bad_signature, stale,
  // other_boot, unsigned_message for bytes that are no seal). Appends to
  // `decided` the verdicts of waiting messages it decides: ok in the order
  // cpmd published them, stale, and unsealed for those waiting too long.
  Trust seal(const void* data, std::size_t size, std::vector<Verdict>& decided);
  // Counts a refusal the caller decided itself (a state or ack with counter 0: unsigned).
  Trust refuse(Trust t) noexcept { return count(t); }
  [[nodiscard]] std::int64_t boot() const noexcept { return boot_; }
  [[nodiscard]] std::int64_t seals_verified() const noexcept { return seals_; }
  [[nodiscard]] std::size_t waiting() const noexcept { return waiting_.size(); }
  // Refused so far, by cause (index: Trust), and in all.
  [[nodiscard]] std::int64_t refused(Trust t) const noexcept { return refused_[static_cast<int>(t)]; }
  [[nodiscard]] std::int64_t refused_total() const noexcept;

 private:
  struct Waiting {
    Digest digest;
    Stream stream;
    std::int64_t seals_then;  // seals_ when it arrived
  };
  struct Recent {  // a verified seal, for messages that arrive after it
    std::int64_t first;
    std::vector<Digest> digests;
  };
  Trust count(Trust t) noexcept {
    ++refused_[static_cast<int>(t)];
    return t;
  }
  // ok and the stream's counter raised when `counter` is newer than its last; stale otherwise.
  Trust take(Stream s, std::int64_t counter) noexcept;
  PublicKey pk_;
  std::int64_t boot_ = 0;
  std::int64_t last_sealed_ = 0;  // the highest counter a verified seal listed
  std::int64_t seals_ = 0;
  std::array<std::int64_t, kStreams> last_{};
  std::array<std::int64_t, 7> refused_{};
  std::map<std::uint64_t, Waiting> waiting_;
  std::vector<Recent> recent_;  // the last few verified seals, oldest first
};

}  // namespace cpm::daemon
