// SPDX-License-Identifier: Apache-2.0
// The kinematic cells of the robustness matrix (kin_cells.hpp): two kinematic
// effects at once, one and two bar radii, one and both directions, ball-bar
// and position data, null sets in every condition; each cell (a pair in a
// condition) judged over seeds by the thresholds. The table is
// printed (markdown, as in docs/identification.md, robustness matrix: "Two
// effects at once on kinematic data").
#include <gtest/gtest.h>

#include <cstdio>

#include "identification/kin_cells.hpp"

namespace cpm::test {
namespace {

constexpr int kSeeds = 5, kNullsPerSeed = 4;

// {ball-bar 150 mm, ball-bar 100 + 150 mm, positions on both} x {both directions, one}.
const std::vector<KinCell>& conditions() {
  static const std::vector<KinCell> c = {
      {false, {0.150}, false},       {false, {0.150}, true},        {false, {0.100, 0.150}, false},
      {false, {0.100, 0.150}, true}, {true, {0.100, 0.150}, false}, {true, {0.100, 0.150}, true},
  };
  return c;
}

// The conditions are run once per process, whichever test asks first.
const std::vector<KinColumn>& columns() {
  static const std::vector<KinColumn> r = [] {
    std::vector<KinColumn> v;
    for (const KinCell& c : conditions()) v.push_back(run_kin_column(c, kSeeds, kNullsPerSeed));
    return v;
  }();
  return r;
}

std::string misses_of(const KinTally& t) {
  std::string s;
  for (const auto& m : t.misses) s += "\n  " + m;
  return s;
}

// Cells the estimator fails today (docs/identification.md, "Two effects at
// once on kinematic data"), measured on these seeds: their assertions stay,
// skipped with the reason while they fail. Empty: judged like every other.
std::string known_failure(const KinCell& cell, const KinPair& pair) {
  if (!cell.position || !pair.has("actuator_scale")) return "";
  if (cell.one_direction && pair.has("backlash"))
    return "position data are in the machine frame: a backlash approached from one side is a constant shift of its "
           "axis, i.e. a plane offset, which only the full calibration explains; the scales at the model as given "
           "leave it, so the model needs calibrating and no scale is named (on ball-bar data the pivot, a set-up, "
           "takes the shift and the scale is named)";
  if (pair.has("guide_angular_error"))
    return "a guide error and a scale on the same axis (signatures 98.7-98.9 % alike on positions) leave the scale "
           "only the rest of its signature: its standard error grows 9-15 fold, and its 10x (measured alone) is "
           "then 2.7-4.5 of them (the one set of five with both on axis 3: s = 2.0e-5 +- 6.9e-6 for 3.1e-5 planted, "
           "p after the Bonferroni correction 0.06; over 20 seeds named in 2 of the 6 sets with both on one axis)";
  return "";
}

void print_table() {
  double seconds = 0.0;
  for (const KinColumn& c : columns()) {
    seconds += c.seconds;
    std::printf("%s: %.1f s\n", c.cell.text().c_str(), c.seconds);
    for (const KinTally& t : c.pairs) std::printf("%s", misses_of(t).c_str());
    std::printf("%s\n", misses_of(c.nulls).c_str());
  }
  std::printf("\nplanted sizes (multiple of 1x):\n%s", kin_amplitudes_markdown(conditions()).c_str());
  std::printf("\n%s† backlash approached from one side: not named, and its candidate says \"both directions\"\n",
              kin_cells_markdown(columns()).c_str());
  std::printf("%d seeds, %d null sets per seed and condition; %.1f s in all\n", kSeeds, kNullsPerSeed, seconds);
}

// Every pair planted in every condition on every seed; backlash is not
// showable exactly where it is approached from one side; then the issue's
// thresholds in every cell but the known failures, and in the null sets.
TEST(KinematicCells, TwoEffectsAtOnceOneAndTwoRadiiOneAndBothDirections) {
  print_table();
  for (const KinColumn& c : columns()) {
    for (std::size_t p = 0; p < kin_pairs().size(); ++p) {
      const KinPair& pair = kin_pairs()[p];
      const KinTally& t = c.pairs[p];
      EXPECT_EQ(t.sets, kSeeds);
      EXPECT_EQ(t.planted + t.hidden, 2 * kSeeds);
      EXPECT_EQ(t.hidden > 0, c.cell.one_direction && pair.has("backlash")) << pair.text();
      if (!known_failure(c.cell, pair).empty()) continue;  // KnownFailingPairs
      std::string why;
      for (const auto& w : kin_pair_failures(t)) why += w + "; ";
      EXPECT_TRUE(why.empty()) << c.cell.text() << ", " << pair.text() << ": " << why << misses_of(t);
    }
    EXPECT_TRUE(kin_null_failures(c.nulls).empty()) << c.cell.text() << misses_of(c.nulls);
  }
}

TEST(KinematicCells, KnownFailingPairs) {
  std::string why;
  for (const KinColumn& c : columns())
    for (std::size_t p = 0; p < kin_pairs().size(); ++p) {
      const std::string reason = known_failure(c.cell, kin_pairs()[p]);
      if (reason.empty()) continue;
      for (const auto& w : kin_pair_failures(c.pairs[p]))
        why += c.cell.text() + ", " + kin_pairs()[p].text() + ": " + w + " (" + reason + ")\n";
    }
  if (!why.empty()) GTEST_SKIP() << why;
  for (const KinColumn& c : columns())
    for (std::size_t p = 0; p < kin_pairs().size(); ++p)
      EXPECT_TRUE(kin_pair_failures(c.pairs[p]).empty())
          << c.cell.text() << ", " << kin_pairs()[p].text() << misses_of(c.pairs[p]);
}

}  // namespace
}  // namespace cpm::test
