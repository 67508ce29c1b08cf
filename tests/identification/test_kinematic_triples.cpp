// SPDX-License-Identifier: Apache-2.0
// Three kinematic effects planted at once (the issue's "two and three
// effects at once", kinematic side; pairs are the kinematic cells): every
// triple of the pool but actuator_scale (which only a nominal-only machine
// can show, test_kinematic_cells.cpp), each on an axis the seed draws, at 10x
// its 1x on that axis (kin_amplitudes), on the two conditions that can show
// every one of them (two bar radii and positions, both directions). Each set
// is diagnosed from the nominal model and every planted effect must be named;
// then the loop (cpm loop) runs from the nominal model and must end within 20 %
// of the noise floor, its waterfall printed.
#include <gtest/gtest.h>

#include <iostream>
#include <random>

#include "cpm/identification/model_loop.hpp"
#include "identification/kin_cells.hpp"

namespace cpm::test {
namespace {

struct Triple {
  std::size_t a, b, c;
};

std::vector<Triple> triples_without_scale() {
  std::vector<std::size_t> pool;
  for (std::size_t k = 0; k < kin_pool().size(); ++k)
    if (std::string(kin_pool()[k].name) != "actuator_scale") pool.push_back(k);
  std::vector<Triple> v;
  for (std::size_t i = 0; i < pool.size(); ++i)
    for (std::size_t j = i + 1; j < pool.size(); ++j)
      for (std::size_t k = j + 1; k < pool.size(); ++k) v.push_back({pool[i], pool[j], pool[k]});
  return v;
}

std::vector<PlantedKinematic> planted_triple(const KinCell& cell, const Triple& t, std::mt19937_64& rng) {
  const KinAmplitudes& amp = kin_amplitudes(cell, false);
  std::vector<PlantedKinematic> planted;
  for (const std::size_t k : {t.a, t.b, t.c}) {
    const auto axis = static_cast<std::size_t>(rng() % 3);
    const KinPoolEffect& e = kin_pool()[k];
    planted.push_back({e.name, static_cast<int>(axis), {amp.planted[k][axis], e.shape[1], e.shape[2]}});
  }
  return planted;
}

std::string waterfall(const ident::LoopResult& R) {
  std::string s;
  for (const auto& step : R.steps)
    s += (s.empty() ? "" : " -> ") + (step.added.empty() ? std::string() : "+" + step.added + " ") +
         std::to_string(step.rms * 1e6).substr(0, 5) + " um";
  return s + " (floor " + std::to_string(R.steps.back().noise_floor * 1e6).substr(0, 5) + " um)";
}

TEST(KinematicTriples, AllThreeNamedAndTheLoopEndsAtTheNoiseFloor) {
  const std::vector<KinCell> cells = {{false, {0.100, 0.150}, false}, {true, {0.100, 0.150}, false}};
  constexpr int kSeeds = 2;
  int sets = 0, all_named = 0, within = 0, phantoms = 0, named = 0;
  for (const KinCell& cell : cells)
    for (int seed = 1; seed <= kSeeds; ++seed) {
      std::mt19937_64 rng(static_cast<std::uint64_t>(seed) * 7919ULL);
      for (const Triple& t : triples_without_scale()) {
        const KinSet set{-1, false, planted_triple(cell, t, rng), static_cast<std::uint64_t>(seed) * 100000ULL + sets};
        const KinSetResult r = run_kin_set(cell, set);
        const ident::LoopResult L =
            ident::run_loop(kin_data(cell, false, set.planted, set.seed), ctl::MachineModel::elkady());
        const double over = L.steps.back().rms / L.steps.back().noise_floor;
        ++sets;
        all_named += r.missed.empty() ? 1 : 0;
        within += over <= 1.2 ? 1 : 0;
        phantoms += static_cast<int>(r.phantoms.size());
        named += r.named;
        std::cout << cell.text() << " seed " << seed << ": planted";
        for (const auto& p : r.planted) std::cout << " " << p;
        std::cout << "; named " << r.named_text << "; loop " << waterfall(L) << "\n";
        EXPECT_TRUE(r.missed.empty()) << cell.text() << ": missed " << r.missed.front() << "; named " << r.named_text;
        EXPECT_LE(over, 1.2) << cell.text() << ": " << waterfall(L) << "; stop: " << L.stop;
      }
    }
  std::cout << "triples: all named " << all_named << "/" << sets << ", loop within 20 % of the floor " << within
            << "/" << sets << ", phantoms " << phantoms << "/" << named << " named\n";
  EXPECT_LE(phantoms * 50, named) << "more than 1 in 50 named effects were not planted";
}

}  // namespace
}  // namespace cpm::test
