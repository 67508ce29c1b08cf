// SPDX-License-Identifier: Apache-2.0
// User effects in the model file (docs/model-file.md, `user_effects`): table,
// expression and pitch_table round-trip bit for bit, and a bad one is
// refused naming the file, line, effect index and key.
#include <gtest/gtest.h>
#include <gmock/gmock.h>

#include "cpm/io/model_file.hpp"
#include "io_test_util.hpp"

namespace cpm::io {
namespace {

using ::testing::HasSubstr;

const char* kNominal = "config/machine.yaml";

std::string with_user_effects(const std::string& block) {
  return test::read_text(kNominal) + "\n" + block;
}

ModelFile user_model() {
  ModelFile mf;
  ctl::MachineModel& m = mf.model;
  ctl::UserEffect t;
  t.kind = ctl::UserEffectKind::table;
  t.axis = 1;
  t.input = 'v';
  t.input_axis = 0;
  t.nodes = {-0.3, -0.01, 0.0, 0.01, 1.0 / 3.0};
  t.values = {-4.25, -1.0 / 7.0, 0.0, 0.125, 3.0};
  m.user_effects.push_back(t);
  ctl::UserEffect x;
  x.kind = ctl::UserEffectKind::expression;
  x.axis = 2;
  x.formula = "c*v1 + k*(d3 - 0.1)^2 + 0*t";
  x.params = {{"k", "N/m^2", 1.0 / 3.0, -1e3, 1e3}, {"c", "N s/m", 3.0, -100.0, std::numeric_limits<double>::infinity()}};
  m.user_effects.push_back(x);
  kin::PitchTable& p = m.kinematics.effects[0].pitch_table;
  p.size = 4;
  p.node = {0.0, 0.1, 0.2, 0.4};
  p.error = {0.0, 1.5e-6, 2.25e-6, -3.0e-6};
  return mf;
}

TEST(ModelFileUser, TablesExpressionsAndPitchTablesRoundTripBitExactly) {
  test::ScratchDir dir;
  const ModelFile mf = user_model();
  save_model_file(dir.path("u.yaml"), mf);
  const ModelFile back = load_model_file(dir.path("u.yaml"));
  ASSERT_EQ(back.model.user_effects.size(), 2u);
  EXPECT_TRUE(back.model.user_effects == mf.model.user_effects);  // doubles compared with ==: same values
  for (std::size_t i = 0; i < 2; ++i)
    for (std::size_t k = 0; k < back.model.user_effects[i].nodes.size(); ++k)
      EXPECT_TRUE(test::same_bits(back.model.user_effects[i].nodes[k], mf.model.user_effects[i].nodes[k]));
  EXPECT_EQ(back.model.user_effects[1].params[0].name, "k");  // the file's order kept
  const kin::PitchTable& a = back.model.kinematics.effects[0].pitch_table;
  const kin::PitchTable& b = mf.model.kinematics.effects[0].pitch_table;
  ASSERT_EQ(a.size, b.size);
  for (int k = 0; k < a.size; ++k) {
    EXPECT_TRUE(test::same_bits(a.node[k], b.node[k]));
    EXPECT_TRUE(test::same_bits(a.error[k], b.error[k]));
  }
  EXPECT_TRUE(back.model.kinematics.effects[1].pitch_table.empty());
  EXPECT_EQ(render_model_file(back), test::read_text(dir.path("u.yaml")));
  // A model without user effects renders without the section: old files unchanged.
  EXPECT_EQ(render_model_file(ModelFile{}).find("user_effects"), std::string::npos);
}

TEST(ModelFileUser, TheDocsExampleLoads) {
  const std::string doc = test::read_text("docs/model-file.md");
  const auto begin = doc.find("```yaml\nuser_effects:");
  ASSERT_NE(begin, std::string::npos);
  const auto end = doc.find("```", begin + 8);
  const ModelFile mf =
      parse_model_file(with_user_effects(doc.substr(begin + 8, end - begin - 8)), "docs/model-file.md");
  EXPECT_EQ(mf.model.user_effects.size(), 2u);
  EXPECT_FALSE(mf.model.kinematics.effects[0].pitch_table.empty());
}

std::string refusal(const std::string& block) {
  return test::error_of([&] { (void)parse_model_file(with_user_effects(block), "m.yaml"); });
}

TEST(ModelFileUser, BadUserEffectsNameFileLineIndexAndKey) {
  const std::string nominal = test::read_text(kNominal);
  // The block starts after the nominal file and one blank line.
  const int base = static_cast<int>(std::count(nominal.begin(), nominal.end(), '\n')) + 1;
  const std::string L = "m.yaml:" + std::to_string(base + 4);  // the 4th line of the block
  EXPECT_THAT(refusal("user_effects:\n  - kind: table\n    axis: 2\n    input: d2\n    nodes: [0.1, 0.3, 0.2]\n    values: [0, 1, 2]\n"),
              HasSubstr(":" + std::to_string(base + 5) + ":12: user_effects[0].nodes[2]: nodes must be strictly increasing: 0.2 is not above 0.3"));
  EXPECT_THAT(refusal("user_effects:\n  - kind: expression\n    axis: 2\n    formula: \"c*x1\"\n    params: {c: {value: 1}}\n"),
              HasSubstr(L + ":14: user_effects[0].formula: unknown variable 'x1' in 'c*x1' (known: d1..d3, v1..v3, a1..a3, t, c)"));
  EXPECT_THAT(refusal("user_effects:\n  - kind: expression\n    axis: 2\n    formula: \"c*(v1\"\n    params: {c: {value: 1}}\n"),
              HasSubstr(L + ":14: user_effects[0].formula: 'c*(v1' does not parse: Missing parenthesis (at position 6)"));
  EXPECT_THAT(refusal("user_effects:\n  - kind: expression\n    axis: 1\n    formula: \"c*v1\"\n    params: {c: {value: 300, lower: -100, upper: 100, unit: \"N s/m\"}}\n"),
              HasSubstr("user_effects[0].params.c.value: 300 N s/m is outside its bounds [-100, 100]"));
  EXPECT_THAT(refusal("user_effects:\n  - kind: spline\n    axis: 1\n"),
              HasSubstr("user_effects[0].kind: unknown kind 'spline' (one of: table, expression, pitch_table)"));
  EXPECT_THAT(refusal("user_effects:\n  - kind: table\n    axis: 1\n    input: a1\n    nodes: [0, 1]\n    values: [0, 1]\n"),
              HasSubstr("user_effects[0].input: 'a1' must be d1..d3 (position) or v1..v3 (velocity)"));
  EXPECT_THAT(refusal("user_effects:\n  - kind: pitch_table\n    axis: 3\n    nodes: [0, 0.1]\n    values: [0, 1e-6]\n  - kind: pitch_table\n    axis: 3\n    nodes: [0, 0.1]\n    values: [0, 1e-6]\n"),
              HasSubstr("user_effects[1].axis: a second pitch_table on this axis (one per axis)"));
  EXPECT_THAT(refusal("user_effects:\n  - kind: table\n    axis: 1\n    input: d1\n    nodes: [0, 1]\n    values: [0, 1]\n    unit: N\n"),
              HasSubstr("user_effects[0].unit: unknown key"));
  // What may be told to a stranger (cpmd's answer) holds no byte of the formula.
  try {
    (void)parse_model_file(with_user_effects("user_effects:\n  - kind: expression\n    axis: 2\n    formula: \"secret*x1\"\n"), "m.yaml");
    FAIL();
  } catch (const ModelFileError& e) {
    EXPECT_EQ(e.summary, "user_effects[0]: not a usable user effect");
  }
}

}  // namespace
}  // namespace cpm::io
