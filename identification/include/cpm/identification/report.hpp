// What people and programs read: the comparison summary (cpm compare), the
// diagnosis as text, JSON (the contract of issue 4) and one self-contained
// HTML file with inline SVG plots.
#pragma once

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
};

ResidualSummary summarize(const MotionProblem& P, const Eigen::VectorXd& residual, int bins = 10);

std::string summary_text(const ResidualSummary& s, const MotionProblem& P);
std::string summary_json(const ResidualSummary& s, const MotionProblem& P, const std::string& data_file,
                         const std::string& model_file, int samples);

std::string diagnosis_text(const Diagnosis& D);
std::string diagnosis_json(const Diagnosis& D);

// HTML: `title`, the residual before (and after, when given), plots of the
// residual against time, against each axis' position split by direction,
// the periodogram against position, and for a diagnosis its tables.
std::string compare_html(const MotionProblem& P, const ResidualSummary& s, const std::string& title);
std::string diagnosis_html(const Diagnosis& D);

}  // namespace cpm::ident
