// SPDX-License-Identifier: Apache-2.0
// The JSON that programs read (cpm compare / diagnose --json; docs/identification.md
// documents the diagnosis' fields). Built with nlohmann::ordered_json, so keys
// keep the order written here; numbers are written shortest-exact, and a number
// that is not finite is written as null.
#include <cmath>

#include <nlohmann/json.hpp>

#include "cpm/identification/kinematic.hpp"
#include "cpm/identification/report.hpp"
#include "internal.hpp"

namespace cpm::ident {
namespace {

using Json = nlohmann::ordered_json;

// Pretty-printed; a byte that is not UTF-8 in a file name or a note becomes U+FFFD instead of an exception.
std::string dumped(const Json& j) { return j.dump(2, ' ', false, Json::error_handler_t::replace) + "\n"; }

// Axis numbers as people count them (1..3), null for none.
Json axis_json(int axis) { return axis >= 0 ? Json(axis + 1) : Json(); }

Json vec_json(const Vec3& v) { return Json::array({v[0], v[1], v[2]}); }

// A standard error, null when there is none (negative).
Json std_error_json(double se) { return se >= 0 ? Json(se) : Json(); }

// A candidate's parameters by name (SI units), their standard errors and units.
Json params_json(const CandidateResult& c) {
  Json o = Json::object();
  for (const auto& p : c.params) o[p.name] = p.value;
  return o;
}

Json std_errors_json(const CandidateResult& c) {
  Json o = Json::object();
  for (const auto& p : c.params) o[p.name] = std_error_json(p.std_error);
  return o;
}

Json units_json(const CandidateResult& c) {
  Json o = Json::object();
  for (const auto& p : c.params) o[p.name] = p.unit;
  return o;
}

Json confounder_json(const Confounder& cf) {
  return {{"with", cf.with},
          {"effect", cf.effect.empty() ? Json() : Json(cf.effect)},
          {"axis", axis_json(cf.axis)},
          {"correlation", cf.correlation},
          {"separate_by", cf.separate_by}};
}

Json candidate_json(const CandidateResult& c) {
  Json with = Json::array();
  for (const auto& cf : c.confounded) with.push_back(confounder_json(cf));
  return {{"effect", c.effect},
          {"axis", axis_json(c.axis)},
          {"params", params_json(c)},
          {"std_errors", std_errors_json(c)},
          {"units", units_json(c)},
          {"rms_after", c.rms_after},
          {"explained", c.explained},
          {"explained_beyond_base", c.explained_beyond_base},
          {"significant", c.significant},
          {"identifiable", c.identifiable},
          {"f_stat", c.f_stat},
          {"p_value", c.p_value},
          {"p_adjusted", c.p_adjusted},
          {"delta_bic", c.delta_bic},
          {"n_params", c.n_params},
          {"refits_base", c.refits_base},
          {"note", c.note},
          {"confounded_with", with}};
}

// An effect the verdict names, with its parameters and what else would fit.
Json named_effect_json(const CandidateResult& c) {
  const std::string implausible = detail::implausible(c);
  return {{"effect", c.effect},
          {"axis", axis_json(c.axis)},
          {"params", params_json(c)},
          {"std_errors", std_errors_json(c)},
          {"implausible", implausible.empty() ? Json() : Json(implausible)},
          {"alternatives", c.alternatives}};
}

Json structure_json(const std::vector<StructureFinding>& items) {
  Json a = Json::array();
  for (const auto& f : items) {
    Json j = {{"kind", f.kind},
              {"axis", axis_json(f.axis)},
              {"coordinate", f.coordinate},
              {"location", f.location},
              {"size", f.size},
              {"z", f.z},
              {"text", f.text}};
    if (f.kind == "smooth") {
      j["smooth"] = {{"range", {f.lo, f.hi}}, {"shape", f.shape}, {"slope", f.slope},
                     {"nodes", f.nodes}, {"values", f.values}, {"also_in", f.also_in}};
      // Why each is alike: correlation with the finding's variable, share of its fit.
      Json alike = Json::array();
      for (const AlikeVariable& w : f.alike)
        alike.push_back({{"variable", w.var}, {"correlation", w.correlation}, {"share", w.share}});
      j["smooth"]["alike"] = std::move(alike);
    }
    if (f.kind == "position_friction")
      j["position_friction"] = {{"range", {f.lo, f.hi}}, {"nodes", f.nodes}, {"levels", f.values}};
    a.push_back(std::move(j));
  }
  return a;
}

// What is missing: an effect of the library, structure outside it, or nothing.
Json verdict_json(const Diagnosis& D) {
  Json v;
  if (!D.outside_library.empty()) {
    v = {{"missing", "outside_library"}, {"axis", axis_json(D.outside_library.front().axis)}};
  } else if (D.verdict >= 0) {
    const auto& c = D.candidates[static_cast<std::size_t>(D.verdict)];
    v = {{"missing", c.effect}, {"axis", axis_json(c.axis)}};
  } else {
    v = {{"missing", nullptr}, {"axis", nullptr}};
  }
  v["ambiguous"] = D.ambiguous;
  Json also = Json::array();
  for (int j : D.also) {
    const auto& c = D.candidates[static_cast<std::size_t>(j)];
    also.push_back({{"effect", c.effect}, {"axis", axis_json(c.axis)}});
  }
  v["also"] = std::move(also);
  // Every effect named, best first.
  Json effects = Json::array();
  for (int j : D.found()) effects.push_back(named_effect_json(D.candidates[static_cast<std::size_t>(j)]));
  v["effects"] = std::move(effects);
  // Structure no library effect describes that leads the verdict (missing = "outside_library").
  v["outside_library"] = structure_json(D.outside_library);
  // Library effects that explain part of the outside finding, not named beside it (labels).
  v["partial"] = D.partial;
  // Of those, the ones fitted beside it to a value outside the physical range, with the value.
  Json unphysical = Json::array();
  for (const auto& u : D.partial_unphysical) {
    Json params = Json::object(), errors = Json::object();
    for (const auto& p : u.params) {
      params[p.name] = p.value;
      errors[p.name] = p.std_error >= 0.0 ? Json(p.std_error) : Json();
    }
    unphysical.push_back({{"effect", u.effect}, {"axis", axis_json(u.axis)}, {"params", params},
                          {"std_errors", errors}, {"why", u.why}});
  }
  v["partial_unphysical"] = std::move(unphysical);
  // User effects that would describe it, as model-file data (user_effects:).
  Json user = Json::array();
  for (const auto& u : D.suggested_user_effects) {
    Json j = {{"kind", u.kind}, {"axis", axis_json(u.axis)}, {"rms_after", u.rms_after}, {"text", u.text}};
    if (u.kind == "expression") {
      j["formula"] = u.formula;
      Json params = Json::object();
      for (const auto& [name, value] : u.params) params[name] = value;
      j["params"] = std::move(params);
    } else {
      if (!u.input.empty()) j["input"] = u.input;
      j["nodes"] = u.nodes;
      j["values"] = u.values;
    }
    user.push_back(std::move(j));
  }
  v["suggested_user_effects"] = std::move(user);
  v["text"] = D.verdict_text;
  return v;
}

// Motion logs: how the acceleration was estimated and how force and motion were aligned.
void add_motion_inputs(Json& o, const Diagnosis& D) {
  const MotionProblem& P = D.motion;
  const Alignment& a = D.alignment;
  o["acceleration"] = {{"source", P.accel_source},
                       {"filter_half_width_samples", P.half_width},
                       {"force_noise", P.force_noise.maxCoeff()}};
  o["alignment"] = {{"tau", a.tau},
                    {"std_error", std_error_json(a.std_error)},
                    {"periods", a.tau / a.period},
                    {"period", a.period},
                    {"model_tau", a.model_tau},
                    {"missing_tau", a.missing()},
                    {"convention", a.convention()}};
}

// Mean and RMS per bin, for each axis.
Json bins_json(const std::array<ResidualSummary::Bins, 3>& bins) {
  Json a = Json::array();
  for (const auto& B : bins) a.push_back({{"centre", B.centre}, {"mean", B.mean}, {"rms", B.rms}});
  return a;
}

}  // namespace

std::string summary_json(const ResidualSummary& s, const MotionProblem& P, const std::string& data_file,
                         const std::string& model_file, int samples) {
  Json o = {{"kind", "motion"}, {"data_file", data_file}, {"model_file", model_file},
            {"samples", samples}, {"rows", 3 * P.rows()}, {"units", "N"}};
  o["acceleration"] = {{"source", P.accel_source},
                       {"filter_half_width_samples", P.half_width},
                       {"force_noise", vec_json(P.force_noise)}};
  o["rms"] = s.rms;
  o["max"] = s.max;
  o["axis_rms"] = vec_json(s.axis_rms);
  o["axis_max"] = vec_json(s.axis_max);
  o["rms_forward"] = vec_json(s.rms_forward);
  o["rms_backward"] = vec_json(s.rms_backward);
  o["mean_forward"] = vec_json(s.mean_forward);
  o["mean_backward"] = vec_json(s.mean_backward);
  o["along_position"] = bins_json(s.along_position);
  o["over_time"] = bins_json(s.over_time);
  o["fit_percent"] = std::isfinite(s.fit_percent.sum()) ? vec_json(s.fit_percent) : Json();
  return dumped(o);
}

std::string diagnosis_json(const Diagnosis& D) {
  Json o = {{"kind", D.kind}, {"samples", D.samples}, {"rows", D.rows}, {"units", D.units},
            {"data_file", D.data_file}, {"model_file", D.model_file}};
  if (D.kind == "motion") add_motion_inputs(o, D);
  o["baseline"] = {{"rms", D.baseline_rms}, {"max", D.baseline_max}, {"axis_rms", vec_json(D.baseline_axis_rms)}};
  o["base_refit"] = {{"rms", D.base_refit_rms}};
  o["noise_floor"] = D.noise_floor;
  // Where the floor comes from (repeated poses, the bar's high band, the residual's high band, ...).
  o["noise_floor_source"] = D.noise_floor_source;
  o["noise_floor_upper_bound"] = D.noise_floor_upper_bound;
  if (!D.smooth_detectability.empty()) {
    // Kinematic data: the smooth error of each axis' reading these data can show (m, peak to peak).
    Json sd = Json::array();
    for (const auto& b : D.smooth_detectability)
      sd.push_back({{"axis", b.axis + 1}, {"missed_below", b.missed_below}, {"found_above", b.found_above},
                    {"told_above", std::isfinite(b.told_above) ? Json(b.told_above) : Json(nullptr)},
                    {"confused_with", b.confused_with}});
    o["smooth_detectability"] = std::move(sd);
  }
  if (D.kind == "motion") {
    o["axis_noise_floor"] = vec_json(D.axis_floor);
    o["axis_residual_rms"] = vec_json(D.axis_residual_rms);
  }
  Json candidates = Json::array();
  for (const auto& c : D.candidates) candidates.push_back(candidate_json(c));
  o["candidates"] = std::move(candidates);
  o["verdict"] = verdict_json(D);
  o["structure"] = structure_json(D.structure);
  o["notes"] = D.notes;
  o["warnings"] = D.warnings;
  return dumped(o);
}

std::string kinematic_summary_json(const KinematicProblem& P, const KinematicSummary& s, const std::string& model_file) {
  Json o = {{"kind", P.kind}, {"data_file", P.data_file}, {"model_file", model_file},
            {"samples", P.samples()}, {"rows", P.rows()}, {"units", "m"},
            {"rms", s.rms}, {"max", s.max}, {"component_rms", vec_json(s.component_rms)}};
  if (P.has_dir)
    o["by_direction"] = {{"rms_forward", vec_json(s.rms_forward)}, {"rms_backward", vec_json(s.rms_backward)},
                         {"mean_forward", vec_json(s.mean_forward)}, {"mean_backward", vec_json(s.mean_backward)}};
  if (s.circle) {
    const auto& c = *s.circle;
    o["circle"] = {{"plane", cal::plane_name(c.spec.plane)}, {"radius", c.spec.radius},
                   {"G", c.G_bidirectional}, {"G_ccw", c.ccw_metrics.G}, {"G_cw", c.cw_metrics.G},
                   {"H", c.H}, {"F_max", c.F_max}, {"F_min", c.F_min}};
  }
  return dumped(o);
}

}  // namespace cpm::ident
