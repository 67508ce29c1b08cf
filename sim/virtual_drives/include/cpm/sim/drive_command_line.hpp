// SPDX-License-Identifier: Apache-2.0
// The command-line options that virtual-drives and canopennode-drives share
// (CLI11): where the drives are, the true machine, the rate, node ids and
// scaling. Header-only: the programs link cpm_program_cli for CLI11.
#pragma once

#include <CLI/CLI.hpp>
#include <string>
#include <vector>

#include "cpm/io/model_file.hpp"
#include "cpm/program_cli.hpp"
#include "cpm/sim/virtual_machine.hpp"

namespace cpm::sim {

struct DriveCommandLine {
  std::string interface, model = "builtin:elkady", control;
  double rate = 1000;  // Hz
  VirtualMachineConfig cfg = VirtualMachineConfig::defaults();

  // After the parse: the configuration with the period of the rate, and the
  // true machine (the model file, or the nominal machine for builtin:elkady).
  [[nodiscard]] VirtualMachineConfig config() const {
    VirtualMachineConfig c = cfg;
    c.period = 1.0 / rate;
    return c;
  }
  [[nodiscard]] ctl::MachineModel true_machine() const {
    return model == "builtin:elkady" ? ctl::MachineModel::elkady() : io::load_model_file(model).model;
  }
};

inline void add_drive_options(CLI::App& app, DriveCommandLine& d) {
  app.add_option("--interface", d.interface, "the SocketCAN interface (e.g. vcan0)")->type_name("IF")->required();
  app.add_option("--model", d.model, "the true machine: a model file (model-file.md), or builtin:elkady (the nominal one)")
      ->type_name("FILE");
  app.add_option("--rate", d.rate, "control rate in Hz: the plant advances 1/HZ s per SYNC (at most 10000)")
      ->type_name("HZ")
      ->check((CLI::PositiveNumber & CLI::Range(0.0, 10000.0)).description(""));
  app.add_option_function<std::vector<int>>(
         "--nodes",
         [&d](const std::vector<int>& v) {
           for (std::size_t k = 0; k < 3; ++k) d.cfg.axes[k].node_id = v[k];
         },
         "node ids of the drives of actuators 1, 2, 3")
      ->type_name("A,B,C")
      ->delimiter(',')
      ->expected(3)
      ->check(CLI::Range(1, 127).description(""))
      ->default_str("1,2,3");
  // A scaling of every axis's drive.
  auto scaling = [&app, &d](const char* name, double hal::pdo::Scaling::*field, const char* help) {
    app.add_option_function<double>(
           name, [&d, field](double v) {
             for (auto& ax : d.cfg.axes) ax.scaling.*field = v;
           },
           help)
        ->type_name("N")
        ->check(program::finite())
        ->default_str(CLI::detail::to_string(d.cfg.axes[0].scaling.*field));
  };
  scaling("--counts-per-m", &hal::pdo::Scaling::counts_per_m, "0x6064 position counts per metre (velocity in counts/s)");
  scaling("--rated-force", &hal::pdo::Scaling::rated_force_n, "the force of 1000 per mille of 0x6071, in N");
  app.add_option("--control", d.control,
                 "a UNIX stream socket for fault-injection commands (docs/canopen-backend.md)")
      ->type_name("PATH");
}

}  // namespace cpm::sim
