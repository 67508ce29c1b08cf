// Signed state (docs/security.md, "Signed state"): what cpmd's publishing
// thread pays per state or ack it signs, and what a client pays to check one.
// Beside the cycle's cost (bench_daemon.cpp): signing is not in the cycle.
#include <benchmark/benchmark.h>

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

void BM_SignState(benchmark::State& st) {
  Signer signer(generate_key());
  cpm_msgs::state_t s = some_state();
  for (auto _ : st) {
    ++s.cycle;
    signer.sign(s);
    benchmark::DoNotOptimize(s.signature[0]);
  }
  st.counters["bytes"] = s.getEncodedSize();
}
BENCHMARK(BM_SignState);

void BM_SignAck(benchmark::State& st) {
  Signer signer(generate_key());
  cpm_msgs::ack_t a{};
  a.message = "move: target (600.0, 425.0, 300.0) mm is outside the workspace";
  for (auto _ : st) {
    ++a.id;
    signer.sign(a);
    benchmark::DoNotOptimize(a.signature[0]);
  }
}
BENCHMARK(BM_SignAck);

void BM_VerifyState(benchmark::State& st) {
  const Key seed = generate_key();
  Signer signer(seed);
  cpm_msgs::state_t s = some_state();
  signer.sign(s);
  const PublicKey pk = public_key_of(seed);
  for (auto _ : st) benchmark::DoNotOptimize(signature_valid(s, pk));
}
BENCHMARK(BM_VerifyState);

}  // namespace
