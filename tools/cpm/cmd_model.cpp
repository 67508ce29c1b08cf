// SPDX-License-Identifier: Apache-2.0
// cpm model check|show|init: validate a model file, print it for a person
// (mm, µm, degrees, labelled), or write the nominal machine as a new file.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <numbers>
#include <string>

#include "cli.hpp"
#include "cpm/io/model_file.hpp"

namespace cpm::cli {
namespace {

constexpr double kDeg = 180.0 / std::numbers::pi;

// A value in the unit a person reads best, labelled.
std::string shown(double v, const std::string& unit) {
  char buf[64];
  if (unit == "m") {
    if (std::abs(v) >= 1e-3 || v == 0.0)
      std::snprintf(buf, sizeof buf, "%.4f mm", v * 1e3);
    else
      std::snprintf(buf, sizeof buf, "%.3f µm", v * 1e6);
  } else if (unit == "rad") {
    std::snprintf(buf, sizeof buf, "%.5f deg", v * kDeg);
  } else if (unit == "rad/m") {
    std::snprintf(buf, sizeof buf, "%.5f deg/m", v * kDeg);
  } else if (unit == "m/s") {
    std::snprintf(buf, sizeof buf, "%.4g mm/s", v * 1e3);
  } else if (unit == "1") {
    std::snprintf(buf, sizeof buf, "%.2f ppm", v * 1e6);
  } else {
    std::snprintf(buf, sizeof buf, "%.6g %s", v, unit.c_str());
  }
  return buf;
}

void show(const io::ModelFile& mf) {
  const ctl::MachineModel& m = mf.model;
  const kin::KinematicModel& km = m.kinematics;
  const kin::LimbGeometry& g = km.limbs;
  std::printf("geometry      L %.3f mm, L1 %.3f mm, L2 %.3f mm, D %.3f mm, singularity margin %.2f deg\n",
              g.L * 1e3, g.L1 * 1e3, g.L2 * 1e3, g.D * 1e3, g.singularity_margin * kDeg);
  std::printf("masses        m1 %.7g kg, m2 %.7g kg, m3 %.7g kg, m4 %.7g kg\n", m.masses.m1,
              m.masses.m2, m.masses.m3, m.masses.m4);
  std::printf("force limit   %.6g N per actuator\n\n", m.force_limit);
  std::printf("limb mode  d0 (mm)   stroke (mm)          normal u                        tilt (deg)"
              "  scale c - 1 (ppm)  offset n (µm)\n");
  for (int i = 0; i < 3; ++i) {
    const kin::LimbPlane& pl = km.planes[i];
    const double tilt = std::acos(std::min(1.0, pl.normal[i])) * kDeg;
    std::printf("%-4d %+-4d  %8.4f  [%8.4f, %8.4f]  (%9.6f, %9.6f, %9.6f)  %10.5f  %17.2f  %13.3f\n",
                i + 1, g.mode[i], km.d0[i] * 1e3, m.strokes.min[i] * 1e3, m.strokes.max[i] * 1e3,
                pl.normal.x(), pl.normal.y(), pl.normal.z(), tilt, (pl.scale - 1.0) * 1e6,
                pl.offset * 1e6);
  }
  std::printf("\nkinematic effects:");
  bool any = false;
  for (int i = 0; i < 3; ++i)
    for (int t = 0; t < kin::kKinematicEffectTypes; ++t) {
      const auto type = static_cast<kin::KinematicEffectType>(t);
      const kin::KinematicEffectInfo& in = kin::info(type);
      const auto v = kin::get_params(km.effects[i], type);
      bool present = false;
      for (int j = 0; j < in.n_params; ++j) present |= v[j] != 0.0;
      if (!present) continue;
      std::printf("\n  limb %d  %-20s", i + 1, in.name);
      for (int j = 0; j < in.n_params; ++j)
        std::printf("  %s = %s", in.params[j].name, shown(v[j], in.params[j].unit).c_str());
      any = true;
    }
  std::printf("%s\n", any ? "" : " none");
  std::printf("dynamic effects:");
  for (const ctl::DynamicEffect& e : m.effects) {
    const ctl::DynamicEffectInfo& in = ctl::info(e.type);
    std::printf("\n  %-28s", e.label().c_str());
    for (int j = 0; j < in.n_params; ++j)
      std::printf("  %s = %s", in.params[j].name, shown(e.param[j], in.params[j].unit).c_str());
  }
  std::printf("%s\n", m.effects.size() ? "" : " none");
  // User effects (docs/effects.md, "Effects you add"), in mm and µm on screen.
  bool user = !m.user_effects.empty();
  for (int i = 0; i < 3; ++i) user |= !km.effects[i].pitch_table.empty();
  if (user) std::printf("user effects:");
  for (const ctl::UserEffect& e : m.user_effects) {
    if (e.kind == ctl::UserEffectKind::table) {
      std::printf("\n  table on axis %d against %s: %zu nodes, %s to %s, force %.4g to %.4g N", e.axis + 1,
                  e.input_name().c_str(), e.nodes.size(), shown(e.nodes.front(), e.input == 'd' ? "m" : "m/s").c_str(),
                  shown(e.nodes.back(), e.input == 'd' ? "m" : "m/s").c_str(),
                  *std::min_element(e.values.begin(), e.values.end()), *std::max_element(e.values.begin(), e.values.end()));
    } else {
      std::printf("\n  expression on axis %d: %s (N)", e.axis + 1, e.formula.c_str());
      for (const ctl::UserParameter& p : e.params) std::printf("  %s = %.6g %s", p.name.c_str(), p.value, p.unit.c_str());
    }
  }
  for (int i = 0; i < 3; ++i) {
    const kin::PitchTable& t = km.effects[i].pitch_table;
    if (t.empty()) continue;
    double lo = t.error[0], hi = t.error[0];
    for (int k = 0; k < t.size; ++k) {
      lo = std::min(lo, t.error[k]);
      hi = std::max(hi, t.error[k]);
    }
    std::printf("\n  pitch_table on axis %d: %d nodes, %s to %s, error %s to %s", i + 1, t.size,
                shown(t.node[0], "m").c_str(), shown(t.node[t.size - 1], "m").c_str(), shown(lo, "m").c_str(),
                shown(hi, "m").c_str());
  }
  if (user) std::printf("\n");
  if (!mf.fitted.empty()) {
    std::printf("\nfitted parameters (%zu):\n  %-40s %16s %16s %16s %16s\n", mf.fitted.size(), "name",
                "nominal", "value", "change", "std. error");
    for (const io::FittedParameter& p : mf.fitted) {
      // A dimensionless value reads as itself; its change and error in ppm.
      char nom[32], val[32];
      std::snprintf(nom, sizeof nom, "%.10g", p.nominal);
      std::snprintf(val, sizeof val, "%.10g", p.value);
      const bool plain = p.unit == "1";
      std::printf("  %-40s %16s %16s %16s %16s\n", p.name.c_str(),
                  plain ? nom : shown(p.nominal, p.unit).c_str(), plain ? val : shown(p.value, p.unit).c_str(),
                  shown(p.value - p.nominal, p.unit).c_str(),
                  p.std_error < 0 ? "unknown" : shown(p.std_error, p.unit).c_str());
    }
  }
  if (!mf.history.empty()) {
    std::printf("\nhistory (oldest first):\n");
    for (const io::Provenance& h : mf.history) {
      std::printf("  %s  %s", h.date.c_str(), h.tool.c_str());
      if (!h.data_file.empty())
        std::printf("  data %s%s%.12s", h.data_file.c_str(), h.data_sha256.empty() ? "" : " sha256 ",
                    h.data_sha256.c_str());
      if (!h.note.empty()) std::printf("  (%s)", h.note.c_str());
      std::printf("\n");
    }
  }
}

struct Options {
  std::string action, file;
  bool force = false;
};

int run(const Options& o) {
  const bool force = o.force;
  const std::string& action = o.action;
  const std::string& file = o.file;
  if (action == "init") {
    if (std::filesystem::exists(file) && !force)
      throw UsageError(file + " exists; give --force to replace it");
    io::ModelFile mf;
    mf.history.push_back({"cpm model init", "", "", io::utc_now_iso8601(),
                          "the nominal machine (docs/model.md)"});
    io::save_model_file(file, mf);
    std::printf("%s: wrote the nominal machine model\n", file.c_str());
    return 0;
  }
  io::ModelFile mf;
  try {
    mf = io::load_model_file(file);
  } catch (const Error& e) {
    std::fprintf(stderr, "%s\n%s: INVALID\n", e.what(), file.c_str());
    return 1;
  }
  int n_kin = 0;
  for (const auto& e : mf.model.kinematics.effects)
    for (int t = 0; t < kin::kKinematicEffectTypes; ++t) {
      const auto v = kin::get_params(e, static_cast<kin::KinematicEffectType>(t));
      n_kin += (v[0] != 0.0 || v[1] != 0.0 || v[2] != 0.0);
    }
  std::printf("%s: valid model (%d kinematic effect%s, %d dynamic effect%s, %zu fitted parameter%s, "
              "%zu history entr%s)\n",
              file.c_str(), n_kin, n_kin == 1 ? "" : "s", mf.model.effects.size(),
              mf.model.effects.size() == 1 ? "" : "s", mf.fitted.size(), mf.fitted.size() == 1 ? "" : "s",
              mf.history.size(), mf.history.size() == 1 ? "y" : "ies");
  std::size_t n_user = mf.model.user_effects.size();
  for (const auto& e : mf.model.kinematics.effects) n_user += e.pitch_table.empty() ? 0 : 1;
  if (n_user > 0) std::printf("  with %zu user effect%s (table, expression, pitch_table)\n", n_user, n_user == 1 ? "" : "s");
  if (action == "show") {
    std::printf("\n");
    show(mf);
  }
  return 0;
}

Run setup(CLI::App& app) {
  auto o = std::make_shared<Options>();
  app.add_option("ACTION", o->action,
                 "check: validate FILE (exit 1 with the error on a bad file); show: validate and print it (mm, µm, "
                 "degrees, ppm); init: write the nominal machine to FILE")
      ->check(CLI::IsMember({"check", "show", "init"}).description(""))
      ->type_name("check|show|init")
      ->required();
  app.add_option("FILE", o->file, "the model file (model-file.md)")->type_name("FILE.yaml")->required();
  app.add_flag("--force", o->force, "init: replace FILE when it exists");
  return [o] { return run(*o); };
}

const Command reg{"model", "check or show a model file, or write the nominal one", setup};

}  // namespace
}  // namespace cpm::cli
