// SPDX-License-Identifier: Apache-2.0
// An independent motion-log generator: the yardstick against which
// `cpm diagnose` is judged on logs it did not make itself.
//
// Written apart from the project's simulator (sim::Plant,
// sim::run_closed_loop, tests/identification/sim_data.hpp) and from
// identification/ (its filters and kernels): its own time integration (RK4
// on a fixed fine step that lands exactly on every instant where the applied
// force switches), its own excitation (per axis a sum of three sines at
// incommensurate frequencies, ramped in from rest), its own controller (PD
// plus the nominal model's feed-forward in task space) and its own
// conventions for when the logged force acts and where the noise enters.
// Only the rigid-body physics of the true machine is shared
// (ctl::Machine: M, G, K, J, the effect forces, the drive gain).
//
// Timing of the logged force f_k (docs/data-formats.md, "Timing of the force column"):
//   sampled  - the controller is continuous (evaluated at every RK4 stage);
//              the drive applies that continuous force; the log records it at t_k.
//   zoh      - f_k is computed at t_k and applied over [t_k, t_k+1).
//   delay1   - f_k is applied over [t_k + T, t_k+1 + T).
//   delay1_5 - f_k is applied over [t_k + 1.5T, t_k+1 + 1.5T) (the switch
//              falls inside a period).
// Before the first command the drive holds f_0 (the machine rests under it).
//
// Noise placement:
//   plant    - a disturbance force, white per sample period (constant over
//              [t_k, t_k+1)), enters the plant; the log holds exactly the command.
//   command  - no disturbance; the log holds the command plus white noise
//              (a logger measuring the force).
// In both the logged d and v carry white encoder noise and the controller
// acts on those noisy readings.
#pragma once

#include <array>
#include <cstdint>
#include <string>
#include <vector>

#include "cpm/control/machine.hpp"
#include "cpm/io/data_files.hpp"

namespace cpm::indep {

enum class Timing { sampled, zoh, delay1, delay1_5 };
enum class NoisePlacement { plant, command };

const char* timing_name(Timing t) noexcept;            // "sampled", "zoh", "delay1", "delay1_5"
const char* noise_name(NoisePlacement n) noexcept;     // "plant", "command"
Timing timing_from_name(const std::string& s);         // throws Error on an unknown name
NoisePlacement noise_from_name(const std::string& s);
// Delay of the applied force behind the logged one, in sample periods:
// 0 (sampled, zoh), 1, 1.5.
double delay_periods(Timing t) noexcept;

struct PlantedEffect {
  std::string name;             // docs/effects.md name
  int axis = -1;                // 0..2, -1 for machine-wide effects
  std::vector<double> values;   // in the order and units of docs/effects.md
};

// A force on the true machine that no effect of docs/effects.md describes
// (the open world), resisting like the library's effect forces (subtracted
// from the drive's force on its axis):
//   cross_velocity: size * v_from (size in N s/m): a cable carrier or a
//                   bellows dragged along by another axis' carriage;
//   bump:           size * exp(-((d_axis - centre) / width)^2 / 2) (N): a tight
//                   spot over a short stretch of one guide;
//   cubic:          size * ((d_axis - centre) / width)^3 (N): a force that grows
//                   along the travel (a guide that narrows, a cable's pull);
//   velocity_hump:  size * u * exp((1 - u^2) / 2), u = v_axis / width (N): a
//                   force of the axis' own speed that rises like viscous
//                   friction, peaks (at `size`) at |v| = width and dies away
//                   above (a wiper seal, a lubricant film that lifts);
//   cross_velocity_hump: the same in v_from on `axis` (a carrier dragged at
//                   low speed only);
//   position_friction: size * (0.65 + 0.35 u) * tanh(v_axis / 2 mm/s), u =
//                   (d_axis - centre) / width (N): a dry friction that opposes
//                   the motion in both directions with a level that rises
//                   along the travel (guide wear, a lubricant that thins
//                   towards one end: a friction map), positive everywhere for
//                   |u| <= 1 (0.3 size to size over centre -+ width).
struct OutsideForce {
  enum class Kind { cross_velocity, bump, cubic, velocity_hump, cross_velocity_hump, position_friction };
  Kind kind = Kind::cubic;
  int axis = 0;          // 0..2: the axis the force acts on
  int from_axis = -1;    // cross_velocity, cross_velocity_hump: the axis whose velocity it follows
  double size = 0.0;     // N s/m (cross_velocity) or N
  double centre = 0.0;   // m (bump, cubic, position_friction)
  double width = 1.0;    // m (bump, cubic, position_friction); m/s (the humps)
};
// "cross_velocity", "bump", "cubic", "velocity_hump", "cross_velocity_hump", "position_friction"
const char* outside_kind_name(OutsideForce::Kind k) noexcept;
// The velocity the force follows (0..2), or -1 when it follows a position.
int outside_velocity_axis(const OutsideForce& f) noexcept;
// Their sum per axis at the actuator state (d, v) (N).
Vec3 outside_forces(const std::vector<OutsideForce>& forces, const Vec3& d, const Vec3& v);

struct GeneratorSpec {
  Timing timing = Timing::zoh;
  NoisePlacement noise = NoisePlacement::plant;
  double rate = 1000.0;                // Hz
  double duration = 20.0;              // s of log
  std::uint64_t seed = 1;
  std::vector<PlantedEffect> effects;  // on the true machine
  // User effects on the true machine, in ctl::add_user_effect's short form
  // (table:..., expression:...): the generator's plant takes the effect
  // forces at the state, so a formula may not read a1..a3 and sees t = 0.
  std::vector<std::string> user_effects;
  std::vector<OutsideForce> outside;   // on the true machine, beyond the library
  // The path: the seed's sines (0), or a circle of this radius (m) in the xy
  // plane at circle_omega (rad/s), axis 3 still (Excitation).
  double circle_radius = 0.0, circle_omega = 1.0;
  double disturbance_sigma = 0.3;      // N per axis, per sample period (plant noise)
  double force_noise_sigma = 0.3;      // N per axis, white on the logged force (command noise)
  double position_noise = 1e-6;        // m, white on logged d
  double velocity_noise = 2e-4;        // m/s, white on logged v
  double max_step = 25e-6;             // s: the internal step is T / n, n even, T / n <= max_step
  // Task-space PD gains (per unit platform mass-free: N/m, N s/m).
  double kp = 4000.0, kd = 200.0;
};

// Everything the generator knows, for tests: the log plus the truth behind it.
struct GeneratedLog {
  io::MotionData log;               // what a user would bring (t, d, v, f noisy as specified)
  std::vector<Vec3> commanded;      // the controller's output at t_k (clamped), noise-free
  std::vector<Vec3> applied_mean;   // mean drive input over [t_k, t_k+1) (before the drive gain)
  std::vector<Vec3> disturbance;    // plant disturbance over [t_k, t_k+1) (0 for command noise)
  std::vector<Vec3> d_true, v_true; // the true state at t_k
  double step = 0.0;                // internal step (s)
  int substeps = 0;                 // internal steps per sample period
  double max_abs_force = 0.0;       // largest |f| commanded (N)
  Vec3 d_min = Vec3::Zero(), d_max = Vec3::Zero();  // true actuator range reached (m)
};

// The machine with `effects` planted on Elkady's nominal model.
ctl::MachineModel true_model(const std::vector<PlantedEffect>& effects);

// Runs the closed loop and writes the log. Throws Error if the platform leaves
// the strokes or the limbs cannot reach a pose.
GeneratedLog generate(const GeneratorSpec& spec);

// The reference: a smooth excitation centred at p = (0.425, 0.425, 0.36).
struct Reference {
  Vec3 p, v, a;
};
class Excitation {
 public:
  explicit Excitation(std::uint64_t seed);
  // A circle in the xy plane instead: p = centre + s(t) (R sin wt, R cos wt, 0),
  // grown from rest at the centre by the same ramp (axis 3 holds still; after
  // the ramp v1 = w (d2 - centre): the two cannot be told apart).
  Excitation(double radius, double omega);
  [[nodiscard]] Reference operator()(double t) const noexcept;

 private:
  double phase_[3][3] = {};
  double radius_ = 0.0, omega_ = 0.0;  // m, rad/s: the circle when radius_ > 0
};
Reference excitation(double t, std::uint64_t seed);

}  // namespace cpm::indep
