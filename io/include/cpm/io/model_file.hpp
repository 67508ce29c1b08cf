// SPDX-License-Identifier: Apache-2.0
// The YAML model file (docs/model-file.md): the machine's nominal
// parameters and every calibrated or identified addition, in one
// human-readable file. The default machine model is config/machine.yaml.
//
// A tool that fits something writes a new model file (never the input in
// place; temporary file, fsync, rename), keeping the nominal values, the
// fitted values, their standard errors and where they came from (data file
// name and SHA-256, date, tool).
#pragma once

#include <optional>
#include <string>
#include <vector>

#include "cpm/control/machine.hpp"

namespace cpm::io {

// One fitted parameter. `name` is the parameter's path in the file, e.g.
// "kinematics.limb2.scale", "kinematics.limb1.normal.y",
// "effects.coulomb_friction.axis3.f_c", "ballbar.pivot_error.z".
struct FittedParameter {
  std::string name;
  std::string unit;
  double nominal = 0.0;
  double value = 0.0;
  double std_error = -1.0;  // < 0: unknown
};

struct Provenance {
  std::string tool;         // e.g. "cpm calibrate --method ballbar"
  std::string data_file;    // as given on the command line
  std::string data_sha256;  // hex
  std::string date;         // ISO 8601, UTC
  std::string note;
};

struct ModelFile {
  ctl::MachineModel model = ctl::MachineModel::elkady();
  std::vector<FittedParameter> fitted;
  std::vector<Provenance> history;  // oldest first
};

// A model file refused. what() is the whole message for the local user
// (file:line:column: key.path: reason, quoting what was read); `line` and
// `summary` are what may be told to a stranger (cpmd's answer over LCM): the
// line (1-based, 0 when none) and the reason, without a byte of the file.
struct ModelFileError : Error {
  ModelFileError(const std::string& full, int line_, std::string summary_)
      : Error(full), line(line_), summary(std::move(summary_)) {}
  int line;
  std::string summary;
};

// Load and validate. Errors (ModelFileError) say the file, the key path and
// the reason:
//   "model.yaml:12:10: kinematics.limb2.scale: expected a number, got 'abc'"
// Unknown keys, missing required keys, wrong types and out-of-range values
// are refused. load_model_file's Error when the file cannot be read is a plain Error.
ModelFile load_model_file(const std::string& path);
ModelFile parse_model_file(const std::string& text, const std::string& name);
// Render and write atomically. Refuses (Error) when `path` is `forbid_path`
// (the input a tool read from), so no tool overwrites its input.
std::string render_model_file(const ModelFile& m);
void save_model_file(const std::string& path, const ModelFile& m,
                     const std::string& forbid_path = "");

// SHA-256 of a file's bytes, lowercase hex (provenance).
std::string sha256_file(const std::string& path);
// Now as ISO 8601 UTC, e.g. "2026-11-22T05:20:00Z".
std::string utc_now_iso8601();
// The history entry of a tool that fitted `data_file` now: its SHA-256 and
// today's date filled in (data_file may be empty: no hash then).
Provenance make_provenance(const std::string& tool, const std::string& data_file,
                           const std::string& note = "");

// Write text to path atomically: temporary file beside it, fsync, rename.
// On any failure the old file is left intact and Error says why.
void write_file_atomically(const std::string& path, const std::string& text);

}  // namespace cpm::io
