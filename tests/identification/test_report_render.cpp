// SPDX-License-Identifier: Apache-2.0
// What the diagnosis' reports show a person (identification/src/report.cpp,
// model_loop.cpp's waterfall, verdict.cpp's sentence): plot ticks that tell their
// values apart, the waterfall's axis, labels and legend, a noise floor above
// the residual reached said as what it is, an implausible effect not called
// missing in the same breath.
#include <gtest/gtest.h>

#include <regex>
#include <string>

#include "../../identification/src/internal.hpp"
#include "cpm/identification/model_loop.hpp"
#include "cpm/identification/report.hpp"

namespace cpm::ident {
namespace {

int count_of(const std::string& text, const std::string& what) {
  int n = 0;
  for (std::size_t at = text.find(what); at != std::string::npos; at = text.find(what, at + 1)) ++n;
  return n;
}

TEST(ReportRender, TickLabelsCarryTheDecimalsTheirStepNeeds) {
  // An axis from 73.190 to 73.200 mm in steps of 0.002: every label differs.
  const double step = detail::nice_step(0.01, 5);
  EXPECT_DOUBLE_EQ(step, 0.002);
  std::vector<std::string> labels;
  for (int k = 0; k <= 5; ++k) labels.push_back(detail::tick_text(73.19 + k * step, step));
  EXPECT_EQ(labels, (std::vector<std::string>{"73.190", "73.192", "73.194", "73.196", "73.198", "73.200"}));
  EXPECT_EQ(detail::tick_text(250.0, 50.0), "250");
  EXPECT_EQ(detail::tick_text(-1e-17, 0.5), "0.0");
  EXPECT_EQ(detail::tick_text(0.25, 0.05), "0.25");
}

LoopResult waterfall() {
  LoopResult R;
  R.kind = "motion";
  R.units = "N";
  R.steps.push_back({"", 2.4, 0.3, "missing: coulomb_friction[axis 2]"});
  R.steps.push_back({"coulomb_friction[axis 2]", 0.9, 0.3, "missing: viscous_friction[axis 1]"});
  R.steps.push_back({"viscous_friction[axis 1]", 0.25, 0.3, "none"});
  R.stop = "nothing missing";
  return R;
}

TEST(ReportRender, WaterfallHasYTicksSlantedLabelsAndAFloorSwatch) {
  const std::string h = loop_html(waterfall(), "log.csv");
  // y ticks 0, 1, 2, 3 N (2.4 N * 1.05 on about 5 steps: 1 N).
  for (const char* tick : {">0<", ">1<", ">2<", ">3<"}) EXPECT_NE(h.find(tick), std::string::npos) << tick;
  // Each step's name slants (rotated), so that long names do not run into each other.
  EXPECT_EQ(count_of(h, "text-anchor='end' transform='rotate(-35"), 3) << h;
  // The legend's dashed swatch: a dashed line besides the three bars' floors.
  EXPECT_EQ(count_of(h, "stroke-dasharray='4 3'"), 4);
  EXPECT_NE(h.find("stroke-width='1.5'/><text"), std::string::npos);
}

TEST(ReportRender, AFloorAboveTheResidualReachedIsSaidToBeTooHigh) {
  const std::string t = loop_text(waterfall());
  EXPECT_NE(t.find("(8 x the noise floor 0.3 N)"), std::string::npos) << t;
  EXPECT_NE(t.find("0.25 N  (below the noise floor's estimate 0.3 N: that estimate is too high)"), std::string::npos) << t;
  EXPECT_EQ(detail::floor_after(1.0, 0.5, "N"), "(noise floor about 0.5 N)");
  EXPECT_EQ(detail::floor_after(0.4, 0.5, "N"), "(below the noise floor's estimate, 0.5 N: that estimate is too high)");
}

CandidateResult effect(const std::string& name, int axis, double value, const std::string& unit) {
  CandidateResult c;
  c.effect = name;
  c.axis = axis;
  ParamEstimate p;
  p.name = "f";
  p.unit = unit;
  p.value = value;
  c.params.push_back(p);
  return c;
}

TEST(ReportRender, AnImplausibleEffectIsNotListedAsMissing) {
  Diagnosis D;
  D.units = "N";
  D.baseline_rms = 5.0;
  D.noise_floor = 0.5;
  D.candidates = {effect("viscous_friction", 0, 12.0, "N s/m"), effect("coulomb_friction", 1, 45.0, "N")};
  D.verdict = 0;
  D.also = {1};
  D.residual_final = Eigen::VectorXd::Constant(30, 0.6);
  detail::verdict_text_motion(D);
  const std::string& v = D.verdict_text;
  const std::size_t dot = v.find(". ");
  ASSERT_NE(dot, std::string::npos) << v;
  const std::string missing = v.substr(0, dot), rest = v.substr(dot);
  EXPECT_EQ(missing.rfind("missing: viscous_friction", 0), 0u) << v;
  EXPECT_EQ(missing.find("coulomb_friction"), std::string::npos) << v;
  EXPECT_EQ(missing.find("implausible"), std::string::npos) << v;
  EXPECT_NE(rest.find("also fit coulomb_friction"), std::string::npos) << v;
  EXPECT_NE(rest.find("more than 30 N of dry friction"), std::string::npos) << v;
  EXPECT_NE(rest.find("(noise floor about 0.5 N)"), std::string::npos) << v;
  // Only the implausible one: nothing is said to be missing.
  D.verdict = 1;
  D.also = {};
  D.residual_final = Eigen::VectorXd::Constant(30, 0.4);
  detail::verdict_text_motion(D);
  EXPECT_EQ(D.verdict_text.rfind("missing: no effect with a plausible value. The data fit coulomb_friction", 0), 0u)
      << D.verdict_text;
  EXPECT_NE(D.verdict_text.find("below the noise floor's estimate, 0.5 N"), std::string::npos) << D.verdict_text;
}

}  // namespace
}  // namespace cpm::ident
