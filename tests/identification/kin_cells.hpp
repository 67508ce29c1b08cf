// SPDX-License-Identifier: Apache-2.0
// The kinematic cells of the robustness matrix: every pair of kinematic
// effects planted at once, on axes the seed picks, in each data condition:
// ball-bar lengths with one bar radius (150 mm) and with two (100 and 150
// mm), full positions, each approached from both directions and from one;
// null sets (nothing planted) in every condition. Each set is diagnosed with
// ident::diagnose_kinematic from the nominal model and scored:
//   - a planted effect the condition's data can show must be named (as itself
//     or as the alternative of an ambiguous verdict);
//   - one they cannot show (kin_hidden_advice: backlash approached from one
//     side only is a constant shift, which the pivot error or the plane offset
//     takes) must NOT be named, and its candidate must say which measurement
//     would show it;
//   - anything else named is a phantom.
// A cell is one pair in one condition (or the null sets of a condition),
// judged over the seeds by the thresholds: planted named >= 95 %,
// not-showable handled right >= 95 %, null sets "none" >= 95 %, phantoms
// <= 1 in 50 named.
#pragma once

#include <array>
#include <cstdint>
#include <string>
#include <vector>

#include "identification/kin_data.hpp"

namespace cpm::test {

// A data condition (a column of the table).
struct KinCell {
  bool position = false;             // full positions (2 µm gaussian) instead of ball-bar lengths (±0.5 µm)
  std::vector<double> radii{0.150};  // bar radii; for positions the hemispheres the poses lie on
  bool one_direction = false;        // every pose approached from the + side on every axis
  [[nodiscard]] std::string text() const;  // "ball-bar 150 mm, both directions"
  [[nodiscard]] std::vector<Vec3> poses(std::uint64_t seed) const;
  [[nodiscard]] KinSimOptions options(std::uint64_t seed, bool nominal_planes) const;
};

// An effect of the pool: its shape (the amplitude, index 0, is set per
// condition and axis), the probe amplitude that measures its 1x, and a
// physically plausible ceiling.
struct KinPoolEffect {
  const char* name;
  std::array<double, 3> shape;  // parameters with the amplitude 1 (lambda, phi; tau)
  double probe_ballbar, probe_position;
  double ceiling;               // the largest amplitude planted
};
// backlash, cyclic_error, guide_angular_error, limb_twist, thermal_drift, actuator_scale.
const std::vector<KinPoolEffect>& kin_pool();

// A pair of pool effects (a row of the table). actuator_scale is nameable
// only where the model is nominal-only and the machine needs no other
// calibration (docs/effects.md; docs "Kinematic side"): a pair with it is planted
// on a machine whose planes are nominal, every other pair on Kim's machine.
struct KinPair {
  std::size_t a = 0, b = 0;  // indices in kin_pool()
  [[nodiscard]] bool nominal_planes() const;
  [[nodiscard]] bool has(const std::string& effect) const;
  [[nodiscard]] std::string text() const;  // "backlash + cyclic_error"
};
const std::vector<KinPair>& kin_pairs();  // every pair of distinct pool effects

// The planted size: 10x the effect's 1x on that axis, in the condition's pose
// set and noise on that machine (1x = 4 standard errors of the amplitude when
// planted alone at the probe size, both directions: test_kinematic.cpp's
// unit), at most the ceiling. Measured once per pose set and machine, on a
// seed of its own.
constexpr double kKinMultiple = 10.0;
struct KinAmplitudes {
  std::vector<std::array<double, 3>> unit, planted;  // per pool effect, per axis
};
const KinAmplitudes& kin_amplitudes(const KinCell& cell, bool nominal_planes);

struct KinSet {
  int pair = -1;                          // index in kin_pairs(), -1: a null set
  bool nominal_planes = false;
  std::vector<PlantedKinematic> planted;  // empty: a null set
  std::uint64_t seed = 1;                 // noise and pose order
};
// One seed's sets for a condition: every pair, each effect on an axis drawn
// from the seed (the two axes may coincide), then `nulls` null sets,
// alternately on Kim's machine and on nominal planes.
std::vector<KinSet> kin_sets(const KinCell& cell, int seed, int nulls);

// The measurement the diagnosis must name for a planted effect that this
// condition's data cannot show; "" when they can show it.
std::string kin_hidden_advice(const KinCell& cell, const std::string& effect);

struct KinSetResult {
  std::vector<std::string> planted, hidden;  // labels: showable / not showable here
  std::vector<std::string> missed, hidden_named, unadvised, phantoms;
  int named = 0;                             // effects the diagnosis named
  std::string named_text;                    // "backlash[axis 1] cyclic_error[axis 2]"
};
KinSetResult run_kin_set(const KinCell& cell, const KinSet& set);
// The condition's data (ball-bar lengths or positions) with `planted` on its
// machine (nominal planes or Kim's), noise and pose order from `seed`.
io::DataSet kin_data(const KinCell& cell, bool nominal_planes, const std::vector<PlantedKinematic>& planted,
                     std::uint64_t seed);

// One cell's counts over the seeds.
struct KinTally {
  int sets = 0, clean = 0;             // clean: nothing named (what a null set must be)
  int planted = 0, planted_named = 0;  // showable planted effects, and how many were named
  int hidden = 0, hidden_right = 0;    // not showable: not named and the measurement said
  int named = 0, phantoms = 0;
  std::vector<std::string> misses;     // one line per set that missed, phantomed or named a hidden effect
};
struct KinColumn {
  KinCell cell;
  std::vector<KinTally> pairs;  // per kin_pairs()
  KinTally nulls;
  double seconds = 0.0;
};
KinColumn run_kin_column(const KinCell& cell, int seeds, int nulls_per_seed);

// The thresholds, one line per threshold a cell fails, saying how.
std::vector<std::string> kin_pair_failures(const KinTally& t, double phantom_rate = 1.0 / 50.0);
std::vector<std::string> kin_null_failures(const KinTally& t);
// Rows: the pairs, then the null sets; columns: the conditions.
std::string kin_cells_markdown(const std::vector<KinColumn>& columns);
// The sizes planted: pose set, machine, effect, axis 1..3 (multiple of 1x).
std::string kin_amplitudes_markdown(const std::vector<KinCell>& cells);

}  // namespace cpm::test
