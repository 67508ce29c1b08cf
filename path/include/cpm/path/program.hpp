// SPDX-License-Identifier: Apache-2.0
// A G-code program from text to a checked plan in one call: read (every
// fault with line and column), checked against the workspace and the soft
// limits, turned into the planner's queue, planned with the limits the
// daemon uses, and the plan checked again at every knot. What `cpm run`
// does before anything is sent (and prints with --dry-run), what
// cpm-path-report reads its program with, and (planner_options,
// check_plan) what cpmd does with a program it receives.
//
// Frame and units: the machine frame (m, z down) and SI, as the rest of
// cpm_path; the program in its own units and frame (gcode.hpp).
#pragma once

#include <optional>
#include <string>
#include <string_view>

#include "cpm/path/gcode.hpp"
#include "cpm/path/plan.hpp"

namespace cpm::path {

// The daemon's limits as planning needs them (cpmd.yaml's limits.*).
struct MachineLimits {
  double velocity = 0.5;      // limits.velocity (m/s): the platform's speed and each actuator's
  double acceleration = 5.0;  // limits.acceleration (m/s^2): |a| of a cartesian_only plan
  double force = 120.0;       // limits.force (N); the model's force limit caps it
  SoftLimits soft;            // limits.workspace_min/max (machine frame, m)
};

// The planner's options for these limits and this model: |v| and each
// actuator's speed within `velocity`; each actuator's force within
// min(force, the model's force_limit) less the planner's reserve; the
// actuators' acceleration is the planner's default (the drives', not
// limits.acceleration, which bounds |a| of cartesian_only plans only: an
// actuator-aware plan takes corners harder than that, within the forces).
PlannerOptions planner_options(const MachineLimits& limits, const ctl::Machine& machine,
                               PlanMode mode = PlanMode::actuator_aware, double jerk = 1000.0);

// Where a plan leaves the workspace or the soft limits, first knot only.
struct PlanFault {
  double t = 0.0;         // s from the plan's start
  Vec3 p = Vec3::Zero();  // machine frame (m)
  int segment = -1;       // programmed segment (PathQueue::segments())
  int line = 0;           // its program line (0: none)
  std::string why;        // soft_limit_text's words, or the workspace check's
};

// Every knot of the plan (and its end) against the machine's workspace
// (kin::check_pose: strokes, limbs' reach, singularity) and the soft
// limits: the blends round corners inside them, but a corner on a limit
// may still cut it. nullopt when every knot is inside. With `frame`, a
// soft-limit fault's words give the program's coordinates (soft_limit_text).
std::optional<PlanFault> check_plan(const Plan& plan, const ctl::Machine& machine, const SoftLimits& soft,
                                    const ProgramFrame* frame = nullptr);

struct ProgramOptions {
  std::string name = "program";          // for messages (the file name)
  ProgramFrame frame;                    // where program zero is
  std::optional<Vec3> start;             // machine frame (m); default: program zero
  double tolerance = 5e-5;               // m, unless the program sets one (G64 P, G61)
  SoftLimits soft;                       // besides the machine's own workspace
  PlannerOptions planner;
};

// A program read and checked, its queue, and (prepare_program) its plan.
struct PreparedProgram {
  Program program;
  PathQueue queue{Vec3::Zero()};
  std::optional<Plan> plan;
  double plan_seconds = 0.0;  // wall time the planner took (s)
};

// Read, check against the workspace and the soft limits, make the queue.
// Throws ProgramError with every fault (file:line:column).
PreparedProgram read_checked_program(std::string_view text, const ctl::Machine& machine, const ProgramOptions& options);

// The same, then planned and the plan checked at every knot. Throws
// ProgramError for a bad program or a plan that leaves the workspace (with
// the line), Error (naming the line) when no plan within the limits exists.
PreparedProgram prepare_program(std::string_view text, const ctl::Machine& machine, const ProgramOptions& options);

// The program line of programmed segment `segment` of a plan (0: none).
int line_of(const Plan& plan, int segment) noexcept;

}  // namespace cpm::path
