// SPDX-License-Identifier: Apache-2.0
// The stages of prepare_motion (motion.hpp), in the order it runs them:
//   1. sampling: input checks, sample period, segments (read_sampling);
//   2. acceleration source: noise of the logged positions and velocities,
//      the kernels, and which derivative the acceleration comes from
//      (choose_acceleration);
//   3. the per-sample zero-phase state d_hat / v_hat (estimate_sample_states);
//   4. the kept rows: filtered state, acceleration, the force at every whole
//      shift, the columns' long-kernel acceleration, the force-gain
//      instrument's cubic (kept_samples, force_instrument, filter_kept_rows);
//   5. the base columns: A..E, the model's own effects, the plane nuisance,
//      the rigid-body force, the model force and the residual
//      (base_parameters, nuisance_parameters, rigid_body_force, ...).
// Not a public header: the types are what one stage hands the next.
#pragma once

#include <functional>
#include <string>
#include <vector>

#include <Eigen/Dense>

#include "cpm/control/machine.hpp"
#include "cpm/identification/filter.hpp"
#include "cpm/identification/motion.hpp"
#include "cpm/io/data_files.hpp"

namespace cpm::ident::motion_stages {

// "path" of the log, or "motion log" when it has none.
std::string log_name(const io::MotionData& data);
// "path:line" of sample k (0-based), or "path (sample k+1)" when its line is unknown.
std::string where(const io::MotionData& data, int k);

// ---- Stage 1: sampling ----------------------------------------------------

struct Sampling {
  double dt = 0.0;                    // s: median step between samples of one run
  std::vector<int> segment_start;     // per sample: first sample of its segment
  std::vector<int> segment_end;       // per sample: one past the last sample of its segment
  int segments = 0;
  std::vector<std::string> warnings;  // one per sampling gap inside a run ("path:line: sampling gap ...")
};

// Checks the columns (equal lengths, at least 10 samples) and the time
// (increasing within a run), takes the median step as the period, and cuts a
// segment at every new run and every step more than dt/4 off the period.
// Throws Error naming the file (and the line, for time that does not increase).
Sampling read_sampling(const io::MotionData& data);

// m: the zero-phase kernel's half width in samples for the options'
// half window at period dt (s); throws when the degree does not fit in it.
int kernel_half_width(const io::MotionData& data, double dt, const MotionOptions& opt);

// ---- Stage 2: noise and acceleration source ----------------------------------

// Savitzky-Golay kernels of one half width and degree evaluated half a sample
// after the centre (the state of a row, t_k + dt/2): smoothing, 1st and 2nd
// derivative (per sample^r).
struct HalfSampleKernels {
  SgKernel smooth, d1, d2;
  static HalfSampleKernels make(int half_width, int order);
};

struct AccelerationEstimate {
  enum class Source { measured, velocity, position };
  Source source = Source::velocity;      // a1..a3, d/dt of v, or d^2/dt^2 of d
  bool velocity_from_positions = false;  // the rows' v from d (else v smoothed)
  int half_width = 0;                    // m (samples)
  SgKernel at_sample, d1_at_sample;      // offset 0: smoothing, 1st derivative
  HalfSampleKernels half;                // offset 1/2
  Vec3 position_noise = Vec3::Zero();    // white noise of the logged d (m)
  Vec3 velocity_noise = Vec3::Zero();    // white noise of the logged v (m/s)
  Vec3 accel_noise = Vec3::Zero();       // what the chosen estimate adds (m/s^2)
  SgKernel accel_kernel;                 // the kernel that makes the acceleration
  SgKernel smooth_force;                 // filter of the commanded force
  SgKernel smooth_state;                 // filter of the effect columns
  std::string text;                      // MotionProblem::accel_source
};

// White-noise sigma of a series from what a zero-phase smoother removes,
// robust to the few samples where the motion itself is sharp.
double smoother_noise(const std::vector<double>& x, const SgKernel& s);

// Estimates the noise of the logged positions and velocities and picks,
// unless the options force it, the acceleration (and, separately, the rows'
// velocity) source that adds less noise; measured a1..a3 when the log has them.
AccelerationEstimate choose_acceleration(const io::MotionData& data, double dt, int half_width,
                                         const MotionOptions& opt);

// The acceleration of axis i at sample k's row (m/s^2) from the estimate's
// source with kernels `h` (A.half, or the columns' longer ones).
double acceleration_at(const io::MotionData& data, const AccelerationEstimate& A, const HalfSampleKernels& h,
                       double dt, int k, int i);

// ---- Stage 3: per-sample state ----------------------------------------------------

struct SampleStates {
  std::vector<Vec3> d_hat, v_hat;     // per sample (m, m/s)
  Vec3 v_hat_noise = Vec3::Zero();    // noise of v_hat (m/s)
};

// Zero-phase estimate at every sample with a short kernel (inside each
// segment; off-centre within m samples of its ends; raw values in a segment
// shorter than the kernel).
SampleStates estimate_sample_states(const io::MotionData& data, const Sampling& S, const AccelerationEstimate& A,
                                    const MotionOptions& opt);

// ---- Stage 4: kept rows ---------------------------------------------------------

// Where the force-gain instrument (MotionProblem::f_past) reads the force:
// `samples` on each side of the row's window, and the least-squares cubic
// through them.
struct ForceInstrument {
  int samples = 0;         // on each side
  int past_gap = 0;        // samples between the earlier ones and the row's sample
  int future_gap = 0;      // samples between the row's sample and the later ones
  std::vector<int> around; // offsets from the row's sample, earlier ones first
  Eigen::MatrixXd fit;     // 4 x around.size(): cubic coefficients (in samples) from the values
};
ForceInstrument force_instrument(int half_width);

// Samples of the kept rows: every `stride` samples inside each segment, where
// both passes' windows, every shift of the force and the instrument fit in it.
std::vector<int> kept_samples(const Sampling& S, int half_width, int stride, int instrument_samples);

// Refuses a log with fewer kept rows (P.sample) than opt.min_rows, saying
// how long a piece of motion would do.
void check_enough_rows(const io::MotionData& data, const MotionProblem& P, int instrument_samples,
                       const MotionOptions& opt);

// Fills the kept rows of P (P.sample, P.dt, P.drive_gain, P.smooth_force set):
// t, d, v, a, f, f_predicted (sized), f_past, force_at_shift, a_columns.
void filter_kept_rows(const io::MotionData& data, const Sampling& S, const AccelerationEstimate& A,
                      const ForceInstrument& instrument, const MotionOptions& opt, MotionProblem& P);

// ---- Stage 5: base columns -----------------------------------------------------

// Fills P's base_params, base, platform_force, model_force (rigid body with
// P.a + the model's own effects), the residual at the model's own
// actuation_delay and force_noise. The rows of stage 4 must be in P.
void add_base_columns(const io::MotionData& data, const ctl::Machine& model, const MotionOptions& opt,
                      MotionProblem& P);

// The model with A, B, C and E each one unit larger (inertia_error), in that order.
std::vector<ctl::Machine> unit_inertia_machines(const ctl::MachineModel& mm);

// A, B, C, E of the model, then the linear parameters of its own effects
// (the force gain's included; payload and inertia error are inside A..E).
std::vector<BaseParameter> model_base_parameters(const ctl::Machine& model);

// A machine with a plane perturbed by `step` (rad or m): a nuisance column is
// (its force - the model's) / step.
struct Perturbation {
  ctl::Machine machine;
  double step = 0.0;
};
// Appends the nuisance parameters of `kind` to `params` and returns the
// perturbed machines of those evaluated by difference (tilt: two tilts and
// the offset of each plane; coupling: none, its columns are the platform
// force itself).
std::vector<Perturbation> nuisance_parameters(const ctl::MachineModel& mm, MotionOptions::Nuisance kind,
                                              std::vector<BaseParameter>& params);

// Per kept row: the direction each axis last moved (from v_hat) and the time.
std::vector<kin::KinematicInputs> row_kinematic_inputs(const MotionProblem& P);

// The rigid body at one row of a machine.
struct RigidBodyRow {
  ctl::TaskState ts;       // platform pose, velocity, J
  Vec3 p_dd;               // platform acceleration (m/s^2)
  Vec3 platform_force;     // M p_dd + G p_dot + K (N)
};
// The rigid-body actuator force J^T (M p_dd + G p_dot + K) of `machine` at
// every kept row of P with the accelerations `acc` (3 rows per kept row, N);
// each_row, when given, sees every row's terms. Throws Error naming the file
// and line of a row the machine cannot follow.
Eigen::VectorXd rigid_body_force(const ctl::Machine& machine, const io::MotionData& data, const MotionProblem& P,
                                 const std::vector<kin::KinematicInputs>& kin_in, const std::vector<Vec3>& acc,
                                 const std::function<void(int, const RigidBodyRow&)>& each_row = {});

}  // namespace cpm::ident::motion_stages
