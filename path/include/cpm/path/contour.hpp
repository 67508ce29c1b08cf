// SPDX-License-Identifier: Apache-2.0
// Contouring figures of a run along a plan (simulated or measured): how far
// the platform strayed from the programmed path, and how fast it went
// against the programmed feed.
//
// The contour error of a sample is the distance from where the platform
// was to the nearest point of the programmed path (the segments as
// written, before blending), not its distance to the reference at the same
// time: lagging along the path is no error of the part.
//
// Frame and units: machine frame (m, m/s, N); reports show mm and µm.
#pragma once

#include <vector>

#include "cpm/path/plan.hpp"

namespace cpm::path {

// One control period of a run.
struct RunSample {
  double t = 0.0;                  // s from the plan's start
  Vec3 p = Vec3::Zero();           // platform position (m)
  Vec3 p_dot = Vec3::Zero();       // platform velocity (m/s)
  Vec3 force = Vec3::Zero();       // actuator commands (N)
};

struct ContourPoint {
  double t = 0.0;
  Vec3 p = Vec3::Zero();
  double error = 0.0;       // m to the programmed path
  Vec3 nearest = Vec3::Zero();  // the nearest point of the programmed path (m)
  double tracking = 0.0;    // m to the plan's reference at t
  double s = 0.0;           // m along the programmed path, of the nearest point
  double along = 0.0;       // m along the plan's path of its reference at t (rises with t)
  double feed = 0.0;        // m/s achieved, |p_dot|
  double programmed = 0.0;  // m/s programmed there (rapids: the velocity ceiling)
  int segment = -1;         // programmed segment nearest
  bool rapid = false;
};

struct ContourFigures {
  std::vector<ContourPoint> points;
  // Over the samples on feed moves (G1, G2, G3), not rapids:
  double max_error = 0.0;     // m
  double rms_error = 0.0;     // m
  double max_tracking = 0.0;  // m, |p - p_ref| at the same time
  double max_rounding = 0.0;  // m, of the plan's own reference from the programmed path (its corner blends)
  // Share of the distance run on feed moves at >= 95 % of the programmed feed.
  double feed_held = 0.0;
  Vec3 peak_force = Vec3::Zero();  // N, largest command per actuator over the whole run
};

// `velocity` (m/s): the plan's velocity ceiling, the programmed speed of rapids.
ContourFigures contour(const PathQueue& queue, const Plan& plan, const std::vector<RunSample>& run, double velocity);

}  // namespace cpm::path
