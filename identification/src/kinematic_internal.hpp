// SPDX-License-Identifier: Apache-2.0
// Pieces the files of the kinematic side share (not a public header):
// kinematic.cpp (the problem: read, calibrate, residual), kinematic_effects.cpp
// (the effect table and a candidate's evaluation), kinematic_scales.cpp
// (actuator_scale at the model as given), kinematic_select.cpp (selection and
// verdict), kinematic_diagnose.cpp (the stages in order, structure) and
// kinematic_fit.cpp (cpm fit).
#pragma once

#include <sstream>
#include <string>
#include <vector>

#include "cpm/identification/kinematic_stages.hpp"
#include "internal.hpp"

namespace cpm::ident::detail {
struct Selection;  // selection.hpp
}  // namespace cpm::ident::detail

namespace cpm::ident::kinematic_detail {

using detail::fmt;

// "file:line" of sample j (or "file (sample j+1)").
std::string where(const KinematicProblem& P, int j);

// The model's own effects plus `extra` (the candidate's), per limb.
KinematicEffects combine(const KinematicEffects& own, const KinematicEffects& extra);

// The model in the frame of the base parameters x (ball-bar frame or machine
// frame) with the effects `eff`.
kin::KinematicModel frame_model(const KinematicProblem& P, const Eigen::VectorXd& x, const KinematicEffects& eff);

// Residual (model - measurement, m) of `m` in the base frame; ball-bar with
// the pivot q + dq and the bar offset dl; `shift` (m) added to axis `axis` of
// every reading. Throws Error naming the file and line of a reading the model
// cannot follow.
Eigen::VectorXd frame_residual(const KinematicProblem& P, const kin::KinematicModel& m, const Vec3& dq, double dl,
                               int axis = -1, double shift = 0.0);

// The ball-bar set-up (pivot offset dq, bar offset dl) in base parameters x;
// zero for position data.
void split_ballbar(const KinematicProblem& P, const Eigen::VectorXd& x, Vec3& dq, double& dl);

// Central difference (step eps) of the residual at the calibrated base with
// respect to parameter `param` of effect t on limb `axis` (m per parameter unit).
Eigen::VectorXd effect_difference(const KinematicProblem& P, kin::KinematicEffectType t, int axis, int param,
                                  double eps);

// The data of a file as a problem, nothing computed (read_kinematic without the residual).
KinematicProblem read_problem(const io::DataSet& data, const kin::KinematicModel& model);

// actuator_scale judged at the model as given jointly with the effects the
// selection `sel` chose (kinematic_scales.cpp): fills the actuator_scale
// candidates among D.candidates, their statistics in sel, and adds those
// named to sel's choices.
void select_scales_at_the_given_model(const KinematicProblem& P, const Engine& E, const DiagnoseOptions& opt,
                                      Diagnosis& D, detail::Selection& sel);

// Stage 5, selection and verdict (kinematic_select.cpp): forward selection
// from the calibrated base (select.cpp), each searched parameter searched
// again on what the effects chosen before it leave, the scales at the model
// as given; reorders D.candidates, sets verdict, also, residual_final and the
// verdict text.
void select_kinematic_effects(const KinematicProblem& P, const Engine& E, const DiagnoseOptions& opt, Diagnosis& D);

// The engine of the base refit with the columns X (m per unit) as base columns
// too, each named `name`: a fit on it takes them beside every other column.
Engine with_base_columns(const Engine& E, const Eigen::MatrixXd& X, const char* name);

}  // namespace cpm::ident::kinematic_detail
