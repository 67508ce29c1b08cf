// SPDX-License-Identifier: Apache-2.0
// Simulated measurements: what an instrument would read on a true machine
// commanded through a controller's model (docs/model.md, issue 3):
//   d = IK_controller(p_commanded)      the encoder readings the drives settle at
//   p_true = FK_truth(d)                where the real platform then is
//   ball-bar: length = |p_true - pivot_true| - dl_true + noise
//   position: p = p_true + noise (each coordinate)
// Static poses: the servo has settled, so no dynamics is involved.
#pragma once

#include <cstdint>
#include <vector>

#include "cpm/control/machine.hpp"
#include "cpm/io/data_files.hpp"

namespace cpm::cal {

enum class NoiseShape { gaussian, uniform };

struct Noise {
  NoiseShape shape = NoiseShape::gaussian;
  double size = 0.0;        // standard deviation (gaussian) or half-width (uniform), m
  std::uint64_t seed = 1;
  [[nodiscard]] double sigma() const;  // standard deviation either way (m)
};

struct SimulatedPose {
  Vec3 commanded = Vec3::Zero();
  Vec3 d = Vec3::Zero();       // encoder readings (m)
  Vec3 p_true = Vec3::Zero();  // true platform point (m), truth's frame
};

// Throws Error naming the pose and the reason when a commanded point is
// outside the controller's workspace or the truth cannot reach it.
// `inputs` (empty, or one per pose): the direction each axis last moved and
// the time of each pose, for a truth with backlash or thermal drift; the
// controller sees the same inputs.
std::vector<SimulatedPose> simulate_poses(const ctl::MachineModel& truth,
                                          const ctl::MachineModel& controller,
                                          const std::vector<Vec3>& commanded,
                                          const std::vector<kin::KinematicInputs>& inputs = {});

// The inputs of visiting the poses in order, `dwell` seconds apart from
// `t0`: each axis' direction is that of its move into the pose (the first
// pose and an axis that does not move keep the previous one, initially +1).
std::vector<kin::KinematicInputs> sequence_inputs(const ctl::MachineModel& controller,
                                                  const std::vector<Vec3>& commanded,
                                                  double dwell, double t0 = 0.0);

struct BallbarSimulation {
  Vec3 pivot_nominal = Vec3(0.430, 0.430, 0.530);  // declared in the file (m)
  Vec3 pivot_true = Vec3(0.430, 0.430, 0.530);     // where the fixed ball really is, truth's frame (m)
  double length_offset = 0.0;                      // dl_true (m): reading = true distance - dl
  bool length_offset_known = true;                 // written to the file's metadata
  Noise noise;
  // One per pose, or empty: see simulate_poses. When given, the file gets
  // the columns t and dir1..dir3.
  std::vector<kin::KinematicInputs> inputs;
};

io::BallbarData simulate_ballbar(const ctl::MachineModel& truth, const ctl::MachineModel& controller,
                                 const std::vector<Vec3>& commanded, const BallbarSimulation& sim);

io::PositionData simulate_positions(const ctl::MachineModel& truth,
                                    const ctl::MachineModel& controller,
                                    const std::vector<Vec3>& commanded, const Noise& noise,
                                    const std::vector<kin::KinematicInputs>& inputs = {});

}  // namespace cpm::cal
