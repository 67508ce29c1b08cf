// The combinations the robustness matrix plants at once: distinct effects,
// none of the pairs that motion data cannot separate (kInseparable in
// matrix.cpp), and every size asked for has some.
#include <gtest/gtest.h>

#include <string>

#include "matrix.hpp"

namespace cpm::indep {
namespace {

int index_of(const std::string& name) {
  const auto& lib = dynamic_library();
  for (std::size_t i = 0; i < lib.size(); ++i)
    if (lib[i].name == name) return static_cast<int>(i);
  ADD_FAILURE() << name << " is not in dynamic_library()";
  return -1;
}

EffectOnAxis on(const std::string& name, int axis = -1) { return {index_of(name), axis}; }

TEST(Combinations, PairsTheDocumentationCallsInseparableAreNeverPlantedTogether) {
  EXPECT_FALSE(separable({on("payload_mass"), on("inertia_error")}));
  EXPECT_FALSE(separable({on("payload_mass"), on("force_gain", 2)}));
  EXPECT_TRUE(separable({on("payload_mass"), on("force_gain", 0)}));  // only z carries the weight
  for (int axis = 0; axis < 3; ++axis) EXPECT_FALSE(separable({on("inertia_error"), on("force_gain", axis)}));
  const char* friction[] = {"viscous_friction", "coulomb_friction", "stribeck_friction"};
  for (const char* a : friction)
    for (const char* b : friction) {
      if (std::string(a) == b) continue;
      EXPECT_FALSE(separable({on(a, 1), on(b, 1)})) << a << " with " << b << " on one axis";
      EXPECT_TRUE(separable({on(a, 1), on(b, 2)})) << a << " with " << b << " on two axes";
    }
  EXPECT_FALSE(separable({on("spring", 0), on("cogging", 0)}));
  EXPECT_TRUE(separable({on("spring", 0), on("cogging", 2)}));
  EXPECT_FALSE(separable({on("viscous_friction", 0), on("viscous_friction", 1)}));  // the same effect twice
}

TEST(Combinations, EverySizeHasSeparableCombinationsAndEachIsSeparable) {
  std::vector<int> pool;
  for (std::size_t i = 0; i < dynamic_library().size(); ++i) pool.push_back(static_cast<int>(i));
  for (int n : {2, 3}) {
    const auto all = separable_combinations(pool, n);
    EXPECT_GT(all.size(), 100u) << n;
    for (const auto& set : all) {
      ASSERT_EQ(static_cast<int>(set.size()), n);
      EXPECT_TRUE(separable(set));
    }
  }
  // Three frictions at once: one per axis, in the 3! ways of placing them.
  const std::vector<int> frictions = {index_of("viscous_friction"), index_of("coulomb_friction"),
                                      index_of("stribeck_friction")};
  EXPECT_EQ(separable_combinations(frictions, 3).size(), 6u);
}

}  // namespace
}  // namespace cpm::indep
