// SPDX-License-Identifier: Apache-2.0
#include "identification/kin_cells.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <map>
#include <memory>
#include <random>
#include <sstream>

#include "cpm/identification/kinematic.hpp"
#include "matrix.hpp"

namespace cpm::test {

io::DataSet kin_data(const KinCell& cell, bool nominal_planes, const std::vector<PlantedKinematic>& planted,
                     std::uint64_t seed) {
  const std::vector<Vec3> poses = cell.poses(seed);
  const KinSimOptions so = cell.options(seed, nominal_planes);
  return cell.position ? io::DataSet(kim_positions(planted, poses, so)) : io::DataSet(kim_ballbar(planted, poses, so));
}

namespace {

// Readings per set: ball-bar 6 rings x 16 azimuths per radius (docs: 192
// lengths on two hemispheres), positions 5 x 12 (120 poses on two).
constexpr int kBarRings = 6, kBarPerRing = 16, kPosRings = 5, kPosPerRing = 12;
constexpr double kBarNoise = 0.5e-6, kPosNoise = 2e-6;
constexpr const char* kScale = "actuator_scale";
constexpr std::uint64_t kProbeSeed = 99;  // the 1x probes' noise and pose order, apart from the sets' seeds

std::string joined(const std::vector<std::string>& v, const char* sep = ", ") {
  std::string s;
  for (const auto& x : v) {
    if (!s.empty()) s += sep;
    s += x;
  }
  return s;
}

std::string radii_text(const KinCell& c) {
  std::vector<std::string> mm;
  for (double r : c.radii) mm.push_back(std::to_string(static_cast<int>(std::lround(r * 1e3))));
  return (c.position ? "positions " : "ball-bar ") + joined(mm, " + ") + " mm";
}

std::string machine_text(bool nominal_planes) { return nominal_planes ? "nominal planes" : "Kim's planes"; }

// The condition's data with `planted` on its machine, diagnosed from the nominal model.
ident::Diagnosis diagnose_set(const KinCell& cell, bool nominal_planes, const std::vector<PlantedKinematic>& planted,
                              std::uint64_t seed) {
  const io::DataSet ds = kin_data(cell, nominal_planes, planted, seed);
  return ident::diagnose_kinematic(std::make_shared<const ident::KinematicProblem>(
      ident::prepare_kinematic(ds, ctl::MachineModel::elkady().kinematics)));
}

std::array<double, 3> sized(const KinPoolEffect& e, double amplitude) {
  std::array<double, 3> v = e.shape;
  v[0] = amplitude;
  return v;
}

// 4 standard errors of the effect's amplitude planted alone at its probe size (0: no estimate).
double unit_of(const KinCell& both, bool nominal_planes, const KinPoolEffect& e, int axis) {
  const double probe = both.position ? e.probe_position : e.probe_ballbar;
  const ident::Diagnosis D = diagnose_set(both, nominal_planes, {{e.name, axis, sized(e, probe)}}, kProbeSeed);
  for (const auto& c : D.candidates)
    if (c.effect == e.name && c.axis == axis && !c.params.empty()) return 4.0 * std::max(0.0, c.params[0].std_error);
  return 0.0;
}

bool any_names(const std::vector<indep::NamedEffect>& named, const std::string& label) {
  return std::any_of(named.begin(), named.end(),
                     [&](const indep::NamedEffect& n) { return indep::names_planted(n, label); });
}

// The candidate of `label` says which measurement would show it: in its note
// or as how to separate it from what it is confounded with.
bool advised(const ident::Diagnosis& D, const std::string& label, const std::string& advice) {
  for (const auto& c : D.candidates) {
    if (c.label() != label) continue;
    if (c.note.find(advice) != std::string::npos) return true;
    for (const auto& cf : c.confounded)
      if (cf.separate_by.find(advice) != std::string::npos) return true;
  }
  return false;
}

KinSetResult score(const KinCell& cell, const KinSet& set, const ident::Diagnosis& D) {
  KinSetResult r;
  std::vector<std::string> all;
  for (const auto& p : set.planted) {
    all.push_back(indep::effect_label(p.effect, p.axis));
    const std::string advice = kin_hidden_advice(cell, p.effect);
    (advice.empty() ? r.planted : r.hidden).push_back(all.back());
  }
  const std::vector<indep::NamedEffect> named = indep::named_effects(D);
  r.named = static_cast<int>(named.size());
  std::vector<std::string> labels;
  for (const auto& n : named) labels.push_back(n.label());
  r.named_text = joined(labels, " ");
  for (const auto& l : r.planted)
    if (!any_names(named, l)) r.missed.push_back(l);
  for (const auto& p : set.planted) {
    const std::string l = indep::effect_label(p.effect, p.axis), advice = kin_hidden_advice(cell, p.effect);
    if (advice.empty()) continue;
    if (any_names(named, l)) r.hidden_named.push_back(l);
    else if (!advised(D, l, advice)) r.unadvised.push_back(l);
  }
  for (const auto& n : named)
    if (std::none_of(all.begin(), all.end(), [&](const std::string& l) { return indep::names_planted(n, l); }))
      r.phantoms.push_back(n.label());
  return r;
}

// One line for a set that missed, phantomed or named what it cannot show.
std::string miss_line(const KinSet& set, const KinSetResult& r) {
  std::vector<std::string> planted = r.planted;
  planted.insert(planted.end(), r.hidden.begin(), r.hidden.end());
  std::string s = "set " + std::to_string(set.seed) + " (" + machine_text(set.nominal_planes) + "): planted " +
                  (planted.empty() ? "nothing" : joined(planted)) + "; named " +
                  (r.named_text.empty() ? "none" : r.named_text);
  if (!r.missed.empty()) s += "; missed " + joined(r.missed);
  if (!r.phantoms.empty()) s += "; phantoms " + joined(r.phantoms);
  if (!r.hidden_named.empty()) s += "; named though not showable " + joined(r.hidden_named);
  if (!r.unadvised.empty()) s += "; no measurement said for " + joined(r.unadvised);
  return s;
}

void add(KinTally& t, const KinSet& set, const KinSetResult& r) {
  ++t.sets;
  t.clean += r.named == 0;
  t.planted += static_cast<int>(r.planted.size());
  t.planted_named += static_cast<int>(r.planted.size() - r.missed.size());
  t.hidden += static_cast<int>(r.hidden.size());
  t.hidden_right += static_cast<int>(r.hidden.size() - r.hidden_named.size() - r.unadvised.size());
  t.named += r.named;
  t.phantoms += static_cast<int>(r.phantoms.size());
  if (!r.missed.empty() || !r.phantoms.empty() || !r.hidden_named.empty() || !r.unadvised.empty())
    t.misses.push_back(miss_line(set, r));
}

std::string count_of(int k, int n) { return std::to_string(k) + "/" + std::to_string(n); }

// k of n meets a share of at least `share` (the 95 %).
bool at_least(int k, int n, double share) { return static_cast<double>(k) >= share * static_cast<double>(n) - 1e-9; }

// One entry of the table: planted named, not-showable handled, phantoms; bold when the cell fails.
std::string entry(const KinTally& t) {
  std::string s = count_of(t.planted_named, t.planted);
  if (t.hidden) s += " + " + count_of(t.hidden_right, t.hidden) + " not shown†";
  if (t.phantoms) s += ", " + std::to_string(t.phantoms) + " phantom" + (t.phantoms > 1 ? "s" : "");
  return kin_pair_failures(t).empty() ? s : "**" + s + "**";
}

}  // namespace

std::string KinCell::text() const {
  return radii_text(*this) + (one_direction ? ", one direction" : ", both directions");
}

std::vector<Vec3> KinCell::poses(std::uint64_t seed) const {
  return position ? hemisphere_poses(radii, kPosRings, kPosPerRing, seed)
                  : hemisphere_poses(radii, kBarRings, kBarPerRing, seed);
}

KinSimOptions KinCell::options(std::uint64_t seed, bool nominal_planes) const {
  KinSimOptions o;
  o.seed = seed;
  o.noise = position ? kPosNoise : kBarNoise;
  o.one_direction = one_direction;
  o.kim_errors = !nominal_planes;
  return o;
}

const std::vector<KinPoolEffect>& kin_pool() {
  static const std::vector<KinPoolEffect> pool = {
      {"backlash", {1, 0, 0}, 2e-6, 1e-5, 20e-6},
      {"cyclic_error", {1, 0.016, 0.3}, 2e-6, 1e-5, 10e-6},
      {"guide_angular_error", {1, 0, 0}, 1e-3, 1e-3, 5e-3},
      {"limb_twist", {1, 0, 0}, 5e-4, 5e-4, 2e-3},
      {"thermal_drift", {1, 1500.0, 0}, 5e-5, 5e-4, 3e-4},
      {kScale, {1, 0, 0}, 2e-4, 2e-4, 5e-4},
  };
  return pool;
}

bool KinPair::has(const std::string& effect) const {
  return kin_pool()[a].name == effect || kin_pool()[b].name == effect;
}

bool KinPair::nominal_planes() const { return has(kScale); }

std::string KinPair::text() const { return std::string(kin_pool()[a].name) + " + " + kin_pool()[b].name; }

const std::vector<KinPair>& kin_pairs() {
  static const std::vector<KinPair> pairs = [] {
    std::vector<KinPair> v;
    for (std::size_t i = 0; i < kin_pool().size(); ++i)
      for (std::size_t j = i + 1; j < kin_pool().size(); ++j) v.push_back({i, j});
    return v;
  }();
  return pairs;
}

const KinAmplitudes& kin_amplitudes(const KinCell& cell, bool nominal_planes) {
  static std::map<std::string, KinAmplitudes> cache;
  KinCell both = cell;
  both.one_direction = false;
  const std::string key = radii_text(both) + ", " + machine_text(nominal_planes);
  if (const auto it = cache.find(key); it != cache.end()) return it->second;
  KinAmplitudes a;
  for (const KinPoolEffect& e : kin_pool()) {
    std::array<double, 3> unit{}, planted{};
    for (std::size_t axis = 0; axis < 3; ++axis) {
      unit[axis] = unit_of(both, nominal_planes, e, static_cast<int>(axis));
      planted[axis] = unit[axis] > 0.0 ? std::min(kKinMultiple * unit[axis], e.ceiling) : e.ceiling;
    }
    a.unit.push_back(unit);
    a.planted.push_back(planted);
  }
  return cache.emplace(key, a).first->second;
}

std::vector<KinSet> kin_sets(const KinCell& cell, int seed, int nulls) {
  std::vector<KinSet> sets;
  const auto next_seed = [&] { return static_cast<std::uint64_t>(seed) * 1000ULL + sets.size(); };
  std::mt19937_64 rng(static_cast<std::uint64_t>(seed));
  for (std::size_t p = 0; p < kin_pairs().size(); ++p) {
    const KinPair& pair = kin_pairs()[p];
    const KinAmplitudes& amp = kin_amplitudes(cell, pair.nominal_planes());
    KinSet s{static_cast<int>(p), pair.nominal_planes(), {}, next_seed()};
    for (const std::size_t k : {pair.a, pair.b}) {
      const auto axis = static_cast<std::size_t>(rng() % 3);
      s.planted.push_back({kin_pool()[k].name, static_cast<int>(axis), sized(kin_pool()[k], amp.planted[k][axis])});
    }
    sets.push_back(s);
  }
  for (int k = 0; k < nulls; ++k) sets.push_back({-1, k % 2 == 1, {}, next_seed()});
  return sets;
}

std::string kin_hidden_advice(const KinCell& cell, const std::string& effect) {
  // From one side, backlash is a constant shift of the axis: the pivot error
  // (ball-bar) or the plane offset (positions) takes it.
  if (effect == "backlash" && cell.one_direction) return "both directions";
  return "";
}

KinSetResult run_kin_set(const KinCell& cell, const KinSet& set) {
  return score(cell, set, diagnose_set(cell, set.nominal_planes, set.planted, set.seed));
}

KinColumn run_kin_column(const KinCell& cell, int seeds, int nulls_per_seed) {
  const auto t0 = std::chrono::steady_clock::now();
  KinColumn c;
  c.cell = cell;
  c.pairs.resize(kin_pairs().size());
  for (int seed = 1; seed <= seeds; ++seed)
    for (const KinSet& set : kin_sets(cell, seed, nulls_per_seed))
      add(set.pair >= 0 ? c.pairs[static_cast<std::size_t>(set.pair)] : c.nulls, set, run_kin_set(cell, set));
  c.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  return c;
}

std::vector<std::string> kin_pair_failures(const KinTally& t, double phantom_rate) {
  std::vector<std::string> why;
  if (!at_least(t.planted_named, t.planted, 0.95))
    why.push_back("planted named " + count_of(t.planted_named, t.planted));
  if (!at_least(t.hidden_right, t.hidden, 0.95))
    why.push_back("not showable, not named and the measurement said " + count_of(t.hidden_right, t.hidden));
  if (static_cast<double>(t.phantoms) > phantom_rate * static_cast<double>(t.named))
    why.push_back("phantoms " + count_of(t.phantoms, t.named) + " named");
  return why;
}

std::vector<std::string> kin_null_failures(const KinTally& t) {
  if (at_least(t.clean, t.sets, 0.95)) return {};
  return {"null sets none " + count_of(t.clean, t.sets)};
}

std::string kin_cells_markdown(const std::vector<KinColumn>& columns) {
  std::ostringstream os;
  os << "| planted |";
  for (const auto& c : columns) os << " " << c.cell.text() << " |";
  os << "\n|---|";
  for (std::size_t k = 0; k < columns.size(); ++k) os << "---|";
  for (std::size_t p = 0; p < kin_pairs().size(); ++p) {
    const KinPair& pair = kin_pairs()[p];
    os << "\n| " << pair.text() << (pair.nominal_planes() ? " (nominal planes)" : "") << " |";
    for (const auto& c : columns) os << " " << entry(c.pairs[p]) << " |";
  }
  os << "\n| nothing (null sets \"none\") |";
  for (const auto& c : columns) {
    const std::string s = count_of(c.nulls.clean, c.nulls.sets);
    os << " " << (kin_null_failures(c.nulls).empty() ? s : "**" + s + "**") << " |";
  }
  return os.str() + "\n";
}

std::string kin_amplitudes_markdown(const std::vector<KinCell>& cells) {
  std::ostringstream os;
  os.precision(2);
  os << "| pose set | machine | effect | axis 1 | axis 2 | axis 3 |\n|---|---|---|---|---|---|\n";
  std::vector<std::string> done;
  for (const KinCell& c : cells)
    for (bool nominal : {false, true}) {
      const std::string head = "| " + radii_text(c) + " | " + machine_text(nominal) + " | ";
      if (std::find(done.begin(), done.end(), head) != done.end()) continue;
      done.push_back(head);
      const KinAmplitudes& a = kin_amplitudes(c, nominal);
      for (std::size_t k = 0; k < kin_pool().size(); ++k) {
        if (!nominal && kin_pool()[k].name == std::string(kScale)) continue;  // planted on nominal planes only
        os << head << kin_pool()[k].name;
        for (std::size_t i = 0; i < 3; ++i)
          os << " | " << a.planted[k][i] << " (" << a.planted[k][i] / a.unit[k][i] << "x)";
        os << " |\n";
      }
    }
  return os.str();
}

}  // namespace cpm::test
