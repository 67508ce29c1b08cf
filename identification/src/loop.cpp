#include "cpm/identification/loop.hpp"

#include <algorithm>
#include <cmath>
#include <memory>
#include <optional>
#include <sstream>

#include <nlohmann/json.hpp>

#include "cpm/identification/kinematic.hpp"
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

// Why the loop stops at this diagnosis (empty: go on and add one of `next`,
// the effects it names that the model does not have yet, best first).
std::string why_stop(const Diagnosis& D, const LoopResult& R, std::vector<FitRequest>& next) {
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
    return "something no library effect describes remains: " + D.outside_library.front().text;
  }
  if (found.empty()) return "nothing is missing: the diagnosis finds no significant effect";
  if (next.empty())
    return "the diagnosis names " + D.candidates[static_cast<std::size_t>(found.front())].label() +
           " again after it was fitted: the data cannot settle it";
  return {};
}

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

}  // namespace

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
      s.nodes = {f.lo - w, f.lo, f.hi, f.hi + w};
      s.values = {0.0, f.size, f.size, 0.0};
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

LoopResult run_loop(const io::DataSet& data, const ctl::MachineModel& model, const DiagnoseOptions& o, int max_steps) {
  LoopResult R;
  R.model = model;
  Diagnosis D = diagnose_any(data, model, o);
  record_model_as_given(R, D, data, model, o);
  for (int step = 0; step < max_steps; ++step) {
    std::vector<FitRequest> named;
    R.stop = why_stop(D, R, named);
    if (!R.stop.empty()) {
      R.outside_library = !D.outside_library.empty();
      if (R.outside_library) R.suggestion = suggest_user_effect(D.outside_library.front());
      return R;
    }
    std::string label;
    std::optional<Refit> F = first_that_lowers(data, model, R, named, o, label);
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
    o << std::string(s.added.empty() ? 16 : std::max<std::size_t>(2, 30 - s.added.size() - 2), ' ') << s.rms * k << " "
      << u << "  (" << (s.noise_floor > 0.0 ? s.rms / s.noise_floor : 0.0) << " x the noise floor " << s.noise_floor * k
      << " " << u << ")\n";
  }
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
  const SuggestedUserEffect& s = R.suggestion;
  if (!s.kind.empty()) {
    Json u = {{"kind", s.kind}, {"axis", s.axis + 1}};
    if (s.kind == "table") {
      u["input"] = s.input;
      u["nodes"] = s.nodes;
      u["values"] = s.values;
    } else {
      u["formula"] = s.formula;
      Json params = Json::object();
      for (const auto& [name, value] : s.params) params[name] = value;
      u["params"] = params;
    }
    u["text"] = s.text;
    o["suggested_user_effect"] = u;
  } else {
    o["suggested_user_effect"] = nullptr;
  }
  return o.dump(2, ' ', false, Json::error_handler_t::replace) + "\n";
}

std::string loop_html(const LoopResult& R, const std::string& data_file) {
  const bool m = R.units == "m";
  const double k = m ? 1e6 : 1.0;
  const std::string u = m ? "µm" : "N";
  // Bars: one per step, the noise floor as a dashed line across them.
  const double W = 120.0 + 110.0 * static_cast<double>(R.steps.size()), H = 300, l = 70, b = 70, t = 30;
  double top = 0.0;
  for (const auto& s : R.steps) top = std::max({top, s.rms * k, s.noise_floor * k});
  top = top > 0.0 ? top * 1.1 : 1.0;
  auto Y = [&](double v) { return H - b - (H - t - b) * v / top; };
  std::ostringstream o;
  o << "<!DOCTYPE html><html><head><meta charset='utf-8'><title>cpm loop: " << data_file
    << "</title><style>body{font-family:sans-serif;margin:18px;color:#222}</style></head><body>";
  o << "<h1>cpm loop: " << data_file << "</h1><p>Diagnose, add the effect found, refit, diagnose again. Residual RMS ("
    << u << ") of the model after each step; the dashed line is the noise floor the diagnosis estimates.</p>";
  o << "<svg xmlns='http://www.w3.org/2000/svg' width='" << W << "' height='" << H
    << "' style='background:#fff;border:1px solid #ddd'>";
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
    o << "<text x='" << x + 35 << "' y='" << H - b + 16 << "' font-size='10' text-anchor='middle'>"
      << (s.added.empty() ? "as given" : "+ " + s.added) << "</text>";
    const double f = s.noise_floor * k;
    o << "<line x1='" << x - 10 << "' x2='" << x + 80 << "' y1='" << Y(f) << "' y2='" << Y(f)
      << "' stroke='#d33' stroke-dasharray='4 3'/>";
  }
  o << "<text x='" << W - 12 << "' y='" << t - 10 << "' font-size='11' fill='#d33' text-anchor='end'>noise floor</text>";
  o << "</svg><p><b>Stop:</b> " << R.stop << "</p><ol start='0'>";
  for (const auto& s : R.steps)
    o << "<li>" << (s.added.empty() ? "model as given" : "+ " + s.added) << ": " << s.verdict << "</li>";
  o << "</ol></body></html>\n";
  return o.str();
}

}  // namespace cpm::ident
