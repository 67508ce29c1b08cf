// SPDX-License-Identifier: Apache-2.0
#include "cpm/sim/table3.hpp"

namespace cpm::sim {

std::array<Table3Row, 4> reproduce_table3() {
  using ctl::ControlLaw;
  std::array<Table3Row, 4> rows = {{
      {ControlLaw::pd, {}, {}, {}, 2.7e-3, 0.0223, 2.886e-3},
      {ControlLaw::pd_gravity, {}, {}, {}, 3.4804e-4, 0.021, 3.980e-4},
      {ControlLaw::pd_feedforward, {}, {}, {}, 3.0256e-4, 0.0182, 3.101e-4},
      {ControlLaw::computed_torque, {}, {}, {}, 2.3469e-4, 0.0161, 1.973e-4},
  }};
  const ctl::Machine machine(ctl::MachineModel::elkady());
  const ctl::CircleTrajectory circle(ctl::CircleSpec{});
  LoopOptions loop;
  loop.rate_hz = 1000.0;
  loop.duration = 4.0;
  loop.keep_log = false;
  PlantOptions plant_options;
  plant_options.substeps = 10;
  for (Table3Row& row : rows) {
    row.gains = ctl::table3_gains(row.law);
    const ctl::Controller controller(machine, row.law, row.gains);
    Plant plant(machine, plant_options);
    const RunResult r = run_closed_loop(controller, plant, circle, loop);
    row.metrics = r.metrics;
    row.fault = r.fault;
  }
  return rows;
}

}  // namespace cpm::sim
