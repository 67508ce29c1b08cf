// SPDX-License-Identifier: Apache-2.0
// Stage "align" of the motion diagnosis: when does the logged force act?
//
// A motion log's force column is the force commanded at t_k (docs/data-formats.md),
// but where it acts depends on the drive and the logger: a zero-order hold
// acts over [t_k, t_k+1) (tau = 0), a logger sampling a continuous force
// records it at t_k itself (tau = -T/2), a drive on a synchronous bus acts
// from the next SYNC (tau = T or more). A wrong alignment leaves a residual
// proportional to the force's rate of change, which reads as viscous friction
// on every axis. So the alignment is estimated on every log, over
// [kShiftLo, kShiftHi] periods, with the base model and friction on every
// axis refitted, before any effect is looked for; every candidate is then
// fitted on the aligned residual, and the alignment is estimated again with
// the effects found until it settles (diagnose_motion).
//
// A tau within +-T/2 of the model's own actuation_delay is how the data were
// sampled; beyond T/2 it is a delay the drive adds (docs/effects.md): the
// diagnosis names `actuation_delay` with tau - model tau.
#pragma once

#include <string>

#include "cpm/identification/engine.hpp"
#include "cpm/identification/motion.hpp"

namespace cpm::ident {

struct Alignment {
  double tau = 0.0;          // s: the estimate (force-to-motion delay, zero-order hold = 0)
  double std_error = -1.0;   // s
  double period = 0.0;       // s: sample period T
  double model_tau = 0.0;    // s: the model's own actuation_delay
  // s: the alignment the model as given may take without a missing effect:
  // model_tau + clamp(tau - model_tau, -T/2, +T/2).
  double reference = 0.0;
  double rss_at_tau = 0.0;        // weighted RSS, base refitted, at tau
  double rss_at_reference = 0.0;  // the same at `reference`
  double n_eff = 0.0;             // effective independent rows of that residual
  int trials = 1;                 // whole-period brackets searched (look-elsewhere)
  // False when the RSS still falls at an end of the searched range: the log
  // then does not determine the delay (on a one-frequency path a delay is a
  // phase, one column with the inertia and viscous friction), and tau is the
  // reference, the alignment the model as given may take.
  bool determined = true;
  // The delay the model is missing, tau - model_tau (s), when beyond T/2.
  [[nodiscard]] double missing() const noexcept { return tau - model_tau; }
  [[nodiscard]] bool beyond_sampling() const noexcept { return missing() > 0.5 * period; }
  // "zero-order hold", "force sampled at t_k", "delayed by 1.02 periods (1.02 ms)".
  [[nodiscard]] std::string convention() const;
};

// Minimum over tau of the base-refitted RSS of P's residual, on the engine's
// base and weights (E built from motion_linear_problem(P), rows that must not
// vote at weight 0). Exact within each whole-period bracket (the RSS is
// quadratic in the interpolation weight there).
Alignment estimate_alignment(const MotionProblem& P, const Engine& E);

// The problem the alignment is estimated on: the same estimator over eight
// times the window. In closed loop the controller answers the velocity noise,
// so the force carries the noise that an acceleration differentiated from the
// same velocities carries too; over the usual window that shared noise moved
// the estimate by up to three periods. Over eight times the window it is
// averaged away while the force's slope at the motion's own frequencies (and
// the delay in it) stays. Rows near a reversal of their axis are left out
// (alignment_linear_problem): a friction column's second-order error there
// and the controller's answer to it otherwise read as a delay.
MotionProblem alignment_problem(const io::MotionData& data, const ctl::Machine& model, const MotionOptions& o);

// Its regression: motion_linear_problem with the rows near a reversal of
// their axis (|v| < 3 cm/s) at weight 0.
LinearProblem alignment_linear_problem(const MotionProblem& Pa);

// The base-only alignment of a log for a model (compare, fit).
Alignment align_motion(const io::MotionData& data, const ctl::Machine& model, const MotionOptions& o);



}  // namespace cpm::ident
