// SPDX-License-Identifier: Apache-2.0
// The circular test of ISO 230-4 with a simulated ball-bar: the controller
// (believing `controller`) drives the true machine (`truth`) round a circle,
// counter-clockwise then clockwise, and a ball-bar between the platform and
// a fixed pivot reads the radius.
//
// Set-up, as a ball-bar user does it: the pivot is put where the machine
// goes when commanded to the circle's centre (its true position, unless
// given), so the bar sees the machine's own circle, not a set-up error.
// Each run enters and leaves the circle by an overshoot arc (the speed
// ramps up and down smoothly); only the 360 degrees at constant feed are
// evaluated.
//
// Results (ISO 230-4, evaluated on the bar's radial deviation
// dr(phi) = |p_true - pivot| - R at the commanded angle phi):
//  * G, circular deviation of one run: the minimum radial separation of two
//    circles about the least-squares centre that enclose the run's path;
//  * G_bidirectional: the same for both runs about their common
//    least-squares centre;
//  * H, circular hysteresis: the largest radial difference between the two
//    runs at the same angle (about the common least-squares centre);
//  * F_max, F_min, radial deviation: the largest and smallest dr about the
//    centre as set (the pivot), both runs; max_abs_error = max(|F_max|, |F_min|),
//    the "maximum absolute error" that Kim quotes.
// The least-squares centre is the linearised one (ISO 4291, annex F):
// dr = r0 + a cos phi + b sin phi fitted by linear least squares.
#pragma once

#include <optional>
#include <string>
#include <vector>

#include "cpm/control/controller.hpp"
#include "cpm/control/trajectory.hpp"

namespace cpm::cal {

struct CircularTestSpec {
  Vec3 centre = Vec3(0.430, 0.430, 0.400);  // commanded centre (m), controller's frame
  double radius = 0.150;                    // m
  ctl::CirclePlane plane = ctl::CirclePlane::xy;
  double feed = 0.020;                      // m/s along the circle
  double overshoot_time = 0.5;              // s of speed ramp at each end (the overshoot arcs)
  bool closed_loop = true;                  // false: kinematic only (no servo error)
  ctl::ControlLaw law = ctl::ControlLaw::computed_torque;
  std::optional<ctl::Gains> gains;          // default: Elkady's Table 3 for the law
  double rate_hz = 1000.0;
  std::optional<Vec3> pivot;                // true position of the fixed ball (truth's frame)
  double trace_step = 0.25 * 3.141592653589793 / 180.0;  // rad between kept trace points
  void validate() const;
};

struct CircularTrace {
  std::vector<double> angle;      // commanded angle in [0, 2 pi) from the plane's first axis (rad)
  std::vector<double> deviation;  // bar reading minus R (m), centre as set
};

struct CircularRunMetrics {
  double G = 0.0;                  // m
  double F_max = 0.0, F_min = 0.0; // m, centre as set
  double lsc_a = 0.0, lsc_b = 0.0; // least-squares centre offset along the plane's two axes (m)
  double lsc_r0 = 0.0;             // mean radius error (m)
};

struct CircularTestResult {
  CircularTestSpec spec;
  Vec3 pivot = Vec3::Zero();
  CircularTrace ccw, cw;
  CircularRunMetrics ccw_metrics, cw_metrics;
  double G_bidirectional = 0.0;  // m
  double H = 0.0;                // m
  double F_max = 0.0, F_min = 0.0;  // m, both runs, centre as set
  double max_abs_error = 0.0;       // m
  double servo_rms = 0.0;           // RMS of |p_ref - p_est| over the runs (m), closed loop only
};

// Throws Error when the circle leaves the workspace or a run stops on a fault.
CircularTestResult run_circular_test(const ctl::MachineModel& truth,
                                     const ctl::MachineModel& controller,
                                     const CircularTestSpec& spec);

// The figures (G per run and bidirectional, H, F) of the traces r.ccw and
// r.cw already in `r` (both non-empty): for traces measured elsewhere, e.g.
// a ball-bar file read from a real circular test.
void evaluate_circular_traces(CircularTestResult& r);

// A self-contained SVG polar plot as a ball-bar user knows it: the nominal
// circle, the two runs' radial deviations magnified (scale rings in µm),
// and the figures. um_per_division > 0 sets the scale (µm between rings, the
// test's magnification); 0 picks one so the largest deviation spans about
// three rings.
std::string circular_test_svg(const CircularTestResult& r, const std::string& title,
                              double um_per_division = 0.0);

// Plane axes of a CirclePlane: (first, second) machine axis indices.
std::pair<int, int> plane_axes(ctl::CirclePlane p);
const char* plane_name(ctl::CirclePlane p);

}  // namespace cpm::cal
