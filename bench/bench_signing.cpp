// SPDX-License-Identifier: Apache-2.0
// Signed state (docs/security.md, "Signed state"): what cpmd's publishing
// thread pays per message it seals, and what a client pays to check one.
// Beside the cycle's cost (bench_daemon.cpp): sealing is not in the cycle.
#include <benchmark/benchmark.h>

#include <thread>

#include <cpm_msgs/ack_t.hpp>
#include <cpm_msgs/state_t.hpp>

#include "cpm/daemon/signing.hpp"

namespace {

using namespace cpm::daemon;

cpm_msgs::state_t some_state() {
  cpm_msgs::state_t s{};
  s.cycle = 12345;
  s.mode = cpm_msgs::state_t::MODE_MOVING;
  for (int i = 0; i < 3; ++i) s.position[i] = 0.4 + 0.01 * i;
  s.boot_id = 0x0B0071D;
  return s;
}

// The 1 kHz state stream as cpmd publishes it: each state encoded and its
// digest listed; a seal signed whenever one is due (10 ms of states, so one
// signature per 10 states). One iteration = one published state; the
// seals' cost is inside.
void BM_SealStateStream(benchmark::State& st) {
  Signer signer(generate_key(), 0x0B0071D);
  cpm_msgs::state_t s = some_state();
  double now = 0.0;
  std::int64_t seals = 0;
  for (auto _ : st) {
    ++s.cycle;
    now += 0.001;
    benchmark::DoNotOptimize(signer.add(s, now).data());
    if (signer.due(now)) {
      benchmark::DoNotOptimize(signer.seal(1).data());
      ++seals;
    }
  }
  st.counters["bytes"] = s.getEncodedSize();
  st.counters["messages_per_seal"] = static_cast<double>(st.iterations()) / static_cast<double>(std::max<std::int64_t>(seals, 1));
}
BENCHMARK(BM_SealStateStream);

// The worst case: an ack alone in its seal (a quiet machine answering a
// command: digest, one signature, the seal's encoding).
void BM_SealAckAlone(benchmark::State& st) {
  Signer signer(generate_key(), 0x0B0071D);
  cpm_msgs::ack_t a{};
  a.message = "move: target (600.0, 425.0, 300.0) mm is outside the workspace";
  for (auto _ : st) {
    ++a.id;
    benchmark::DoNotOptimize(signer.add(a, 0.0, true).data());
    benchmark::DoNotOptimize(signer.seal(1).data());
  }
}
BENCHMARK(BM_SealAckAlone);

// Hand the seal to the sealing thread (timed: what the publisher pays), then
// wait, untimed, until it has signed, so the next iteration starts alike.
void seal_and_wait_untimed(Signer& signer, benchmark::State& st) {
  benchmark::DoNotOptimize(signer.seal(1).data());
  st.PauseTiming();
  while (signer.seals_waiting() > 0) std::this_thread::yield();
  st.ResumeTiming();
}

void stop_and_count(Signer& signer, benchmark::State& st, std::int64_t seals) {
  signer.stop_thread();
  st.counters["messages_per_seal"] = static_cast<double>(st.iterations()) / static_cast<double>(std::max<std::int64_t>(seals, 1));
}

// The same with the signature on the sealing thread (Signer::start_thread,
// as cpmd runs): the CPU time is the publishing thread's own (the digests,
// the hand-off); the seal's signature is the sealing thread's. Each seal is
// awaited outside the timing, as at 1 kHz the sealing thread is idle long
// before the next one.
void BM_SealStateStreamOffThread(benchmark::State& st) {
  Signer signer(generate_key(), 0x0B0071D);
  std::int64_t seals = 0;
  signer.start_thread([&seals](const std::uint8_t*, std::size_t) { ++seals; });
  cpm_msgs::state_t s = some_state();
  double now = 0.0;
  for (auto _ : st) {
    ++s.cycle;
    now += 0.001;
    benchmark::DoNotOptimize(signer.add(s, now).data());
    if (signer.due(now)) seal_and_wait_untimed(signer, st);
  }
  stop_and_count(signer, st, seals);
}
BENCHMARK(BM_SealStateStreamOffThread);

// An ack alone in its seal, signed on the sealing thread: what the
// publishing thread pays (its digest, the hand-off and the wake-up).
void BM_SealAckAloneOffThread(benchmark::State& st) {
  Signer signer(generate_key(), 0x0B0071D);
  std::int64_t seals = 0;
  signer.start_thread([&seals](const std::uint8_t*, std::size_t) { ++seals; });
  cpm_msgs::ack_t a{};
  a.message = "move: target (600.0, 425.0, 300.0) mm is outside the workspace";
  for (auto _ : st) {
    ++a.id;
    benchmark::DoNotOptimize(signer.add(a, 0.0, true).data());
    if (!signer.due(0.0)) st.SkipWithError("an ack alone is due at once with a sealing thread");
    seal_and_wait_untimed(signer, st);
  }
  stop_and_count(signer, st, seals);
}
BENCHMARK(BM_SealAckAloneOffThread);

// What a client pays per state of the 1 kHz stream: the digest of each, one
// signature verified per seal of 10.
void BM_VerifyStateStream(benchmark::State& st) {
  const Key seed = generate_key();
  Signer signer(seed, 0x0B0071D);
  cpm_msgs::state_t s = some_state();
  std::vector<std::vector<std::uint8_t>> states;
  for (int i = 0; i < 10; ++i) {
    ++s.cycle;
    states.push_back(signer.add(s, 0.0));
  }
  const std::vector<std::uint8_t> seal = signer.seal(1);
  std::vector<Verifier::Verdict> decided;
  for (auto _ : st) {
    st.PauseTiming();
    Verifier v(public_key_of(seed));
    decided.clear();
    st.ResumeTiming();
    std::uint64_t ticket = 0;
    for (const auto& b : states) benchmark::DoNotOptimize(v.offer(Stream::state, b.data(), b.size(), ++ticket));
    benchmark::DoNotOptimize(v.seal(seal.data(), seal.size(), decided));
  }
  st.SetItemsProcessed(st.iterations() * 10);  // items/s: states verified per second
}
BENCHMARK(BM_VerifyStateStream);

}  // namespace
