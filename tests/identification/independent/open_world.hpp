// SPDX-License-Identifier: Apache-2.0
// The open-world matrix of the motion diagnosis: logs from the independent
// generator with a force no library effect describes (generator.hpp,
// OutsideForce: a cable carrier following another axis' velocity, a local
// bump over a short stretch of one axis, a cubic along one axis' travel) at a
// few multiples of the noise, and null logs, each diagnosed with
// `cpm::ident::diagnose_motion` and default options, and scored: an
// `outside_library` verdict on the right axis (and, for the cable carrier,
// on the right variable), no library effect named as missing, null logs
// clean; and the honest noise floor against the residual RMS of the true model.
#pragma once

#include <string>
#include <vector>

#include "generator.hpp"
#include "matrix.hpp"

namespace cpm::indep {

struct OpenWorldOptions {
  std::vector<Timing> timings = {Timing::zoh, Timing::delay1};
  std::vector<NoisePlacement> noises = {NoisePlacement::plant, NoisePlacement::command};
  std::vector<double> rates = {1000.0};
  std::vector<OutsideForce::Kind> kinds = {OutsideForce::Kind::cross_velocity, OutsideForce::Kind::bump,
                                           OutsideForce::Kind::cubic, OutsideForce::Kind::velocity_hump,
                                           OutsideForce::Kind::cross_velocity_hump,
                                           OutsideForce::Kind::position_friction};
  // The force's largest value over the log, in multiples of the honest floor
  // of its axis on the null log of the same cell and seed.
  std::vector<double> multiples = {3.0, 10.0};
  int seeds = 1, first_seed = 1;
  double duration = 15.0;
  std::string write_logs;  // directory: every log as CSV ("" = none)
  ident::DiagnoseOptions diagnose;
};

struct OpenWorldLog {
  Timing timing = Timing::zoh;
  NoisePlacement noise = NoisePlacement::plant;
  double rate = 0.0;
  int seed = 0;
  std::string kind{};           // "" for a null log
  int axis = -1, from_axis = -1;
  double multiple = 0.0, size = 0.0;
  bool outside = false;         // the verdict leads with outside_library
  bool right_axis = false;      // ... on the planted axis
  // Forces of a velocity (cross_velocity, the humps): on the v it follows (lead
  // variable); others: = right_axis.
  bool right_variable = false;
  bool variable_listed = false; // ... that v is the lead variable or among those seen alike
  bool library_named = false;   // a library effect named as missing (beyond the delay cells' own delay)
  std::vector<std::string> named{}, partial{};
  std::string verdict{};        // the diagnosis' verdict text
  std::string lead{};           // the leading outside finding's text
  double floor = 0.0;           // the honest floor (RMS over the axes, N)
  Vec3 axis_floor = Vec3::Zero();  // per axis (N)
  double true_rms = 0.0;        // residual RMS of the true model (N), null logs in zoh cells
  double diagnose_s = 0.0;
  std::string error{};
};

struct OpenWorldResult {
  OpenWorldOptions options;
  std::vector<OpenWorldLog> logs;
  double wall_s = 0.0;
};

OpenWorldResult run_open_world(const OpenWorldOptions& o);
std::string open_world_table(const OpenWorldResult& r);
// The thresholds: per kind >= 90 % outside on the right axis (and variable),
// >= 90 % with no library effect named; nulls none in >= 95 %. One line per miss.
std::vector<std::string> open_world_failures(const OpenWorldResult& r);

}  // namespace cpm::indep
