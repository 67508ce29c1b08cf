// SPDX-License-Identifier: Apache-2.0
#include <cpm/daemon/signing.hpp>

#include <sodium.h>

#include <algorithm>
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

Digest digest_of(const void* data, std::size_t size) {
  static const bool ready = sodium_init() >= 0;
  Digest d{};
  if (ready) crypto_generichash(d.data(), d.size(), static_cast<const unsigned char*>(data), size, nullptr, 0);
  return d;
}

Signer::~Signer() {
  stop_thread();
  sodium_memzero(secret_.data(), secret_.size());
}

Signer::Signer(const Key& seed, std::int64_t boot_id) : boot_(boot_id) {
  init_sodium();
  PublicKey pk{};
  crypto_sign_seed_keypair(pk.data(), secret_.data(), seed.data());
  buf_.reserve(16384);
  seal_.digests.reserve(kSealEvery * sizeof(Digest));
  for (auto& s : slots_) s.digests.reserve(kSealEvery * sizeof(Digest));
  sealed_.reserve(kSealEvery * sizeof(Digest) + 256);
}

void Signer::list(double now, bool ack) {
  ++counter_;
  if (unsealed_++ == 0) {
    oldest_ = now;
    seal_.first = counter_;
    seal_.digests.clear();
  }
  if (ack && oldest_ack_ < 0.0) oldest_ack_ = now;
  const Digest d = digest_of(buf_.data(), buf_.size());
  seal_.digests.insert(seal_.digests.end(), d.begin(), d.end());
}

bool Signer::due(double now) const noexcept {
  if (unsealed_ == 0) return false;
  return unsealed_ >= kSealEvery || now - oldest_ >= kSealWithin || (oldest_ack_ >= 0.0 && now - oldest_ack_ >= ack_within_);
}

void Signer::sign(cpm_msgs::seal_t& s, std::vector<std::uint8_t>& out) const {
  for (auto& b : s.signature) b = 0;
  out.resize(static_cast<std::size_t>(s.getEncodedSize()));
  s.encode(out.data(), 0, static_cast<int>(out.size()));
  crypto_sign_detached(s.signature, nullptr, out.data(), out.size(), secret_.data());
  // The signature is the encoding's last 64 bytes.
  std::copy(std::begin(s.signature), std::end(s.signature), out.end() - kSignatureBytes);
}

const std::vector<std::uint8_t>& Signer::seal(std::int64_t utime) {
  sealed_.clear();
  if (unsealed_ == 0) return sealed_;
  seal_.utime = utime;
  seal_.boot_id = boot_;
  seal_.digest_bytes = static_cast<std::int32_t>(seal_.digests.size());
  if (thread_.joinable()) {
    const std::uint64_t n = handed_.load(std::memory_order_relaxed);
    if (n - signed_.load(std::memory_order_acquire) < kHandoffSlots) {
      cpm_msgs::seal_t& slot = slots_[n % kHandoffSlots];
      slot.utime = seal_.utime;
      slot.boot_id = seal_.boot_id;
      slot.first = seal_.first;
      slot.digest_bytes = seal_.digest_bytes;
      slot.digests.swap(seal_.digests);  // the slot's emptied vector comes back: no allocation
      handed_.store(n + 1, std::memory_order_release);
      wake_.fetch_add(1, std::memory_order_release);
      wake_.notify_one();
      unsealed_ = 0;
      oldest_ack_ = -1.0;
      return sealed_;
    }
    // The sealing thread is kHandoffSlots seals behind: keep listing, seal
    // here only when one more would not fit a seal (a client then refuses
    // the seals still queued as older than this one: fail closed).
    if (unsealed_ < kMostDigests) return sealed_;
    ++sealed_here_;
  }
  sign(seal_, sealed_);
  unsealed_ = 0;
  oldest_ack_ = -1.0;
  return sealed_;
}

void Signer::start_thread(Publish publish) {
  if (thread_.joinable()) return;
  publish_ = std::move(publish);
  quit_.store(false);
  ack_within_ = 0.0;
  thread_ = std::thread([this] { run_thread(); });
}

void Signer::stop_thread() {
  if (!thread_.joinable()) return;
  quit_.store(true, std::memory_order_release);
  wake_.fetch_add(1, std::memory_order_release);
  wake_.notify_one();
  thread_.join();
  ack_within_ = kSealAckWithin;
}

void Signer::run_thread() {
  std::vector<std::uint8_t> out;
  out.reserve(kSealEvery * sizeof(Digest) + 256);
  for (;;) {
    const std::uint32_t w = wake_.load(std::memory_order_acquire);
    // Read before the seals: stop_thread() comes after the last hand-off.
    const bool quitting = quit_.load(std::memory_order_acquire);
    std::uint64_t n = signed_.load(std::memory_order_relaxed);
    while (n != handed_.load(std::memory_order_acquire)) {
      cpm_msgs::seal_t& slot = slots_[n % kHandoffSlots];
      sign(slot, out);
      slot.digests.clear();
      signed_.store(++n, std::memory_order_release);  // the slot is the publisher's again
      publish_(out.data(), out.size());
    }
    if (quitting) return;
    wake_.wait(w, std::memory_order_acquire);
  }
}

bool signature_valid_bytes(const std::uint8_t* data, std::size_t size, const std::uint8_t (&sig)[kSignatureBytes],
                           const PublicKey& pk) {
  static const bool ready = sodium_init() >= 0;
  return ready && crypto_sign_verify_detached(sig, data, size, pk.data()) == 0;
}

bool seal_valid(const cpm_msgs::seal_t& s, const PublicKey& pk) {
  cpm_msgs::seal_t z = s;
  for (auto& b : z.signature) b = 0;
  std::vector<std::uint8_t> buf(static_cast<std::size_t>(z.getEncodedSize()));
  z.encode(buf.data(), 0, static_cast<int>(buf.size()));
  return signature_valid_bytes(buf.data(), buf.size(), s.signature, pk);
}

std::optional<cpm_msgs::seal_t> decode_seal(const void* data, std::size_t size) {
  // hash, utime, boot_id, first (8 each), digest_bytes (4), digests, signature (64).
  constexpr std::size_t kFixed = 8 * 4 + 4 + kSignatureBytes, kMaxDigests = 1024;
  if (size < kFixed || size > kFixed + kMaxDigests * sizeof(Digest)) return std::nullopt;
  const auto* p = static_cast<const std::uint8_t*>(data) + 32;
  const std::uint32_t n = (std::uint32_t{p[0]} << 24) | (std::uint32_t{p[1]} << 16) | (std::uint32_t{p[2]} << 8) | p[3];
  if (n == 0 || n % sizeof(Digest) != 0 || n != size - kFixed) return std::nullopt;
  cpm_msgs::seal_t s;
  if (s.decode(data, 0, static_cast<int>(size)) != static_cast<int>(size)) return std::nullopt;
  return s;
}

Trust Verifier::take(Stream s, std::int64_t counter) noexcept {
  auto& last = last_[static_cast<int>(s)];
  if (counter <= last) return count(Trust::stale);
  last = counter;
  return Trust::ok;
}

Trust Verifier::offer(Stream s, const void* data, std::size_t size, std::uint64_t ticket) {
  const Digest d = digest_of(data, size);
  // Listed by a seal that came first (LCM does not order across channels).
  for (const Recent& r : recent_)
    for (std::size_t i = 0; i < r.digests.size(); ++i)
      if (r.digests[i] == d) return take(s, r.first + static_cast<std::int64_t>(i));
  if (waiting_.size() >= kMaxWaiting) {
    waiting_.erase(waiting_.begin());
    count(Trust::unsealed);
  }
  waiting_[ticket] = Waiting{d, s, seals_};
  return Trust::pending;
}

Trust Verifier::seal(const void* data, std::size_t size, std::vector<Verdict>& decided) {
  const auto s = decode_seal(data, size);
  if (!s) return count(Trust::unsigned_message);
  if (!seal_valid(*s, pk_)) return count(Trust::bad_signature);
  if (boot_ == 0) boot_ = s->boot_id;
  if (s->boot_id != boot_) return count(Trust::other_boot);
  if (s->first <= last_sealed_) return count(Trust::stale);
  Recent r{s->first, std::vector<Digest>(s->digests.size() / sizeof(Digest))};
  for (std::size_t i = 0; i < r.digests.size(); ++i)
    std::copy_n(s->digests.begin() + static_cast<std::ptrdiff_t>(i * sizeof(Digest)), sizeof(Digest),
                r.digests[i].begin());
  last_sealed_ = s->first + static_cast<std::int64_t>(r.digests.size()) - 1;
  ++seals_;
  // The waiting messages it lists, in the order cpmd published them.
  for (std::size_t i = 0; i < r.digests.size(); ++i)
    for (auto it = waiting_.begin(); it != waiting_.end(); ++it)
      if (it->second.digest == r.digests[i]) {
        decided.push_back({it->first, it->second.stream, take(it->second.stream, r.first + static_cast<std::int64_t>(i))});
        waiting_.erase(it);
        break;
      }
  // Those that waited through kSealsToWait seals without being listed never will be.
  for (auto it = waiting_.begin(); it != waiting_.end();)
    if (seals_ - it->second.seals_then >= kSealsToWait) {
      decided.push_back({it->first, it->second.stream, count(Trust::unsealed)});
      it = waiting_.erase(it);
    } else {
      ++it;
    }
  recent_.push_back(std::move(r));
  if (recent_.size() > 4) recent_.erase(recent_.begin());
  return Trust::ok;
}

const char* trust_text(Trust t) noexcept {
  switch (t) {
    case Trust::ok: return "verified";
    case Trust::unsigned_message: return "unsigned (this cpmd does not sign, or the message is forged): cannot be verified";
    case Trust::bad_signature: return "its signature does not verify (forged, or signed by another key)";
    case Trust::stale: return "not newer than the last verified one (replayed or reordered)";
    case Trust::other_boot: return "from another start of cpmd than the one this client began with (cpmd restarted)";
    case Trust::unsealed:
      return "no seal signed by cpmd lists it (forged, tampered, or its seal was lost on the way)";
    case Trust::pending: return "waiting for the seal that lists it";
  }
  return "?";
}

std::int64_t Verifier::refused_total() const noexcept {
  std::int64_t n = 0;
  for (auto v : refused_) n += v;
  return n;
}

}  // namespace cpm::daemon
