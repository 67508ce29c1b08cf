// SPDX-License-Identifier: Apache-2.0
// Fault reports people read (issue 17, part 4): every fault kind gives its
// name, the axis as 1-3 or none, its figures in human units and a sentence of
// what happened and what to do.
#include <gtest/gtest.h>

#include <cstdio>
#include <cstring>
#include <string>

#include "cpm/daemon/fault_report.hpp"
#include "loop_fixture.hpp"

namespace cpm::daemon::test {
namespace {

struct Case {
  std::uint32_t bit;
  int axis;
  double value, limit;
  const char* cause;  // state_t.fault_text
  const char* where;  // expected "axis 2 (y)", "limb 1", or "" for none
  const char* figure; // expected figure with its unit
};

cpm_msgs::state_t faulted(const Case& c) {
  cpm_msgs::state_t s{};
  s.faults = static_cast<std::int32_t>(c.bit);
  s.first_fault = static_cast<std::int32_t>(c.bit);
  s.fault_axis = static_cast<std::int8_t>(c.axis);
  s.fault_value = c.value;
  s.fault_limit = c.limit;
  std::strncpy(reinterpret_cast<char*>(s.fault_text), c.cause, sizeof s.fault_text - 1);
  return s;
}

bool has(const std::string& s, const std::string& part) { return s.find(part) != std::string::npos; }

const Case kCases[] = {
    {kFaultFollowingError, -1, 0.005046, 0.005, "", "", "5.046 mm from its reference against a limit of 5.000 mm"},
    {kFaultSoftLimit, 0, 0.7512, 0.75, "", "axis 1 (x)", "x = 751.200 mm, beyond the soft limit 750.000 mm"},
    {kFaultSoftLimit, 2, 0.3012, 0.3, "stroke_high", "axis 3 (z)", "301.200 mm, beyond its stroke end 300.000 mm"},
    {kFaultSoftLimit, 1, 0.01, 0.0349, "near_singularity", "limb 2", "0.57 deg of straight or folded against a margin of 2.00 deg"},
    {kFaultSoftLimit, 0, 0.52, 0.5, "limb_unreachable", "limb 1", "520.000 mm against its reach of 500.000 mm"},
    {kFaultOverspeed, -1, 0.61, 0.5, "", "", "610.0 mm/s against a limit of 500.0 mm/s"},
    {kFaultController, -1, 0, 0, "not_finite", "", "(not_finite)"},
    {kFaultEstimate, -1, 0, 1e-6, "singular_planes", "", "(singular_planes)"},
    {kFaultDrive, 1, 0x0218, 0, "drive 2 (y, node 2): fault", "axis 2 (y)", "statusword 0x0218"},
    {kFaultBackendIo, -1, 2, 0, "no TPDO", "", "did not answer in time"},
    {kFaultEstop, -1, 1, 0, "", "", "the e-stop chain is open"},
    {kFaultOverrun, -1, 3, 3, "", "", "3 cycles in a row ended late against a limit of 3"},
    {kFaultEnableTimeout, -1, 2.001, 2.0, "", "", "after 2001 ms against a limit of 2000 ms"},
    {kFaultLimitSwitch, 2, 1, 0, "", "axis 3 (z)", "the limit switch is open"},
    {kFaultSaturation, 0, 0.201, 0.2, "", "axis 1 (x)", "201 ms against a limit of 200 ms"},
    {kFaultStreamUnderrun, -1, 0.05, 1e-6, "", "", "ran dry at 50.0 mm/s"},
};

TEST(FaultReport, EveryKindSaysWhereWhatAndWhatToDo) {
  std::uint32_t covered = 0;
  for (const Case& c : kCases) {
    const std::string r = fault_report(faulted(c));
    SCOPED_TRACE(r);
    covered |= c.bit;
    EXPECT_EQ(r.rfind(fault_bit_name(c.bit), 0), 0u) << "starts with the fault's name";
    if (*c.where) EXPECT_TRUE(has(r, std::string(" on ") + c.where + ": "));
    else EXPECT_FALSE(has(r, " on ")) << "a fault of no one axis names none";
    EXPECT_FALSE(has(r, "axis 0")) << "axes are 1-3";
    EXPECT_TRUE(has(r, c.figure));
    EXPECT_TRUE(has(r, "reset")) << "says what to do";
    EXPECT_FALSE(has(r, "does not know"));
  }
  EXPECT_EQ(covered, (kFaultStreamUnderrun << 1) - 1) << "a fault kind without a case";
}

TEST(FaultReport, BackendWordsCloseTheLine) {
  const std::string r = fault_report(faulted(kCases[8]));
  EXPECT_TRUE(has(r, "(drive 2 (y, node 2): fault)")) << r;
}

TEST(FaultReport, NoFaultNoReportAndAnUnknownBitIsNamedAsSuch) {
  EXPECT_EQ(fault_report(cpm_msgs::state_t{}), "");
  const std::string r = fault_report(faulted({1u << 20, -1, 0, 0, "", "", ""}));
  EXPECT_TRUE(has(r, "does not know (bit 1048576)")) << r;
}

// The loop fills the figures the report reads: a drive fault on the second
// drive of the simulator, and the platform leaving the configured workspace.
TEST(FaultReport, FromTheLoop) {
  LoopHarness h;
  h.to_holding();
  h.sim->inject_drive_fault(1);
  h.run(2);
  ASSERT_EQ(h.mode(), Mode::fault);
  const std::string drive = fault_report(h.state());
  EXPECT_TRUE(has(drive, "drive on axis 2 (y): the drive reports a fault (statusword 0x0218)")) << drive;

  DaemonConfig cfg = test_config();
  cfg.limits.workspace_min.x() = 0.58;  // the platform starts at x = 0.600 m
  LoopHarness f(cfg);
  f.to_holding();
  ASSERT_TRUE(f.command(f.move_to(f.queue_end() + Vec3(-0.05, 0, 0))).accepted);
  f.run(2000);
  ASSERT_EQ(f.mode(), Mode::fault);
  const std::string soft = fault_report(f.state());
  EXPECT_TRUE(has(soft, "soft_limit on axis 1 (x): the platform reached x = 579.")) << soft;
  EXPECT_TRUE(has(soft, "beyond the soft limit 580.000 mm")) << soft;
  std::printf("%s\n%s\n", drive.c_str(), soft.c_str());  // as cpm status and the journal show them
}

}  // namespace
}  // namespace cpm::daemon::test
