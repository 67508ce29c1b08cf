// SPDX-License-Identifier: Apache-2.0
// Stage "verdict" of the motion diagnosis (internal.hpp): the sentence that
// names every effect the selection chose, with its parameters, what the data
// cannot tell it apart from, and values no healthy machine has.
#include <cmath>
#include <sstream>

#include "internal.hpp"

namespace cpm::ident::detail {
namespace {

// Values no healthy machine of this size has, per effect: worth a second look
// before they go into a model (a sign error in the log, a wrong unit, a model
// far off). `off` judges the first parameter.
struct Implausible {
  const char* effect;
  bool (*off)(double);
  const char* why;
  bool impossible = false;  // no machine at all has it (a mass taken off), not only no healthy one
};

constexpr Implausible kImplausible[] = {
    {"payload_mass", [](double v) { return v < 0.0; },
     "a negative payload: mass taken off the platform, or the model's masses too large", true},
    {"force_gain", [](double v) { return std::fabs(v) > 0.3; },
     "a drive gain off by more than 30 %: check the torque constant and the units of the force column"},
    {"coulomb_friction", [](double v) { return v > 30.0; },
     "more than 30 N of dry friction (a quarter of the force limit)"},
    {"viscous_friction", [](double v) { return v > 200.0; }, "more than 200 N s/m of viscous friction"},
    {"cogging", [](double v) { return v > 20.0; }, "more than 20 N of cogging"},
    {"actuation_delay", [](double v) { return v > 0.02; }, "a dead time of more than 20 ms"},
    // The bound lets a model that carries too much mass on one actuator be
    // corrected; a rotor the model lacks only adds inertia.
    {"actuator_inertia", [](double v) { return v < 0.0; },
     "a negative reflected inertia: no rotor takes mass off an axis; the model's masses on it too large, or "
     "something else that follows its acceleration",
     true},
};

// Ambiguity: an effect chosen that another explains as well (alternatives),
// with the measurement that separates them where the confounding says it.
// "v from a (to separate: ...)" for each; sets D.ambiguous.
std::vector<std::string> cannot_tell_apart(Diagnosis& D, const std::vector<int>& found) {
  std::vector<std::string> alts;
  D.ambiguous = false;
  for (int j : found) {
    const CandidateResult& v = D.candidates[static_cast<std::size_t>(j)];
    for (const auto& a : v.alternatives) {
      D.ambiguous = true;
      std::string how;
      for (const auto& cf : v.confounded)
        if (cf.with == a) how = " (to separate: " + cf.separate_by + ")";
      alts.push_back(v.label() + " from " + a + how);
    }
  }
  return alts;
}

// "label or alternative (p = value ± se unit, ...)".
void write_found_effect(std::ostringstream& os, const CandidateResult& v) {
  os << v.label();
  for (const auto& a : v.alternatives) os << " or " << a;
  os << " (";
  for (std::size_t q = 0; q < v.params.size(); ++q)
    os << (q ? ", " : "") << v.params[q].name << " = " << human_value(v.params[q]);
  os << ")";
}

}  // namespace

std::string implausible_value(const std::string& effect, double first_param, bool impossible_only) {
  for (const Implausible& i : kImplausible)
    if (effect == i.effect && i.off(first_param) && (i.impossible || !impossible_only)) return i.why;
  return {};
}

std::string implausible(const CandidateResult& c) {
  return c.params.empty() ? std::string() : implausible_value(c.effect, c.params[0].value);
}

std::string unphysical(const CandidateResult& c) {
  if (std::string why = implausible(c); !why.empty()) return why;
  for (const ParamEstimate& p : c.params)
    if (p.at_bound && p.value != 0.0)
      return "its best fit lies beyond the physical range of " + p.name + ", held at the bound " + human_value(p);
  return {};
}

std::string not_missing_beside_outside(const CandidateResult& c) {
  if (std::string why = unphysical(c); !why.empty()) return why;
  for (const ParamEstimate& p : c.params)
    if (p.std_error > std::fabs(p.value))
      return "these data do not determine its " + p.name + " (standard error above the value)";
  return {};
}

void verdict_text_motion(Diagnosis& D) {
  const std::vector<int> found = D.found();
  if (found.empty()) {
    D.ambiguous = false;
    D.verdict_text = no_effect_text(D);
    return;
  }
  const std::vector<std::string> alts = cannot_tell_apart(D, found);
  // An effect whose value no healthy machine has is not said to be missing
  // from the model in the same breath: it is said apart, with why.
  std::vector<int> plausible, doubtful;
  for (int j : found) (implausible(D.candidates[static_cast<std::size_t>(j)]).empty() ? plausible : doubtful).push_back(j);
  std::ostringstream os;
  os << "missing: ";
  if (plausible.empty()) os << "no effect with a plausible value";
  for (std::size_t j = 0; j < plausible.size(); ++j) {
    if (j) os << "; ";
    write_found_effect(os, D.candidates[static_cast<std::size_t>(plausible[j])]);
  }
  os << ". ";
  if (!doubtful.empty()) {
    os << "The data " << (plausible.empty() ? "fit " : "also fit ");
    for (std::size_t j = 0; j < doubtful.size(); ++j) {
      const CandidateResult& v = D.candidates[static_cast<std::size_t>(doubtful[j])];
      if (j) os << "; ";
      write_found_effect(os, v);
      os << ", a value no healthy machine has (" << implausible(v) << ")";
    }
    os << ": check the log before adding " << (doubtful.size() > 1 ? "them" : "it") << " to a model. ";
  }
  os << (found.size() > 1 ? "Together they bring" : "It brings") << " the residual from "
     << amount(D.baseline_rms, D.units) << " to " << amount(Engine::rms(D.residual_final), D.units) << " RMS "
     << floor_after(Engine::rms(D.residual_final), D.noise_floor, D.units);
  if (D.ambiguous) {
    os << ". These data cannot tell ";
    for (std::size_t j = 0; j < alts.size(); ++j) os << (j ? "; nor " : "") << alts[j];
    os << " apart";
  }
  D.verdict_text = os.str();
}

}  // namespace cpm::ident::detail
