// SPDX-License-Identifier: Apache-2.0
// The JSON the identification writes (cpm diagnose / loop / compare --json):
// numbers read back exactly, strings escaped, fields in the documented order.
#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <string>

#include <nlohmann/json.hpp>

#include "cpm/identification/kinematic.hpp"
#include "cpm/identification/model_loop.hpp"
#include "cpm/identification/report.hpp"

namespace cpm::ident {
namespace {

using nlohmann::json;

// Characters a file name or a note may carry: quotes, backslash, control
// characters, non-ASCII, and a byte that is not UTF-8.
const std::string kAwkward = "a\"b\\c\n\t\x01 µm /tmp/x.csv \xff end";

Diagnosis small_diagnosis() {
  Diagnosis D;
  D.kind = "ballbar";
  D.units = "m";
  D.data_file = kAwkward;
  D.model_file = "model.yaml";
  D.samples = 32;
  D.rows = 32;
  D.baseline_rms = 0.6;  // "%.17g" would write 0.59999999999999998
  D.baseline_max = 0.1 + 0.2;
  D.noise_floor = std::numeric_limits<double>::quiet_NaN();
  CandidateResult c;
  c.effect = "backlash";
  c.axis = 1;
  c.params = {{"b", "m", 1.0 / 3.0, -1.0, false}};
  c.rms_after = std::numeric_limits<double>::infinity();
  c.note = "both directions";
  c.confounded.push_back({"dq_x", "", -1, 0.97, "a second bar radius"});
  D.candidates.push_back(c);
  D.verdict = 0;
  D.verdict_text = "missing: backlash[axis 2]";
  D.notes = {"a note"};
  return D;
}

TEST(ReportJson, NumbersReadBackExactlyAndShortest) {
  const std::string text = diagnosis_json(small_diagnosis());
  const json j = json::parse(text);
  EXPECT_EQ(j["baseline"]["rms"].get<double>(), 0.6);
  EXPECT_NE(text.find(R"("rms": 0.6,)"), std::string::npos) << "shortest text that reads back: 0.6";
  EXPECT_EQ(j["baseline"]["max"].get<double>(), 0.1 + 0.2);
  EXPECT_EQ(j["candidates"][0]["params"]["b"].get<double>(), 1.0 / 3.0);
  // Not finite, and an undetermined standard error: null, as before.
  EXPECT_TRUE(j["noise_floor"].is_null());
  EXPECT_TRUE(j["candidates"][0]["rms_after"].is_null());
  EXPECT_TRUE(j["candidates"][0]["std_errors"]["b"].is_null());
  EXPECT_EQ(text.find("nan"), std::string::npos);
  EXPECT_EQ(text.find("inf"), std::string::npos);
}

TEST(ReportJson, StringsAreEscapedAndBadUtf8Replaced) {
  const std::string text = diagnosis_json(small_diagnosis());
  const json j = json::parse(text);  // throws on a raw control character or bad UTF-8
  EXPECT_EQ(j["data_file"].get<std::string>(), "a\"b\\c\n\t\x01 µm /tmp/x.csv \xEF\xBF\xBD end");
  EXPECT_NE(text.find("µm"), std::string::npos) << "non-ASCII stays UTF-8, not \\u escapes";
}

TEST(ReportJson, FieldsInTheDocumentedOrder) {
  const nlohmann::ordered_json o = nlohmann::ordered_json::parse(diagnosis_json(small_diagnosis()));
  std::vector<std::string> keys;
  for (const auto& [k, v] : o.items()) keys.push_back(k);
  const std::vector<std::string> want = {"kind", "samples", "rows", "units", "data_file", "model_file", "baseline",
                                         "base_refit", "noise_floor", "noise_floor_source", "noise_floor_upper_bound", "candidates", "verdict", "structure", "notes",
                                         "warnings"};
  EXPECT_EQ(keys, want);
  const auto& v = o["verdict"];
  EXPECT_EQ(v["missing"], "backlash");
  EXPECT_EQ(v["axis"], 2);
  EXPECT_EQ(v["effects"][0]["effect"], "backlash");
  EXPECT_EQ(o["candidates"][0]["confounded_with"][0]["with"], "dq_x");
  EXPECT_TRUE(o["candidates"][0]["confounded_with"][0]["effect"].is_null());
  EXPECT_EQ(o["candidates"][0]["confounded_with"][0]["separate_by"], "a second bar radius");
}

TEST(ReportJson, LoopWaterfall) {
  LoopResult R;
  R.kind = "motion";
  R.units = "N";
  R.steps.push_back({"", 0.6, 0.1, "missing: viscous_friction[axis 1]"});
  R.stop = "nothing missing";
  const json j = json::parse(loop_json(R, kAwkward, "out.yaml"));
  EXPECT_TRUE(j["waterfall"][0]["added"].is_null());
  EXPECT_EQ(j["waterfall"][0]["rms"].get<double>(), 0.6);
  EXPECT_EQ(j["waterfall"][0]["step"], 0);
  EXPECT_EQ(j["out"], "out.yaml");
  EXPECT_EQ(j["outside_library"], false);
}

}  // namespace
}  // namespace cpm::ident
