// SPDX-License-Identifier: Apache-2.0
// Calibration from files, as `cpm calibrate` runs it: read the model file and
// a measurement file (docs/data-formats.md: kind = ballbar or position), check
// every row, fit, and produce the new model file (nominal values, fitted
// values, standard errors, provenance with the data file's SHA-256) and the
// reports. Nothing is written unless everything succeeded.
#pragma once

#include <optional>
#include <string>
#include <vector>

#include "cpm/calibration/ballbar.hpp"
#include "cpm/calibration/position.hpp"
#include "cpm/io/data_files.hpp"
#include "cpm/io/model_file.hpp"

namespace cpm::cal {

struct CalibrationOptions {
  // Rows whose reading disagrees with the nominal model by more than this are
  // refused as inconsistent (wrong pivot, wrong frame, mm for m): m.
  double consistency_tolerance = 0.005;
  LmOptions lm;
  IdentifiabilityOptions identifiability;
};

struct CalibrationResult {
  std::string kind;                   // "ballbar" or "position"
  std::optional<BallbarFit> ballbar;
  std::optional<PositionFit> position;
  io::ModelFile model;                // the new model file's content
  std::vector<std::string> warnings;  // data file warnings + fit warnings
  int rows = 0;
  std::string data_path, data_sha256;

  [[nodiscard]] const Identifiability& identifiability() const;
  [[nodiscard]] const LmReport& convergence() const;
  [[nodiscard]] double residual_rms() const;  // m
  // The human summary (mm, µm, degrees, labelled).
  [[nodiscard]] std::string summary() const;
  // The machine-readable summary: kind, residual_rms, parameters {name:
  // {value, stderr}} in SI units, warnings, convergence, identifiability.
  [[nodiscard]] std::string json() const;
};

// Calibrate `input` from a data set already read. `data_path` and
// `data_sha256` go into the provenance. Throws Error (with the file, line and
// column where there is one) on bad input; DegeneratePoses on a pose set that
// cannot determine the parameters.
CalibrationResult calibrate(const io::ModelFile& input, const io::DataSet& data,
                            const std::string& data_path, const std::string& data_sha256,
                            const std::string& tool, const CalibrationOptions& options = {});

// The whole command: read, calibrate, write `out_path` (never `model_path`)
// and, when given, the JSON. On any error nothing is written.
CalibrationResult calibrate_files(const std::string& model_path, const std::string& data_path,
                                  const std::string& out_path,
                                  const std::optional<std::string>& json_path,
                                  const std::string& tool, const CalibrationOptions& options = {});

}  // namespace cpm::cal
