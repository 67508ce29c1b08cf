// What remains: structure in a residual that the fitted effects do not
// explain, said with where it is. Checks, per axis: a difference between the
// two directions of motion; a periodic pattern against each axis' position
// (wavelengths 2 mm .. 2/3 of the stroke covered) and against time; a trend
// in time; a step or a bump at a position. Significance uses the residual's
// own spread, corrected for autocorrelation and for how many places were
// searched, so noise alone reports nothing.
#pragma once

#include <vector>

#include "cpm/identification/diagnose.hpp"

namespace cpm::ident {

std::vector<StructureFinding> find_motion_structure(const MotionProblem& P,
                                                    const Eigen::VectorXd& residual,
                                                    const Vec3& axis_noise);

// Periodogram of y against coordinate x for wavelengths in [lmin, lmax]:
// the least-squares power of a sine/cosine pair (weighted sum of squares
// removed) at each wavelength. Returns wavelengths and powers.
void periodogram(const std::vector<double>& x, const std::vector<double>& y, double lmin, double lmax,
                 std::vector<double>& wavelength, std::vector<double>& power);

}  // namespace cpm::ident
