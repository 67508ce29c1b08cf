// SPDX-License-Identifier: Apache-2.0
#include "cpm/identification/model_loop.hpp"

#include <algorithm>
#include <cmath>
#include <memory>
#include <optional>
#include <sstream>

#include <nlohmann/json.hpp>

#include "cpm/calibration/workflow.hpp"
#include "cpm/control/effects.hpp"
#include "cpm/identification/fit_user.hpp"
#include "cpm/identification/kinematic.hpp"
#include "internal.hpp"
#include "cpm/identification/report.hpp"

namespace cpm::ident {
namespace {

Diagnosis diagnose_any(const io::DataSet& data, const ctl::MachineModel& model, const DiagnoseOptions& o) {
  if (const auto* m = std::get_if<io::MotionData>(&data)) return diagnose_motion(*m, ctl::Machine(model), o);
  return diagnose_kinematic(std::make_shared<const KinematicProblem>(prepare_kinematic(data, model.kinematics)), o);
}

std::string label_of(const FitRequest& r) {
  return r.effect + (r.axis >= 0 ? "[axis " + std::to_string(r.axis + 1) + "]" : "");
}

// The first bars of the waterfall: the model as given (kinematic data: then
// its planes calibrated, the base).
void record_model_as_given(LoopResult& R, const Diagnosis& D, const io::DataSet& data, const ctl::MachineModel& model,
                           const DiagnoseOptions& o) {
  R.kind = D.kind;
  R.units = D.units;
  if (const auto* m = std::get_if<io::MotionData>(&data)) {
    R.steps.push_back({"", motion_rms(*m, model, o.motion), D.noise_floor, D.verdict_text});
  } else {
    R.steps.push_back({"", D.baseline_rms, D.noise_floor, ""});
    R.steps.push_back({"calibrated planes", D.base_refit_rms, D.noise_floor, D.verdict_text});
  }
}

bool has(const std::vector<FitRequest>& v, const FitRequest& r) {
  return std::any_of(v.begin(), v.end(), [&](const FitRequest& a) { return a.effect == r.effect && a.axis == r.axis; });
}

double rms_of(const Eigen::VectorXd& x) { return x.size() ? std::sqrt(x.squaredNorm() / static_cast<double>(x.size())) : 0.0; }

}  // namespace

bool finding_too_small(const StructureFinding& f, const Diagnosis& D, double explained) {
  return std::fabs(f.size) < D.noise_floor || std::fabs(f.size) < kSmallFindingShare * explained;
}

std::string loop_stop_reason(const Diagnosis& D, const LoopResult& R, std::vector<FitRequest>& next) {
  const std::vector<int> found = D.found();
  next.clear();
  for (int j : found) {
    const CandidateResult& c = D.candidates[static_cast<std::size_t>(j)];
    if (!has(R.added, {c.effect, c.axis})) next.push_back({c.effect, c.axis});
  }
  // The library effects named beside an outside finding are added first: the
  // finding stops the loop only once nothing of the library is left to add (a
  // structure far smaller than what the effects explain, or under the floor,
  // is reported but must not keep them out of the model).
  if (!D.outside_library.empty()) {
    if (!next.empty()) return {};
    // A finding the selection led with, so that it named no library effect
    // beside it: when every finding is too small to matter (9.5 mN at 13
    // sigma beside 3 N of friction stopped the loop with a viscous friction
    // and a payload still significant in the same diagnosis), the significant
    // candidates are added, best first, before it may stop the loop.
    double explained = 0.0;
    if (R.steps.size() >= 2)
      explained = std::sqrt(std::max(0.0, R.steps.front().rms * R.steps.front().rms - R.steps.back().rms * R.steps.back().rms));
    for (const CandidateResult& c : D.candidates)
      if (c.significant && c.identifiable) explained = std::max(explained, rms_of(c.fitted));
    const bool small = std::all_of(D.outside_library.begin(), D.outside_library.end(),
                                   [&](const StructureFinding& f) { return finding_too_small(f, D, explained); });
    if (small)
      for (const CandidateResult& c : D.candidates)
        if (c.significant && c.identifiable && !has(R.added, {c.effect, c.axis}))
          next.push_back({c.effect, c.axis});
    if (!next.empty()) return {};
    return "something no library effect describes remains: " + D.outside_library.front().text;
  }
  if (found.empty()) return "nothing is missing: the diagnosis finds no significant effect";
  if (next.empty())
    return "the diagnosis names " + D.candidates[static_cast<std::size_t>(found.front())].label() +
           " again after it was fitted: the data cannot settle it";
  return {};
}

namespace {

// Every effect of `trial` refitted together on the model as given.
struct Refit {
  ctl::MachineModel model;
  double rms = 0.0;  // residual RMS of the new model (N or m)
  std::vector<io::FittedParameter> fitted;
  std::vector<CandidateResult> effects;
};

Refit refit(const io::DataSet& data, const ctl::MachineModel& model, const std::vector<FitRequest>& trial,
            const DiagnoseOptions& o) {
  Refit out{model, 0.0, {}, {}};
  if (trial.empty()) {
    // Only user effects in the model so far: nothing of the library to refit.
    if (const auto* m = std::get_if<io::MotionData>(&data)) {
      out.rms = motion_rms(*m, model, o.motion);
    } else {
      // The planes recalibrated beside the user effects (the model file must hold them calibrated).
      io::ModelFile in;
      in.model = model;
      const cal::CalibrationResult C = cal::calibrate(in, data, "", "", "cpm loop");
      out.model = C.model.model;
      out.rms = C.residual_rms();
    }
    return out;
  }
  if (const auto* m = std::get_if<io::MotionData>(&data)) {
    const FitResult F = fit_motion(*m, model, trial, o, nullptr, false);
    out.model = F.model;
    out.fitted = F.fitted;
    out.effects = F.effects;
    out.rms = F.on_fit.after;
  } else {
    const KinematicFit F = fit_kinematic(data, model.kinematics, trial, o, nullptr, false);
    out.model.kinematics = F.model;
    out.fitted = F.fitted;
    out.effects = F.effects;
    out.rms = F.on_fit.after;
  }
  return out;
}

// The step: the first effect named (best first) whose refit with those added
// before lowers the model's residual, else all of them together; R.added
// grows by what was kept, `label` says what (or, when nothing lowers it, what
// was tried). A refit that does not lower the residual of the model is not
// kept: what the diagnosis fits jointly, with the nuisance beside it, one
// effect alone may not hold in the model file (a spring named beside a
// payload, fitted without it, took a rest position 0.27 m off; a delay named
// beside a friction lowered nothing until the friction was in).
std::optional<Refit> first_that_lowers(const io::DataSet& data, const ctl::MachineModel& model, LoopResult& R,
                                       const std::vector<FitRequest>& named, const DiagnoseOptions& o,
                                       std::string& label) {
  const double before = R.steps.back().rms;
  std::vector<std::vector<FitRequest>> tries;
  std::vector<std::string> refused;
  for (const FitRequest& r : named) tries.push_back({r});
  if (named.size() > 1) tries.push_back(named);
  for (const auto& extra : tries) {
    std::vector<FitRequest> trial = R.added;
    trial.insert(trial.end(), extra.begin(), extra.end());
    label.clear();
    for (const FitRequest& r : extra) label += (label.empty() ? "" : " + ") + label_of(r);
    // A trial whose fit leaves the physical range (a negative viscous
    // friction, named beside a delay on a 250 Hz log) is not kept, and the
    // loop goes on with the next: one implausible effect must not end it.
    std::optional<Refit> F;
    try {
      F = refit(data, model, trial, o);
    } catch (const Error& e) {
      refused.push_back(label + " (" + e.what() + ")");
      continue;
    }
    if (F->rms < before) {
      R.added = std::move(trial);
      return F;
    }
  }
  label.clear();
  for (const FitRequest& r : named) label += (label.empty() ? "" : ", ") + label_of(r);
  label += named.size() > 1 ? " (one at a time or together)" : "";
  for (const std::string& r : refused) label += "; not fitted: " + r;
  return std::nullopt;
}

bool same_user_effect(const SuggestedUserEffect& a, const SuggestedUserEffect& b) {
  return a.kind == b.kind && a.axis == b.axis && a.input == b.input && a.formula == b.formula;
}

// The step that adds the suggestion `s` to `base` (the model as given with
// the user effects added so far) and fits it beside the library effects
// already added; nullopt (and `why`) when it cannot be fitted or lowers nothing.
std::optional<Refit> add_user_effect_step(const io::DataSet& data, ctl::MachineModel& base, LoopResult& R,
                                          SuggestedUserEffect s, const DiagnoseOptions& o, std::string& why) {
  const double before = R.steps.back().rms;
  ctl::MachineModel trial_base = base;
  try {
    if (const auto* m = std::get_if<io::MotionData>(&data)) {
      // Fitted on the model the loop has (its library effects held), then
      // those refitted beside the fitted user effect.
      ctl::MachineModel held = R.model;
      held.user_effects.push_back(user_effect_of(s));
      const int index = static_cast<int>(held.user_effects.size()) - 1;
      const UserFit U = fit_user_effect(*m, held, index, o.motion);
      const ctl::UserEffect& fitted = U.model.user_effects[static_cast<std::size_t>(index)];
      trial_base.user_effects.push_back(fitted);
      if (fitted.kind == ctl::UserEffectKind::table) {
        s.values = fitted.values;
      } else {
        for (std::size_t k = 0; k < s.params.size() && k < fitted.params.size(); ++k)
          s.params[k] = {fitted.params[k].name, fitted.params[k].value};
      }
    } else {
      trial_base.kinematics.effects[static_cast<std::size_t>(s.axis)].pitch_table = pitch_table_of(s);
    }
    Refit F = refit(data, trial_base, R.added, o);
    if (!(F.rms < before)) {
      why = "adding " + label_of(s) + " left the residual at " + std::to_string(F.rms) + " " + R.units +
            " (not below " + std::to_string(before) + "); not kept";
      return std::nullopt;
    }
    s.rms_after = F.rms;
    base = std::move(trial_base);
    R.user_added.push_back(std::move(s));
    return F;
  } catch (const Error& e) {
    why = "adding " + label_of(s) + " failed: " + e.what();
    return std::nullopt;
  }
}

}  // namespace

SuggestedUserEffect suggestion_of(const Diagnosis& D) {
  if (D.kind != "motion") {
    if (!D.suggested_user_effects.empty()) return D.suggested_user_effects.front();
    return {};
  }
  if (D.outside_library.empty()) return {};
  return suggest_user_effect(D.outside_library.front());
}

ctl::UserEffect user_effect_of(const SuggestedUserEffect& s) {
  ctl::UserEffect e;
  e.axis = s.axis;
  if (s.kind == "table") {
    if (s.input.size() != 2 || (s.input[0] != 'd' && s.input[0] != 'v') || s.input[1] < '1' || s.input[1] > '3')
      throw Error("a table follows d1..d3 or v1..v3, not " + s.input);
    e.kind = ctl::UserEffectKind::table;
    e.input = s.input[0];
    e.input_axis = s.input[1] - '1';
    e.nodes = s.nodes;
    e.values = s.values;
    if (e.values.size() != e.nodes.size()) e.values.assign(e.nodes.size(), 0.0);
  } else if (s.kind == "expression") {
    e.kind = ctl::UserEffectKind::expression;
    e.formula = s.formula;
    for (const auto& [name, value] : s.params) e.params.push_back({name, "", value});
  } else {
    throw Error("a " + (s.kind.empty() ? std::string("finding without a suggestion") : s.kind) +
                " is not a force effect of the model");
  }
  ctl::validate_user_effect(e, 0);
  return e;
}

kin::PitchTable pitch_table_of(const SuggestedUserEffect& s) {
  if (s.kind != "pitch_table" || s.axis < 0 || s.axis > 2) throw Error("not a pitch_table on axis 1..3");
  if (s.nodes.size() > static_cast<std::size_t>(kin::PitchTable::kCapacity) || s.values.size() != s.nodes.size())
    throw Error("pitch_table: " + std::to_string(s.nodes.size()) + " nodes and " + std::to_string(s.values.size()) +
                " values (equal numbers, at most " + std::to_string(kin::PitchTable::kCapacity) + ")");
  kin::PitchTable t;
  t.size = static_cast<int>(s.nodes.size());
  std::copy(s.nodes.begin(), s.nodes.end(), t.node.begin());
  std::copy(s.values.begin(), s.values.end(), t.error.begin());
  t.validate();
  return t;
}

std::string label_of(const SuggestedUserEffect& s) {
  std::string l = s.kind + "[axis " + std::to_string(s.axis + 1) + "]";
  if (s.kind == "expression") l += ": " + s.formula;
  if (s.kind == "table") l += ": " + s.input;
  return l;
}

SuggestedUserEffect suggest_user_effect(const StructureFinding& f) {
  SuggestedUserEffect s;
  s.axis = f.axis;
  std::ostringstream os;
  os.precision(4);
  const std::string ax = std::to_string(f.axis + 1);
  if (f.kind == "smooth" && f.shape == "linear") {
    s.kind = "expression";
    s.formula = "c*" + f.coordinate;
    s.params = {{"c", f.slope}};
    os << "add to axis " << ax << " the expression effect c*" << f.coordinate << " with c = " << f.slope
       << " (N per SI unit of " << f.coordinate << ")";
  } else if (f.kind == "position_friction" && f.nodes.size() >= 4 && f.hi > f.lo) {
    // A table follows one variable: a friction map is an expression, its
    // level a cubic in u = (d - mid) / half fitted to the finding's levels,
    // times the library's sign of the speed (docs/effects.md, "Effects you add").
    const double mid = 0.5 * (f.lo + f.hi), half = 0.5 * (f.hi - f.lo);
    Eigen::MatrixXd U(static_cast<Eigen::Index>(f.nodes.size()), 4);
    Eigen::VectorXd L(U.rows());
    for (Eigen::Index q = 0; q < U.rows(); ++q) {
      const double u = (f.nodes[static_cast<std::size_t>(q)] - mid) / half;
      U.row(q) << 1.0, u, u * u, u * u * u;
      L(q) = f.values[static_cast<std::size_t>(q)];
    }
    const Eigen::VectorXd c = U.colPivHouseholderQr().solve(L);
    std::ostringstream u;
    u.precision(6);
    u << "((" << f.coordinate << "-" << mid << ")/" << half << ")";
    const std::string v = "v" + f.coordinate.substr(1);
    std::ostringstream tanh_eps;
    tanh_eps.precision(6);
    tanh_eps << ctl::kSignEpsilon;
    s.kind = "expression";
    s.formula = "(c0+c1*" + u.str() + "+c2*" + u.str() + "^2+c3*" + u.str() + "^3)*tanh(" + v + "/" + tanh_eps.str() + ")";
    s.params = {{"c0", c(0)}, {"c1", c(1)}, {"c2", c(2)}, {"c3", c(3)}};
    os << "add to axis " << ax << " the expression effect " << s.formula << " with c0 = " << c(0) << ", c1 = " << c(1)
       << ", c2 = " << c(2) << ", c3 = " << c(3) << " N (a friction map: its level along " << f.coordinate
       << ", opposing the motion in both directions)";
  } else if (f.kind == "smooth") {
    s.kind = "table";
    s.input = f.coordinate;
    s.nodes = f.nodes;
    s.values = f.values;
  } else if (f.kind == "bump" || f.kind == "step") {
    // Linear interpolation between nodes: zero outside, the excess over the stretch found.
    const double w = std::max(f.hi - f.lo, 1e-4);
    s.kind = "table";
    s.input = f.coordinate;
    if (f.kind == "bump") {
      // Its shape, not only its stretch: nodes a quarter of the scan's bin
      // apart over four bins around it (the fit sets their values). Four
      // nodes (a trapezoid over the bin) left a Gaussian tight spot at 10x the
      // floor 1.23x the floor, and the loop then named a drive gain and a
      // rotor inertia for what the trapezoid left.
      constexpr int kNodes = 17;
      for (int k = 0; k < kNodes; ++k) {
        const double x = f.lo - 1.5 * w + 4.0 * w * k / (kNodes - 1);
        s.nodes.push_back(x);
        s.values.push_back(x >= f.lo && x <= f.hi ? f.size : 0.0);
      }
    } else {
      s.nodes = {f.location - 1e-3, f.location + 1e-3};
      s.values = {0.0, f.size};
    }
  } else {
    os << "no table or expression suggested: a " << f.kind << " structure is what a library effect describes "
       << "(cogging, friction) once its cause is known";
    s.text = os.str();
    return s;
  }
  if (s.kind == "table") {
    os << "add to axis " << ax << " a table effect over " << s.input << ": nodes";
    for (double x : s.nodes) os << " " << x;
    os << ", values (N)";
    for (double v : s.values) os << " " << v;
  }
  s.text = os.str();
  return s;
}

LoopResult run_loop(const io::DataSet& data, const ctl::MachineModel& model, const DiagnoseOptions& o, int max_steps,
                    const std::vector<std::string>& allow) {
  LoopResult R;
  R.model = model;
  ctl::MachineModel base = model;  // the model as given with the user effects added: the library refits start there
  Diagnosis D = diagnose_any(data, model, o);
  record_model_as_given(R, D, data, model, o);
  for (int step = 0; step < max_steps; ++step) {
    std::vector<FitRequest> named;
    R.stop = loop_stop_reason(D, R, named);
    for (const StructureFinding& f : D.outside_library)
      if (R.stop.empty() && R.notes.size() < 20) R.notes.push_back("reported, not stopping the loop (too small beside the effects): " + f.text);
    if (!R.stop.empty()) {
      R.outside_library = !D.outside_library.empty();
      if (!R.outside_library) return R;
      R.suggestion = suggestion_of(D);
      const SuggestedUserEffect s = R.suggestion;
      if (s.kind.empty() || std::find(allow.begin(), allow.end(), s.kind) == allow.end()) return R;
      if (std::any_of(R.user_added.begin(), R.user_added.end(),
                      [&](const SuggestedUserEffect& u) { return same_user_effect(u, s); })) {
        R.stop += "; the diagnosis suggests " + label_of(s) + " again after it was added: the data cannot settle more";
        return R;
      }
      std::string why;
      std::optional<Refit> F = add_user_effect_step(data, base, R, s, o, why);
      if (!F) {
        R.stop += "; " + why;
        return R;
      }
      R.fitted = std::move(F->fitted);
      R.effects = std::move(F->effects);
      R.model = std::move(F->model);
      R.outside_library = false;
      R.suggestion = {};
      D = diagnose_any(data, R.model, o);
      R.steps.push_back({label_of(R.user_added.back()), F->rms, D.noise_floor, D.verdict_text});
      continue;
    }
    std::string label;
    std::optional<Refit> F = first_that_lowers(data, base, R, named, o, label);
    if (!F) {
      R.stop = "adding " + label + " did not lower the model's residual below " + std::to_string(R.steps.back().rms) +
               " " + R.units + "; not kept";
      return R;
    }
    R.fitted = std::move(F->fitted);
    R.effects = std::move(F->effects);
    R.model = std::move(F->model);
    D = diagnose_any(data, R.model, o);
    R.steps.push_back({label, F->rms, D.noise_floor, D.verdict_text});
  }
  R.stop = "stopped after " + std::to_string(max_steps) + " steps";
  return R;
}

std::string loop_text(const LoopResult& R) {
  const bool m = R.units == "m";
  const double k = m ? 1e6 : 1.0;
  const std::string u = m ? "µm" : "N";
  std::ostringstream o;
  o.precision(4);
  o << "waterfall (" << R.kind << " data; residual RMS after each step, " << u << "):\n";
  for (std::size_t j = 0; j < R.steps.size(); ++j) {
    const LoopStep& s = R.steps[j];
    o << "  " << j << "  " << (s.added.empty() ? "model as given" : "+ " + s.added);
    o << std::string(s.added.empty() ? 16 : (s.added.size() + 4 < 30 ? 28 - s.added.size() : 2), ' ') << s.rms * k << " "
      << u << "  ";
    if (s.noise_floor > s.rms)  // a floor above what was reached is an estimate too high, not a floor
      o << "(below the noise floor's estimate " << s.noise_floor * k << " " << u << ": that estimate is too high)\n";
    else
      o << "(" << (s.noise_floor > 0.0 ? s.rms / s.noise_floor : 0.0) << " x the noise floor " << s.noise_floor * k << " "
        << u << ")\n";
  }
  for (const std::string& n : R.notes) o << "note: " << n << "\n";
  o << "stop: " << R.stop << "\n";
  if (!R.suggestion.text.empty()) o << "suggested user effect: " << R.suggestion.text << "\n";
  if (!R.steps.empty()) o << "last diagnosis: " << R.steps.back().verdict << "\n";
  return o.str();
}

std::string loop_json(const LoopResult& R, const std::string& data_file, const std::string& out_file) {
  using Json = nlohmann::ordered_json;
  Json waterfall = Json::array();
  for (std::size_t j = 0; j < R.steps.size(); ++j) {
    const LoopStep& s = R.steps[j];
    waterfall.push_back({{"step", j}, {"added", s.added.empty() ? Json() : Json(s.added)}, {"rms", s.rms},
                         {"noise_floor", s.noise_floor}, {"verdict", s.verdict}});
  }
  Json effects = Json::array();
  for (const CandidateResult& c : R.effects) {
    Json params = Json::object();
    for (const auto& p : c.params) params[p.name] = p.value;
    effects.push_back({{"effect", c.effect}, {"axis", c.axis >= 0 ? Json(c.axis + 1) : Json()}, {"params", params}});
  }
  Json o = {{"kind", R.kind}, {"units", R.units}, {"data_file", data_file}, {"out", out_file},
            {"waterfall", waterfall}, {"effects", effects}, {"outside_library", R.outside_library},
            {"stop", R.stop}};
  // The outside finding as a user effect for the model file's `user_effects:` list.
  auto user_json = [](const SuggestedUserEffect& s) {
    Json u = {{"kind", s.kind}, {"axis", s.axis + 1}};
    if (s.kind == "table" || s.kind == "pitch_table") {
      if (s.kind == "table") u["input"] = s.input;
      u["nodes"] = s.nodes;
      u["values"] = s.values;
    } else {
      u["formula"] = s.formula;
      Json params = Json::object();
      for (const auto& [name, value] : s.params) params[name] = value;
      u["params"] = params;
    }
    if (s.rms_after > 0.0) u["rms_after"] = s.rms_after;
    u["text"] = s.text;
    return u;
  };
  Json added = Json::array();
  for (const SuggestedUserEffect& s : R.user_added) added.push_back(user_json(s));
  o["user_effects_added"] = added;
  o["suggested_user_effect"] = R.suggestion.kind.empty() ? Json() : user_json(R.suggestion);
  return o.dump(2, ' ', false, Json::error_handler_t::replace) + "\n";
}

std::string loop_html(const LoopResult& R, const std::string& data_file) {
  const bool m = R.units == "m";
  const double k = m ? 1e6 : 1.0;
  const std::string u = m ? "µm" : "N";
  // Bars: one per step, the noise floor as a dashed line across them. The
  // steps' names under the bars slant, so that long names do not overlap;
  // the bottom margin is sized for the longest.
  std::size_t longest = 8;  // "as given"
  for (const auto& s : R.steps) longest = std::max(longest, s.added.size() + 2);
  const double W = 120.0 + 110.0 * static_cast<double>(R.steps.size()), l = 70, t = 30;
  const double b = 30.0 + 0.6 * 6.0 * static_cast<double>(longest), H = 230.0 + b;
  double top = 0.0;
  for (const auto& s : R.steps) top = std::max({top, s.rms * k, s.noise_floor * k});
  const double ystep = detail::nice_step(top > 0.0 ? top * 1.05 : 1.0, 5);
  top = top > 0.0 ? std::ceil(top * 1.05 / ystep) * ystep : 5.0 * ystep;
  auto Y = [&](double v) { return H - b - (H - t - b) * v / top; };
  std::ostringstream o;
  o << "<!DOCTYPE html><html><head><meta charset='utf-8'><title>cpm loop: " << data_file
    << "</title><style>body{font-family:sans-serif;margin:18px;color:#222}</style></head><body>";
  o << "<h1>cpm loop: " << data_file << "</h1><p>Diagnose, add the effect found, refit, diagnose again. Residual RMS ("
    << u << ") of the model after each step; the dashed line is the noise floor the diagnosis estimates.</p>";
  o << "<svg xmlns='http://www.w3.org/2000/svg' width='" << W << "' height='" << H
    << "' style='background:#fff;border:1px solid #ddd'>";
  // The y axis with its ticks and grid.
  for (double v = 0.0; v <= top + 0.5 * ystep; v += ystep) {
    o << "<line x1='" << l << "' x2='" << W - 10 << "' y1='" << Y(v) << "' y2='" << Y(v) << "' stroke='#eee'/>";
    o << "<line x1='" << l - 4 << "' x2='" << l << "' y1='" << Y(v) << "' y2='" << Y(v) << "' stroke='#888'/>";
    o << "<text x='" << l - 6 << "' y='" << Y(v) + 4 << "' font-size='10' text-anchor='end'>"
      << detail::tick_text(v, ystep) << "</text>";
  }
  o << "<line x1='" << l << "' y1='" << Y(0) << "' x2='" << l << "' y2='" << t << "' stroke='#888'/>";
  o << "<line x1='" << l << "' y1='" << Y(0) << "' x2='" << W - 10 << "' y2='" << Y(0) << "' stroke='#888'/>";
  o << "<text x='14' y='" << (H - b + t) / 2 << "' font-size='11' transform='rotate(-90 14 " << (H - b + t) / 2
    << ")' text-anchor='middle'>residual RMS (" << u << ")</text>";
  for (std::size_t j = 0; j < R.steps.size(); ++j) {
    const LoopStep& s = R.steps[j];
    const double x = l + 20 + 110.0 * static_cast<double>(j), v = s.rms * k;
    o << "<rect x='" << x << "' y='" << Y(v) << "' width='70' height='" << Y(0) - Y(v) << "' fill='#36c'/>";
    char buf[64];
    std::snprintf(buf, sizeof buf, "%.4g", v);
    o << "<text x='" << x + 35 << "' y='" << Y(v) - 4 << "' font-size='11' text-anchor='middle'>" << buf << "</text>";
    const double lx = x + 40, ly = H - b + 14;
    o << "<text x='" << lx << "' y='" << ly << "' font-size='10' text-anchor='end' transform='rotate(-35 " << lx << " "
      << ly << ")'>" << (s.added.empty() ? "as given" : "+ " + s.added) << "</text>";
    const double f = s.noise_floor * k;
    o << "<line x1='" << x - 10 << "' x2='" << x + 80 << "' y1='" << Y(f) << "' y2='" << Y(f)
      << "' stroke='#d33' stroke-dasharray='4 3'/>";
  }
  // The legend: the floor's dashed line beside its name.
  o << "<line x1='" << W - 100 << "' x2='" << W - 76 << "' y1='" << t - 14 << "' y2='" << t - 14
    << "' stroke='#d33' stroke-dasharray='4 3' stroke-width='1.5'/>";
  o << "<text x='" << W - 72 << "' y='" << t - 10 << "' font-size='11' fill='#d33'>noise floor</text>";
  o << "</svg><p><b>Stop:</b> " << R.stop << "</p><ol start='0'>";
  for (const auto& s : R.steps)
    o << "<li>" << (s.added.empty() ? "model as given" : "+ " + s.added) << ": " << s.verdict << "</li>";
  o << "</ol></body></html>\n";
  return o.str();
}

}  // namespace cpm::ident
