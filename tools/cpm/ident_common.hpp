// Options shared by the identification subcommands (compare, diagnose, fit,
// loop): the measurements, the model judged, the motion logs' filter, and
// the new model file fit and loop write. Not a subcommand itself.
#pragma once

#include <optional>
#include <string>

#include "cli.hpp"
#include "cpm/identification/motion.hpp"

namespace cpm::cli {

struct MeasurementOptions {
  std::string data;
  std::optional<std::string> model;
  double window_ms = ident::MotionOptions{}.half_window * 1e3;
  [[nodiscard]] std::string model_path() const { return model_or_default(model); }
  [[nodiscard]] double half_window() const { return window_ms * 1e-3; }  // s
};

// --data FILE.csv (required), --model MODEL.yaml, --window MS.
inline void add_measurement_options(CLI::App& app, MeasurementOptions& m, const std::string& model_what) {
  app.add_option("--data", m.data,
                 "the measurements: a motion log, ball-bar or position data (data-formats.md), or an lcm-logger file "
                 "of cpmd's state")
      ->type_name("FILE.csv")
      ->required();
  add_model_option(app, m.model, model_what);
  add_number(app, "--window", m.window_ms, "MS", "half width of the motion logs' smoothing filter in ms");
}

// --out NEW_MODEL.yaml (required) of fit and loop.
inline void add_new_model_option(CLI::App& app, std::string& out) {
  app.add_option("--out", out, "the new model file (the input model is never overwritten)")
      ->type_name("NEW_MODEL.yaml")
      ->required();
}

}  // namespace cpm::cli
