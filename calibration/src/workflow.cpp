// SPDX-License-Identifier: Apache-2.0
#include "cpm/calibration/workflow.hpp"

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <numbers>
#include <sstream>

#include <nlohmann/json.hpp>

#include "cpm/kinematics/workspace.hpp"

namespace cpm::cal {
namespace {

constexpr double kDeg = 180.0 / std::numbers::pi;

std::string fmt(const char* f, double v) {
  char buf[64];
  std::snprintf(buf, sizeof buf, f, v);
  return buf;
}

std::string pad(const std::string& s, std::size_t w) {
  // Pads by display width: count UTF-8 lead bytes only (µ is two bytes).
  std::size_t n = 0;
  for (unsigned char ch : s) n += (ch & 0xC0) != 0x80;
  return n >= w ? s + " " : s + std::string(w - n, ' ');
}

std::string row_where(const io::FileInfo& info, std::size_t j) {
  const int line = j < info.line_of_row.size() ? info.line_of_row[j] : static_cast<int>(j) + 1;
  return info.path + ":" + std::to_string(line);
}

// Effective displacements d~ of the model's kinematic effects (backlash,
// cyclic error, thermal drift, actuator scale): the plane model then holds
// with d~ in place of d. Effects that tilt the planes cannot be calibrated
// under here.
std::vector<Vec3> effective(const kin::KinematicModel& m, const std::vector<Vec3>& d,
                            const io::CommonColumns& extra, std::vector<std::string>& warnings) {
  bool any = false, backlash = false, thermal = false;
  for (int i = 0; i < 3; ++i) {
    const kin::LimbKinematicEffects& e = m.effects[i];
    if (e.guide_ka != 0.0 || e.guide_kb != 0.0 || e.twist != 0.0)
      throw Error("limb " + std::to_string(i + 1) +
                  " of the model carries guide_angular_error or limb_twist: the plane calibration "
                  "cannot run under effects that tilt the planes; calibrate a model without them "
                  "and identify them afterwards (cpm fit)");
    any = any || e.any();
    backlash = backlash || e.backlash != 0.0;
    thermal = thermal || e.thermal_expansion != 0.0;
  }
  if (!any) return d;
  if (backlash && extra.dir.empty())
    warnings.push_back("the model has backlash but the data have no dir1..dir3 columns: every "
                       "axis is taken to have last moved in + direction");
  if (thermal && extra.t.empty())
    warnings.push_back("the model has thermal drift but the data have no t column: t = 0 (cold) is used");
  std::vector<Vec3> out(d.size());
  for (std::size_t j = 0; j < d.size(); ++j) {
    const double t = extra.t.empty() ? 0.0 : extra.t[j];
    for (int i = 0; i < 3; ++i) {
      const int dir = extra.dir.empty() ? +1 : extra.dir[j][static_cast<std::size_t>(i)];
      out[j][i] = kin::effective_displacement(m.effects[i], d[j][i], dir, t);
    }
  }
  return out;
}

void check_strokes(const ctl::MachineModel& m, const io::FileInfo& info, const std::vector<Vec3>& d) {
  for (std::size_t j = 0; j < d.size(); ++j)
    for (int i = 0; i < 3; ++i)
      if (d[j][i] < m.strokes.min[i] || d[j][i] > m.strokes.max[i]) {
        char buf[200];
        std::snprintf(buf, sizeof buf,
                      ": column 'd%d': %.6f m is outside actuator %d's stroke [%.4f, %.4f] m: "
                      "the machine cannot have been there (wrong units or wrong model?)",
                      i + 1, d[j][i], i + 1, m.strokes.min[i], m.strokes.max[i]);
        throw Error(row_where(info, j) + buf);
      }
}

std::string mm3(const Vec3& p) {
  char buf[96];
  std::snprintf(buf, sizeof buf, "(%.3f, %.3f, %.3f) mm", p.x() * 1e3, p.y() * 1e3, p.z() * 1e3);
  return buf;
}

void check_ballbar_rows(const ctl::MachineModel& m, const io::BallbarData& b,
                        const std::vector<Vec3>& de, double tol) {
  const std::size_t N = b.d.size();
  std::size_t bad = 0, first = 0;
  double first_nominal = 0.0;
  for (std::size_t j = 0; j < N; ++j) {
    if (!(b.length[j] > 0.0))
      throw Error(row_where(b.info, j) + ": column 'length': " + fmt("%g", b.length[j]) +
                  " m is not a bar length (must be > 0)");
    Vec3 p;
    if (Status s = kin::forward(m.kinematics, de[j], {}, p); !s)
      throw Error(row_where(b.info, j) + ": the model has no platform point for these readings: " + describe(s));
    const double nominal = (p - b.pivot).norm();
    if (std::abs(nominal - b.length[j]) > tol) {
      if (bad == 0) {
        first = j;
        first_nominal = nominal;
      }
      ++bad;
    }
  }
  if (bad == 0) return;
  const std::string reading = fmt("%.3f mm", b.length[first] * 1e3);
  const std::string dist = fmt("%.3f mm", first_nominal * 1e3);
  const std::string units = b.length[first] > 5.0 ? " (the lengths look like mm: the file must be in m)" : "";
  if (bad == N)
    throw Error(b.info.path + ": no pose reaches the pivot " + mm3(b.pivot) +
                " with these bar lengths: e.g. at " + row_where(b.info, first) + " the bar reads " +
                reading + " but the platform is " + dist +
                " from the pivot; check the `pivot` metadata (machine frame, m)" + units);
  throw Error(row_where(b.info, first) + ": column 'length': the bar reads " + reading +
              " but the platform is " + dist + " from the pivot " + mm3(b.pivot) + " (" +
              std::to_string(bad) + " of " + std::to_string(N) +
              " rows disagree by more than " + fmt("%.1f mm", tol * 1e3) +
              "): a bad row, or readings from another set-up" + units);
}

void check_position_rows(const ctl::MachineModel& m, const io::PositionData& pd,
                         const std::vector<Vec3>& de, double tol) {
  for (std::size_t j = 0; j < pd.d.size(); ++j) {
    Vec3 p;
    if (Status s = kin::forward(m.kinematics, de[j], {}, p); !s)
      throw Error(row_where(pd.info, j) + ": the model has no platform point for these readings: " + describe(s));
    if ((p - pd.p[j]).norm() > tol)
      throw Error(row_where(pd.info, j) + ": the measured point " + mm3(pd.p[j]) + " is " +
                  fmt("%.3f mm", (p - pd.p[j]).norm() * 1e3) +
                  " from where the model puts the platform " + mm3(p) +
                  ": the instrument's frame is not the machine frame, or the units are not m");
  }
}

// Replace earlier calibrations' entries in `fitted`.
void drop_previous(std::vector<io::FittedParameter>& f) {
  std::vector<io::FittedParameter> keep;
  for (auto& p : f) {
    const bool plane = p.name.rfind("kinematics.limb", 0) == 0 &&
                       (p.name.find(".normal.") != std::string::npos ||
                        p.name.ends_with(".scale") || p.name.ends_with(".offset"));
    if (!plane && p.name.rfind("ballbar.", 0) != 0) keep.push_back(std::move(p));
  }
  f = std::move(keep);
}

double se_or_unknown(double s) { return std::isfinite(s) ? s : -1.0; }

void add_plane_entries(io::ModelFile& out, const kin::KinematicModel& before,
                       const kin::KinematicModel& after, const std::array<Vec3, 3>& se_u,
                       const Vec3& se_c, const Vec3& se_n) {
  const char* ax = "xyz";
  for (int i = 0; i < 3; ++i) {
    const std::string limb = "kinematics.limb" + std::to_string(i + 1);
    for (int k = 0; k < 3; ++k)
      out.fitted.push_back({limb + ".normal." + ax[k], "1", before.planes[i].normal[k],
                            after.planes[i].normal[k], se_or_unknown(se_u[i][k])});
    out.fitted.push_back({limb + ".scale", "1", before.planes[i].scale, after.planes[i].scale,
                          se_or_unknown(se_c[i])});
    out.fitted.push_back({limb + ".offset", "m", before.planes[i].offset, after.planes[i].offset,
                          se_or_unknown(se_n[i])});
  }
}

// Kim's incident angle from the scale: gamma = acos(c) for c <= 1, and
// -acos(1/c) for c > 1 (an actuator that over-travels, which cos gamma cannot
// express, shows as a negative angle). Monotone in c and continuous at
// c = 1, so the standard error maps through the interval c -+ se.
double gamma_of_scale(double c) { return c <= 1.0 ? std::acos(std::max(-1.0, c)) : -std::acos(1.0 / c); }

std::pair<double, double> gamma_of(double c, double se) {
  const double g = gamma_of_scale(c);
  if (!std::isfinite(se)) return {g, INFINITY};
  return {g, 0.5 * (gamma_of_scale(c - se) - gamma_of_scale(c + se))};
}

// A parameter for people: rad in degrees, scales as ppm from 1, m in mm or µm.
std::string shown(const std::string& unit, const std::string& name, double v, bool deviation) {
  if (unit == "rad") return fmt("%+.5f deg", v * kDeg);
  if (unit == "1") return deviation ? fmt("%+.2f ppm", v * 1e6) : fmt("%+.2f ppm", (v - 1.0) * 1e6);
  if (unit == "m") return fmt("%+.3f µm", v * 1e6);
  (void)name;
  return fmt("%g", v);
}

}  // namespace

const Identifiability& CalibrationResult::identifiability() const {
  return ballbar ? ballbar->identifiability : position->identifiability;
}
const LmReport& CalibrationResult::convergence() const {
  return ballbar ? ballbar->lm : position->lm;
}
double CalibrationResult::residual_rms() const { return identifiability().residual_rms; }

CalibrationResult calibrate(const io::ModelFile& input, const io::DataSet& data,
                            const std::string& data_path, const std::string& data_sha256,
                            const std::string& tool, const CalibrationOptions& o) {
  const ctl::MachineModel& m = input.model;
  m.validate();
  CalibrationResult res;
  res.data_path = data_path;
  res.data_sha256 = data_sha256;
  res.model = input;
  drop_previous(res.model.fitted);
  kin::KinematicModel start = m.kinematics;
  // The fit starts from the nominal planes (the data decide); `before` keeps
  // the input's planes as the nominal values of the entries.
  const kin::KinematicModel before = m.kinematics;
  for (int i = 0; i < 3; ++i) start.planes[i] = kin::KinematicModel::nominal().planes[i];
  ctl::MachineModel nominal_machine = m;
  nominal_machine.kinematics.planes = start.planes;
  std::string note;
  if (const auto* b = std::get_if<io::BallbarData>(&data)) {
    res.kind = "ballbar";
    res.rows = static_cast<int>(b->d.size());
    res.warnings = b->info.warnings;
    check_strokes(m, b->info, b->d);
    const std::vector<Vec3> de = effective(m.kinematics, b->d, b->extra, res.warnings);
    check_ballbar_rows(nominal_machine, *b, de, o.consistency_tolerance);
    BallbarOptions bo;
    bo.lm = o.lm;
    bo.identifiability = o.identifiability;
    bo.length_offset_known = b->length_offset_known;
    BallbarFit fit = fit_ballbar(start, de, b->length, b->pivot, bo);
    res.warnings.insert(res.warnings.end(), fit.warnings.begin(), fit.warnings.end());
    add_plane_entries(res.model, before, fit.model, fit.normal_std_error, fit.scale_std_error,
                      fit.offset_std_error);
    const Identifiability& id = fit.identifiability;
    const char* bb_names[] = {"theta_z", "theta_x", "theta_y", "dq_x", "dq_y", "dq_z", "dl"};
    const char* file_names[] = {"ballbar.theta_z", "ballbar.theta_x", "ballbar.theta_y",
                                "ballbar.pivot_error.x", "ballbar.pivot_error.y",
                                "ballbar.pivot_error.z", "ballbar.length_offset"};
    for (int k = 0; k < 7; ++k) {
      const int j = id.index(bb_names[k]);
      if (j < 0) continue;
      res.model.fitted.push_back({file_names[k], id.units[static_cast<std::size_t>(j)], 0.0,
                                  id.value[j], se_or_unknown(id.std_error[j])});
    }
    note = "ball-bar, pivot " + mm3(b->pivot) + (b->length_offset_known ? ", bar length known" : ", bar length offset fitted");
    res.ballbar = std::move(fit);
    res.model.model.kinematics = res.ballbar->model;
  } else if (const auto* p = std::get_if<io::PositionData>(&data)) {
    res.kind = "position";
    res.rows = static_cast<int>(p->d.size());
    res.warnings = p->info.warnings;
    check_strokes(m, p->info, p->d);
    const std::vector<Vec3> de = effective(m.kinematics, p->d, p->extra, res.warnings);
    check_position_rows(nominal_machine, *p, de, o.consistency_tolerance);
    PositionOptions po;
    po.lm = o.lm;
    po.identifiability = o.identifiability;
    po.sigma = p->sigma;
    PositionFit fit = fit_positions(start, de, p->p, po);
    res.warnings.insert(res.warnings.end(), fit.warnings.begin(), fit.warnings.end());
    const Identifiability& id = fit.identifiability;
    Vec3 se_c, se_n;
    for (int i = 0; i < 3; ++i) {
      se_c[i] = id.std_error[4 * i + 2];
      se_n[i] = id.std_error[4 * i + 3];
    }
    add_plane_entries(res.model, before, fit.model, fit.normal_std_error, se_c, se_n);
    note = "full position";
    res.position = std::move(fit);
    res.model.model.kinematics = res.position->model;
  } else {
    throw Error(data_path + ": a motion log cannot calibrate the kinematics; give a ball-bar "
                            "(kind = ballbar) or full-position (kind = position) file");
  }
  res.model.model.validate();
  const Identifiability& id = res.identifiability();
  io::Provenance pv;
  pv.tool = tool;
  pv.data_file = data_path;
  pv.data_sha256 = data_sha256;
  pv.date = io::utc_now_iso8601();
  pv.note = "kinematic calibration (Kim 2005), " + note + ", " + std::to_string(res.rows) +
            " rows, residual RMS " + fmt("%.3f µm", id.residual_rms * 1e6) +
            (res.warnings.empty() ? "" : ", " + std::to_string(res.warnings.size()) + " warning(s)");
  res.model.history.push_back(pv);
  return res;
}

CalibrationResult calibrate_files(const std::string& model_path, const std::string& data_path,
                                  const std::string& out_path,
                                  const std::optional<std::string>& json_path,
                                  const std::string& tool, const CalibrationOptions& o) {
  namespace fs = std::filesystem;
  auto same = [](const std::string& a, const std::string& b) {
    std::error_code ec;
    return fs::weakly_canonical(a, ec) == fs::weakly_canonical(b, ec);
  };
  if (same(out_path, model_path))
    throw Error("--out " + out_path + " is the input model file: calibration never overwrites its input; give a new file name");
  if (same(out_path, data_path)) throw Error("--out " + out_path + " is the data file");
  if (json_path && (same(*json_path, model_path) || same(*json_path, data_path) || same(*json_path, out_path)))
    throw Error("--json " + *json_path + " is one of the other files");
  const io::ModelFile input = io::load_model_file(model_path);
  const io::DataSet data = io::read_data_file(data_path);
  CalibrationResult res = calibrate(input, data, data_path, io::sha256_file(data_path), tool, o);
  io::save_model_file(out_path, res.model, model_path);
  if (json_path) io::write_file_atomically(*json_path, res.json());
  return res;
}

std::string CalibrationResult::summary() const {
  std::ostringstream o;
  const Identifiability& id = identifiability();
  const LmReport& lm = convergence();
  o << (kind == "ballbar" ? "ball-bar" : "full-position") << " calibration (Kim 2005): " << rows
    << " rows from " << data_path << " (sha256 " << data_sha256.substr(0, 12) << "…)\n";
  o << "convergence: " << (lm.converged ? "converged" : "NOT converged") << " after " << lm.iterations
    << " iterations (" << lm.reason << ")\n";
  o << "  cost 1/2|r|^2 " << fmt("%.4g", lm.initial_cost) << " -> " << fmt("%.4g", lm.final_cost)
    << " m^2, gradient |J^T r| " << fmt("%.3g", lm.gradient_norm) << " m (cosine "
    << fmt("%.2g", lm.gradient_cosine) << "), last step " << fmt("%.3g", lm.last_step_norm) << " (scaled)\n";
  o << "residual RMS " << fmt("%.3f µm", id.residual_rms * 1e6) << ", noise estimate s "
    << fmt("%.3f µm", id.residual_sigma * 1e6) << " (" << id.dof << " degrees of freedom)\n\n";
  o << pad("parameter", 14) << pad("fitted", 18) << pad("std error", 16)
    << fmt("%.0f%% interval\n", id.confidence * 100);
  for (std::size_t j = 0; j < id.names.size(); ++j) {
    const auto k = static_cast<Eigen::Index>(j);
    const std::string& u = id.units[j];
    const bool scale = u == "1";
    o << pad(id.names[j] + (scale ? "-1" : ""), 14) << pad(shown(u, id.names[j], id.value[k], false), 18)
      << pad(std::isfinite(id.std_error[k]) ? shown(u, id.names[j], id.std_error[k], true).substr(1)
                                             : "undetermined",
             16)
      << "[" << shown(u, id.names[j], id.ci_low[k], false) << ", "
      << shown(u, id.names[j], id.ci_high[k], false) << "]\n";
  }
  o << "\nidentifiability: condition number of the (column-scaled) Jacobian "
    << fmt("%.4g", id.condition_number) << "; singular values";
  for (Eigen::Index k = 0; k < id.singular_values.size(); ++k) o << ' ' << fmt("%.3g", id.singular_values[k]);
  o << '\n';
  if (id.strong_pairs.empty()) {
    o << "no pair of parameters correlated beyond 0.9\n";
  } else {
    o << "strongly correlated pairs:";
    for (const CorrelatedPair& c : id.strong_pairs)
      o << ' ' << id.names[static_cast<std::size_t>(c.a)] << '/' << id.names[static_cast<std::size_t>(c.b)]
        << fmt(" (%+.3f)", c.correlation);
    o << '\n';
  }
  const kin::KinematicModel& km = model.model.kinematics;
  o << "\ncalibrated planes in the machine frame"
    << (kind == "ballbar" ? " (axes: best fit to the three limb normals; origin: fitted pivot on the declared pivot)" : "")
    << ":\nlimb  normal u                           scale c-1 (ppm)   offset n (µm)\n";
  for (int i = 0; i < 3; ++i) {
    const kin::LimbPlane& pl = km.planes[i];
    o << pad(std::to_string(i + 1), 4) << "  (" << fmt("%+.7f", pl.normal.x()) << ", " << fmt("%+.7f", pl.normal.y())
      << ", " << fmt("%+.7f", pl.normal.z()) << ")  " << fmt("%+12.2f", (pl.scale - 1.0) * 1e6)
      << "   " << fmt("%+12.3f", pl.offset * 1e6) << '\n';
  }
  if (!warnings.empty()) {
    o << "\nWARNINGS:\n";
    for (const std::string& w : warnings) o << "  - " << w << '\n';
  }
  return o.str();
}

namespace {

using Json = nlohmann::ordered_json;

Json vec_json(const Vec3& v) { return Json::array({v[0], v[1], v[2]}); }

// The correlation matrix to 4 decimals (what a person compares), rounded as printf rounds.
Json correlation_json(const MatX& c) {
  Json rows = Json::array();
  for (Eigen::Index a = 0; a < c.rows(); ++a) {
    Json row = Json::array();
    for (Eigen::Index b = 0; b < c.cols(); ++b) row.push_back(std::strtod(fmt("%.4f", c(a, b)).c_str(), nullptr));
    rows.push_back(std::move(row));
  }
  return rows;
}

Json identifiability_json(const Identifiability& id) {
  Json pairs = Json::array();
  for (const CorrelatedPair& c : id.strong_pairs)
    pairs.push_back({{"a", id.names[static_cast<std::size_t>(c.a)]},
                     {"b", id.names[static_cast<std::size_t>(c.b)]},
                     {"correlation", c.correlation}});
  return {{"names", id.names},
          {"singular_values", std::vector<double>(id.singular_values.begin(), id.singular_values.end())},
          {"condition_number", id.condition_number},
          {"confidence", id.confidence},
          {"dof", id.dof},
          {"correlation", correlation_json(id.correlation)},
          {"strong_pairs", pairs}};
}

Json convergence_json(const LmReport& lm) {
  return {{"converged", lm.converged},         {"reason", lm.reason},
          {"iterations", lm.iterations},       {"evaluations", lm.evaluations},
          {"initial_cost", lm.initial_cost},   {"final_cost", lm.final_cost},
          {"gradient_norm", lm.gradient_norm}, {"gradient_cosine", lm.gradient_cosine},
          {"last_step_norm", lm.last_step_norm}};
}

// One fitted parameter j of the identifiability analysis, with its interval.
Json fitted_json(const Identifiability& id, int j) {
  return {{"value", id.value[j]}, {"stderr", id.std_error[j]}, {"ci_low", id.ci_low[j]},
          {"ci_high", id.ci_high[j]}, {"unit", id.units[static_cast<std::size_t>(j)]}};
}

Json derived_json(const Json& value, const Json& std_error, const char* unit) {
  return {{"value", value}, {"stderr", std_error}, {"unit", unit}};
}

// A ball-bar fit's own parameters: the limb angles gamma (from the scales),
// the scales, the frame's rotation and the pivot's offset, the bar's offset.
void add_ballbar_parameters(Json& params, const Identifiability& id) {
  for (int i = 0; i < 3; ++i) {
    const int j = id.index("c" + std::to_string(i + 1));
    const auto [g, gs] = gamma_of(id.value[j], id.std_error[j]);
    params["gamma" + std::to_string(i + 1)] = derived_json(g, gs, "rad");
  }
  for (const char* n : {"c1", "c2", "c3", "theta_z", "theta_x", "theta_y", "dq_x", "dq_y", "dq_z"})
    params[n] = fitted_json(id, id.index(n));
  if (id.index("dl") >= 0) params["dl"] = fitted_json(id, id.index("dl"));
  else params["dl"] = {{"value", 0}, {"stderr", 0}, {"fixed", true}, {"unit", "m"}};
}

// The machine-frame planes (for a ball-bar: after the frame choice, named
// "machine.c1" ...), and for full positions the plane rotations fitted.
Json parameters_json(const CalibrationResult& r) {
  const Identifiability& id = r.identifiability();
  Json params = Json::object();
  if (r.ballbar) add_ballbar_parameters(params, id);
  const kin::KinematicModel& km = r.model.model.kinematics;
  const std::string pre = r.ballbar ? "machine." : "";
  for (int i = 0; i < 3; ++i) {
    const std::string s = std::to_string(i + 1);
    if (r.ballbar) {
      params[pre + "c" + s] = derived_json(km.planes[i].scale, r.ballbar->scale_std_error[i], "1");
      params[pre + "n" + s] = derived_json(km.planes[i].offset, r.ballbar->offset_std_error[i], "m");
    } else {
      params["c" + s] = fitted_json(id, 4 * i + 2);
      params["n" + s] = fitted_json(id, 4 * i + 3);
    }
    const Vec3& se_u = r.ballbar ? r.ballbar->normal_std_error[i] : r.position->normal_std_error[i];
    params[pre + "u" + s] = derived_json(vec_json(km.planes[i].normal), vec_json(se_u), "1");
  }
  if (!r.ballbar)
    for (int j = 0; j < 12; ++j)
      if (id.units[static_cast<std::size_t>(j)] == "rad") params[id.names[static_cast<std::size_t>(j)]] = fitted_json(id, j);
  return params;
}

}  // namespace

std::string CalibrationResult::json() const {
  const Identifiability& id = identifiability();
  const Json o = {{"kind", kind},
                  {"rows", rows},
                  {"data_file", data_path},
                  {"data_sha256", data_sha256},
                  {"residual_rms", id.residual_rms},
                  {"residual_sigma", id.residual_sigma},
                  {"parameters", parameters_json(*this)},
                  {"convergence", convergence_json(convergence())},
                  {"identifiability", identifiability_json(id)},
                  {"warnings", warnings}};
  return o.dump(2, ' ', false, Json::error_handler_t::replace) + "\n";
}

}  // namespace cpm::cal
