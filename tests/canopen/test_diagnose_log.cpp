// SPDX-License-Identifier: Apache-2.0
// The diagnosis on a log it did not make: recorded through cpmd's CANopen
// path (record_log.hpp), where the synchronous drives apply each torque from
// the SYNC after the one it was computed from. The log carries a dead time of
// one period that no model of the daemon's own simulator had; the diagnosis
// must name exactly that and nothing else.
#include <gtest/gtest.h>

#include "canopen/record_log.hpp"
#include "cpm/identification/diagnose.hpp"

namespace cpm::daemon::test {
namespace {

TEST(DiagnoseCanopenLog, TheSynchronousBusIsOnePeriodOfActuationDelayAndNothingElse) {
  const io::MotionData m = record_canopen_motion_log(12.0, 11, false);
  const double T = 1.0 / m.rate;
  const ident::Diagnosis D = ident::diagnose_motion(m, ctl::Machine(ctl::MachineModel::elkady()));
  ASSERT_GE(D.verdict, 0) << D.verdict_text;
  const ident::CandidateResult& v = D.candidates[static_cast<std::size_t>(D.verdict)];
  EXPECT_EQ(v.effect, "actuation_delay") << D.verdict_text;
  EXPECT_NEAR(v.params[0].value, T, 0.1 * T) << D.verdict_text;
  EXPECT_EQ(D.found().size(), 1u) << D.verdict_text;
  std::printf("CANopen log at %.0f Hz: %s\n", m.rate, D.verdict_text.c_str());
  // With the bus's delay in the model, nothing is missing.
  ctl::MachineModel with_delay = ctl::MachineModel::elkady();
  ctl::add_effect(with_delay, "actuation_delay", -1, {T});
  const ident::Diagnosis W = ident::diagnose_motion(m, ctl::Machine(with_delay));
  EXPECT_LT(W.verdict, 0) << W.verdict_text;
  EXPECT_NEAR(W.alignment.missing(), 0.0, 0.1 * T);
}

}  // namespace
}  // namespace cpm::daemon::test
