// SPDX-License-Identifier: Apache-2.0
// What people and programs read: the comparison summary (cpm compare), the
// diagnosis as text, JSON (the contract of issue 4) and one self-contained
// HTML file with inline SVG plots.
#pragma once

#include <array>
#include <cmath>
#include <string>
#include <vector>

#include "cpm/identification/diagnose.hpp"

namespace cpm::ident {

// Residual of a model on a motion log, broken down (cpm compare).
struct ResidualSummary {
  double rms = 0.0, max = 0.0;           // N, over all axes
  Vec3 axis_rms = Vec3::Zero(), axis_max = Vec3::Zero();
  Vec3 rms_forward = Vec3::Zero(), rms_backward = Vec3::Zero();    // by direction of motion of the axis
  Vec3 mean_forward = Vec3::Zero(), mean_backward = Vec3::Zero();
  // Along each axis' own position and over time: bin centres and mean / RMS per bin.
  struct Bins { std::vector<double> centre, mean, rms; std::vector<int> count; };
  std::array<Bins, 3> along_position;    // centre in m
  std::array<Bins, 3> over_time;         // centre in s
  // The fit of the model's force to the measured one per axis, as MATLAB's
  // compare gives it (NRMSE-based, docs/identification.md): 100 (1 - ||y -
  // yhat|| / ||y - mean(y)||) %, y the measured force (g F, aligned) and yhat
  // the model's, over the kept rows. 100 % is a perfect fit, 0 % no better
  // than the mean; negative is worse than the mean.
  Vec3 fit_percent = Vec3::Constant(std::nan(""));
};

ResidualSummary summarize(const MotionProblem& P, const Eigen::VectorXd& residual, int bins = 10);

std::string summary_text(const ResidualSummary& s, const MotionProblem& P);
std::string summary_json(const ResidualSummary& s, const MotionProblem& P, const std::string& data_file,
                         const std::string& model_file, int samples);

// MATLAB's resid: the residual's autocorrelation and its cross-correlation
// with each axis' own position, velocity and force, with the 99 % band of a
// white residual (2.576 / sqrt(N)). The kept rows are filtered over
// 2 half_width + 1 samples and overlap; every `spacing`-th row is used, so
// that no two share a sample and a white residual stays white.
struct ResidualCorrelation {
  int lags = 0;      // autocorrelation at k = 0..lags, cross-correlation at k = -lags..lags
  int rows = 0;      // N
  int spacing = 1;   // in kept rows
  double lag_s = 0;  // one lag in s
  double band = 0;   // the 99 % band, +-
  std::array<std::vector<double>, 3> autocorrelation;                 // per axis
  std::array<std::array<std::vector<double>, 3>, 3> cross;            // [axis][position, velocity, force]
  std::array<int, 3> auto_outside{};                                  // lags 1..lags outside the band
  std::array<std::array<int, 3>, 3> cross_outside{};                  // of 2 lags + 1
  std::array<double, 3> auto_largest{};                               // max |r(k)|, k >= 1
};
ResidualCorrelation residual_correlation(const MotionProblem& P, const Eigen::VectorXd& residual, int lags = 20);
std::string correlation_text(const ResidualCorrelation& c);
// The plots (inline SVG) of the autocorrelation and cross-correlations with their bands.
std::string correlation_html(const ResidualCorrelation& c);

// What `cpm compare` compares at: where the logged force acts (A.tau), the
// alignment the model as given may take (A.reference: half a sample period
// either side of its actuation_delay, how a log is sampled), and, when they
// differ, that the rest is a delay the model misses.
std::string alignment_text(const Alignment& A);

std::string diagnosis_text(const Diagnosis& D);
std::string diagnosis_json(const Diagnosis& D);

// HTML: `title`, the residual before (and after, when given), plots of the
// residual against time, against each axis' position split by direction,
// the periodogram against position, and for a diagnosis its tables.
std::string compare_html(const MotionProblem& P, const ResidualSummary& s, const std::string& title,
                         const ResidualCorrelation* correlation = nullptr);
std::string diagnosis_html(const Diagnosis& D);

}  // namespace cpm::ident
