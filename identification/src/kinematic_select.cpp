// SPDX-License-Identifier: Apache-2.0
// Stage 5 of the kinematic diagnosis, selection and verdict
// (kinematic_internal.hpp, select_kinematic_effects).
//
// The one statistic of the motion side (select.cpp): forward selection over
// every effect the data can show on every axis, here from the calibrated base
// (the base is calibration's: every model tried refits it). Before, the
// candidates were ranked by their significance alone, the verdict was the
// first, and the forward selection only tried those significant alone: a
// thermal drift left in the residual, smooth in time and so correlated in
// file order, cut the effective sample size of every other candidate judged
// alone (33 of 192 rows), and the other effect was missed in 75 of 105 sets
// that could show it (the kinematic cells, docs/identification.md).
// Each wavelength and time constant is searched again on what the effects
// chosen before it leave, and each one chosen again beside every later
// choice: searched alone on a residual holding a limb twist, a cyclic error on
// axis 3 locked onto an alias (1.5 mm for 16 mm), and what it left was named
// as twists on other axes. The actuator scales, which the calibrated base
// absorbs, are judged last, at the model as given with the effects chosen
// (kinematic_scales.cpp). After each choice every effect chosen before is
// tested again beside all the others and dropped when it no longer adds
// anything: with one bar radius a limb twist on axis 3 explained most of a
// guide error there and a twist on axis 1 together, was chosen first, and
// stayed beside the two real effects as a phantom.
#include <algorithm>

#include "kinematic_internal.hpp"
#include "selection.hpp"

namespace cpm::ident::kinematic_detail {
namespace {

using detail::amount;


// From the calibrated base, what each term adds measured against the model
// reached, searched parameters searched again beside the effects chosen.
detail::SelectionKind from_the_calibrated_base(const KinematicProblem& P, const Engine& E) {
  detail::SelectionKind k;
  k.base_refitted = true;
  k.gains_beyond_state = true;
  k.prune = true;
  k.research = [&P, &E](detail::Term& t, CandidateResult& c, const Eigen::MatrixXd& others) {
    const auto type = kin::kinematic_effect_from_name(c.effect);
    const KinematicEffectFitter* f = type ? kinematic_fitter(*type) : nullptr;
    if (!f || !f->search_beside || c.axis < 0 || c.axis > 2) return;
    const KinematicCandidateContext x{P, E, c.axis, kin::info(*type), span_of(P)};
    f->search_beside(x, with_base_columns(E, others, "chosen effect"), c);
    t.X = c.columns;
  };
  return k;
}

// "label (how to separate)" for what effect v cannot be told apart from: its
// alternatives in the selection, and for the verdict (`hidden`) what its
// signature is alike among the candidates the data cannot show (those the
// base absorbs).
std::vector<std::string> cannot_tell_apart(const Diagnosis& D, const CandidateResult& v, bool hidden_too) {
  std::vector<std::string> alts;
  auto how = [&](const std::string& label) {
    for (const auto& cf : v.confounded)
      if (cf.with == label) return " (" + cf.separate_by + ")";
    return std::string();
  };
  for (const auto& a : v.alternatives) alts.push_back(a + how(a));
  if (!hidden_too) return alts;
  for (const auto& cf : v.confounded) {
    if (cf.effect.empty() || cf.correlation < 0.85) continue;
    const bool hidden = std::any_of(D.candidates.begin(), D.candidates.end(), [&](const CandidateResult& o) {
      return o.label() == cf.with && !o.identifiable;
    });
    const bool named = std::find(v.alternatives.begin(), v.alternatives.end(), cf.with) != v.alternatives.end();
    if (hidden && !named) alts.push_back(cf.with + " (" + cf.separate_by + ")");
  }
  return alts;
}

// ". These data cannot tell <it> apart from a (how); b (how)" or nothing.
std::string apart_text(const std::string& it, const std::vector<std::string>& alts) {
  if (alts.empty()) return {};
  std::string s = ". These data cannot tell " + it + " apart from ";
  for (std::size_t j = 0; j < alts.size(); ++j) s += (j ? "; " : "") + alts[j];
  return s;
}

// The verdict: the first effect chosen with its parameters and what it does
// alone, what it cannot be told apart from; then the others chosen, what they
// bring together, and theirs. Sets D.ambiguous.
std::string kinematic_verdict_text(Diagnosis& D) {
  const CandidateResult& v = D.candidates[static_cast<std::size_t>(D.verdict)];
  std::ostringstream os;
  os << "missing: " << v.label() << " — ";
  for (std::size_t j = 0; j < v.params.size(); ++j)
    os << (j ? ", " : "") << v.params[j].name << " = " << fmt(v.params[j].value, 4) << " " << v.params[j].unit;
  if (!v.searched_determined) os << " (one of several wavelengths these data fit alike)";
  os << "; it brings the residual from " << amount(D.baseline_rms, D.units) << " to "
     << amount(v.rms_after, D.units) << " RMS (noise floor about " << amount(D.noise_floor, D.units) << ")";
  std::vector<std::string> alts = cannot_tell_apart(D, v, true);
  D.ambiguous = !alts.empty();
  os << apart_text("it", alts);
  if (D.also.empty()) return os.str();
  os << ". Also significant on top of it: ";
  for (std::size_t j = 0; j < D.also.size(); ++j) os << (j ? ", " : "") << D.candidates[D.also[j]].label();
  os << " (together they bring the residual to " << amount(Engine::rms(D.residual_final), D.units) << " RMS)";
  for (int j : D.also) {
    const CandidateResult& o = D.candidates[static_cast<std::size_t>(j)];
    alts = cannot_tell_apart(D, o, false);
    D.ambiguous = D.ambiguous || !alts.empty();
    os << apart_text(o.label(), alts);
  }
  return os.str();
}

}  // namespace

void select_kinematic_effects(const KinematicProblem& P, const Engine& E, const DiagnoseOptions& opt, Diagnosis& D) {
  detail::Selection sel = detail::forward_selection(D, E, opt, from_the_calibrated_base(P, E));
  select_scales_at_the_given_model(P, E, opt, D, sel);
  detail::apply_selection(D, E, sel);
  D.verdict_text = D.verdict < 0 ? detail::no_effect_text(D) : kinematic_verdict_text(D);
}

Engine with_base_columns(const Engine& E, const Eigen::MatrixXd& X, const char* name) {
  LinearProblem L = E.problem();
  L.B = detail::hstack(L.B, X);
  for (Eigen::Index j = 0; j < X.cols(); ++j) {
    L.base_names.emplace_back(name);
    L.base_units.emplace_back("m");
    L.base_values.push_back(0.0);
    L.nuisance.push_back(0);
  }
  return Engine(std::move(L));
}

}  // namespace cpm::ident::kinematic_detail
