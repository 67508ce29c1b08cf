// SPDX-License-Identifier: Apache-2.0
// cpm export-comp / import-comp: a pitch_table (docs/effects.md, "Effects
// you add") as LinuxCNC's screw-compensation file and back
// (io/linuxcnc_comp.hpp has the format and the conversion).
#include <cstdio>
#include <fstream>
#include <memory>
#include <sstream>

#include "cli.hpp"
#include "cpm/io/linuxcnc_comp.hpp"
#include "cpm/io/model_file.hpp"

namespace cpm::cli {
namespace {

struct Options {
  std::optional<std::string> model;
  int axis = 1, type = 0;
  std::string units = "mm", file, out;
};

std::string read_text(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw Error(path + ": cannot be read");
  std::ostringstream os;
  os << in.rdbuf();
  return os.str();
}

void add_common(CLI::App& app, Options& o) {
  app.add_option("--axis", o.axis, "the axis (joint) of the table, 1..3")->check(CLI::Range(1, 3))->required();
  app.add_option("--type", o.type, "LinuxCNC's COMP_FILE_TYPE: 0 = forward/reverse positions, 1 = trims")
      ->check(CLI::Range(0, 1));
  add_choice(app, "--units", o.units, {"mm", "inch"}, "the machine units of the file (LinuxCNC's LINEAR_UNITS)");
}

Run setup_export(CLI::App& app) {
  auto o = std::make_shared<Options>();
  add_model_option(app, o->model, "the model holding the pitch_table");
  add_common(app, *o);
  app.add_option("FILE", o->file, "the compensation file to write (COMP_FILE of the joint's INI section)")
      ->required();
  app.footer("The file holds one 'nominal forward reverse' triplet per line and no comment (LinuxCNC's loader\n"
             "stops at the first line that is not three numbers). Set COMP_FILE_TYPE in the INI to --type.");
  return [o] {
    const io::ModelFile mf = io::load_model_file(model_or_default(o->model));
    const kin::PitchTable& t = mf.model.kinematics.effects[static_cast<std::size_t>(o->axis - 1)].pitch_table;
    if (t.empty()) throw Error("the model has no pitch_table on axis " + std::to_string(o->axis));
    const io::CompUnits u = io::comp_units(o->units);
    write_file_atomically(o->file, io::render_linuxcnc_comp(t, o->type, u));
    std::printf("%s: %d lines, axis %d, %s, COMP_FILE_TYPE = %d\n", o->file.c_str(), t.size, o->axis, u.name, o->type);
    return 0;
  };
}

Run setup_import(CLI::App& app) {
  auto o = std::make_shared<Options>();
  add_model_option(app, o->model, "the model to add the pitch_table to");
  add_common(app, *o);
  app.add_option("FILE", o->file, "LinuxCNC's compensation file")->required()->check(CLI::ExistingFile);
  app.add_option("--out", o->out, "the new model file (never the input)")->type_name("NEW.yaml")->required();
  return [o] {
    const std::string model_path = model_or_default(o->model);
    io::ModelFile mf = io::load_model_file(model_path);
    const io::CompUnits u = io::comp_units(o->units);
    const io::ImportedComp c = io::parse_linuxcnc_comp(read_text(o->file), o->file, o->type, u);
    mf.model.kinematics.effects[static_cast<std::size_t>(o->axis - 1)].pitch_table = c.table;
    mf.history.push_back(io::make_provenance("cpm import-comp", o->file,
                                             "LinuxCNC compensation file, " + std::string(u.name) + ", COMP_FILE_TYPE " +
                                                 std::to_string(o->type) + ", axis " + std::to_string(o->axis)));
    io::save_model_file(o->out, mf, model_path);
    std::printf("pitch_table on axis %d: %d nodes from %.4f to %.4f mm\n", o->axis, c.table.size,
                c.table.node[0] * 1e3, c.table.node[static_cast<std::size_t>(c.table.size - 1)] * 1e3);
    for (const auto& n : c.notes) std::printf("note: %s\n", n.c_str());
    std::printf("new model: %s\n", o->out.c_str());
    return 0;
  };
}

const Command reg_export{"export-comp", "write an axis' pitch_table as LinuxCNC's screw-compensation file",
                         setup_export};
const Command reg_import{"import-comp", "read LinuxCNC's screw-compensation file into an axis' pitch_table",
                         setup_import};

}  // namespace
}  // namespace cpm::cli
