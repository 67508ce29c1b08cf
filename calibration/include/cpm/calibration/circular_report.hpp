// SPDX-License-Identifier: Apache-2.0
// The one-page ball-bar report of a circular test (cpm circular-test
// --report): the error sources a ball-bar user reads off the two runs, each
// with its contribution in µm and its share, and pass/fail against the
// user's tolerances. docs/calibration.md describes the page and the keys of
// the tolerance file.
//
// The sources are the classic ball-bar signatures, fitted jointly by linear
// least squares to both runs' radial deviation dr(phi, s) (m; phi the
// commanded angle from the plane's first axis a, second axis b; s = +1 CCW,
// -1 CW; R the radius):
//   set-up     r0 + c_a cos phi + c_b sin phi (bar length and centre offset; not listed)
//   squareness alpha: a_true = a + alpha b         -> (alpha R / 2) sin 2 phi
//   scale mismatch e_a - e_b                        -> ((e_a - e_b) R / 2) cos 2 phi
//   servo mismatch dt (axis a lags b by dt)         -> s (w R dt / 2) sin 2 phi, w = feed / R
//   backlash b_a on a (lags by b_a / 2 against its motion) -> (b_a / 2) s sign(sin phi) cos phi
//   backlash b_b on b                                -> -(b_b / 2) s sign(cos phi) sin phi
// Each source's contribution is the peak-to-valley of its own term over the
// circle (m): |alpha| R, |e_a - e_b| R, w R |dt|, |b_a|, |b_b|; "not
// explained" is the peak-to-valley of what the fit leaves. Shares are of the
// sum of the contributions listed (how a ball-bar's software ranks them).
#pragma once

#include <optional>
#include <string>
#include <vector>

#include "cpm/calibration/circular_test.hpp"

namespace cpm::cal {

struct BallbarError {
  std::string key;       // "squareness", "scale_mismatch", "servo_mismatch", "backlash_x", ..., "not_explained"
  std::string name;      // what the page says
  double value = 0.0;    // SI in the unit below (rad, 1, s, m)
  std::string unit;      // "rad", "1", "s", "m"
  double contribution = 0.0;  // m, peak-to-valley over the circle
  double share = 0.0;         // % of the sum of contributions
};

// Tolerances (SI inside; the file is in µm, µm/m and ms). Absent: not judged.
struct BallbarTolerances {
  std::optional<double> circularity, hysteresis, radial_deviation;  // m: G both runs, H, max |F|
  std::optional<double> squareness;      // rad
  std::optional<double> scale_mismatch;  // 1
  std::optional<double> servo_mismatch;  // s
  std::optional<double> backlash;        // m, each axis
};
// Reads the YAML file (keys: docs/calibration.md). Throws Error naming the
// file and the key for an unknown key or a value that is not a number >= 0.
BallbarTolerances load_ballbar_tolerances(const std::string& path);

struct BallbarCheck {
  std::string what;       // e.g. "circularity G"
  double value = 0.0;     // SI
  double tolerance = 0.0; // SI
  std::string unit;       // for the page: "µm", "µm/m", "ms"
  double scale = 1.0;     // SI -> unit
  bool pass = true;
};

struct BallbarReport {
  CircularTestResult test;
  std::vector<BallbarError> errors;   // largest contribution first, "not explained" last
  std::vector<BallbarCheck> checks;   // one per tolerance given
  bool pass = true;                   // every check passes (true when none is given)
  double um_per_division = 0.0;       // plot scale, 0 = automatic
};

// The diagnosis of both runs (none empty). Throws Error for runs too short to fit.
std::vector<BallbarError> diagnose_circular_test(const CircularTestResult& r);

BallbarReport make_ballbar_report(const CircularTestResult& r, const BallbarTolerances& tolerances,
                                  double um_per_division = 0.0);

// The structured data the page is made from (SI values and µm contributions).
std::string ballbar_report_json(const BallbarReport& b);
// One self-contained HTML page that prints on one A4 sheet.
std::string ballbar_report_html(const BallbarReport& b, const std::string& title);

}  // namespace cpm::cal
