// SPDX-License-Identifier: Apache-2.0
// The YAML model file: bit-exact round trips with every effect kind, the
// default config equal to the nominal machine, refusal of bad files with
// FILE:LINE:COLUMN and the key path, and safe saving.
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <random>
#include <regex>

#include "cpm/io/model_file.hpp"
#include "io_test_util.hpp"
#include "support/random_models.hpp"

namespace cpm::io {
namespace {

using test::error_of;
using test::same_bits;
using test::ScratchDir;
using test::write_text;
using ::testing::HasSubstr;

// Every field of a MachineModel, compared bit for bit.
void expect_same_model(const ctl::MachineModel& a, const ctl::MachineModel& b) {
  const kin::KinematicModel& ka = a.kinematics;
  const kin::KinematicModel& kb = b.kinematics;
  EXPECT_TRUE(same_bits(ka.limbs.L, kb.limbs.L));
  EXPECT_TRUE(same_bits(ka.limbs.L1, kb.limbs.L1));
  EXPECT_TRUE(same_bits(ka.limbs.L2, kb.limbs.L2));
  EXPECT_TRUE(same_bits(ka.limbs.D, kb.limbs.D));
  EXPECT_EQ(ka.limbs.mode, kb.limbs.mode);
  EXPECT_TRUE(same_bits(ka.limbs.singularity_margin, kb.limbs.singularity_margin));
  EXPECT_TRUE(same_bits(ka.d0, kb.d0));
  for (int i = 0; i < 3; ++i) {
    SCOPED_TRACE("limb " + std::to_string(i + 1));
    EXPECT_TRUE(same_bits(ka.planes[i].normal, kb.planes[i].normal));
    EXPECT_TRUE(same_bits(ka.planes[i].scale, kb.planes[i].scale));
    EXPECT_TRUE(same_bits(ka.planes[i].offset, kb.planes[i].offset));
    for (int t = 0; t < kin::kKinematicEffectTypes; ++t) {
      const auto type = static_cast<kin::KinematicEffectType>(t);
      const auto pa = kin::get_params(ka.effects[i], type);
      const auto pb = kin::get_params(kb.effects[i], type);
      for (int j = 0; j < 3; ++j) EXPECT_TRUE(same_bits(pa[j], pb[j])) << kin::info(type).name << " " << j;
    }
  }
  EXPECT_TRUE(same_bits(a.strokes.min, b.strokes.min));
  EXPECT_TRUE(same_bits(a.strokes.max, b.strokes.max));
  EXPECT_TRUE(same_bits(a.masses.m1, b.masses.m1));
  EXPECT_TRUE(same_bits(a.masses.m2, b.masses.m2));
  EXPECT_TRUE(same_bits(a.masses.m3, b.masses.m3));
  EXPECT_TRUE(same_bits(a.masses.m4, b.masses.m4));
  EXPECT_TRUE(same_bits(a.force_limit, b.force_limit));
  ASSERT_EQ(a.effects.size(), b.effects.size());
  for (int k = 0; k < a.effects.size(); ++k) {
    EXPECT_EQ(a.effects[k].type, b.effects[k].type) << k;
    EXPECT_EQ(a.effects[k].axis, b.effects[k].axis) << k;
    for (int j = 0; j < 4; ++j) EXPECT_TRUE(same_bits(a.effects[k].param[j], b.effects[k].param[j])) << k;
  }
}

// A model that uses everything the file can hold: calibrated planes, every
// kinematic effect on every limb, every dynamic effect (out of enum order,
// two on one axis), other geometry, masses and strokes.
ModelFile everything(std::uint64_t seed) {
  std::mt19937_64 rng(seed);
  ModelFile mf;
  ctl::MachineModel& m = mf.model;
  m.kinematics = test::random_calibrated_kinematics(rng, true);
  m.kinematics.limbs.L2 = 0.37312345678;
  m.kinematics.limbs.singularity_margin = 0.06;
  m.kinematics.d0 = Vec3(0.2251, 0.2249, 1.0 / 3.0);
  m.strokes.min = Vec3(-0.001, 0.0, 0.002);
  m.strokes.max = Vec3(0.4, 0.399, 0.3);
  m.masses.m4 = 0.35;
  m.force_limit = 150.0;
  ctl::add_effect(m, "spring", 1, {120.0, 0.2});
  ctl::add_effect(m, "viscous_friction", 0, {12.5});
  ctl::add_effect(m, "coulomb_friction", 2, {3.0 / 7.0});
  ctl::add_effect(m, "stribeck_friction", 2, {1.5, 0.004});
  ctl::add_effect(m, "cogging", 0, {0.8, 0.012, -1.2});
  ctl::add_effect(m, "cogging", 0, {0.3, 0.004, 2.0});
  ctl::add_effect(m, "force_gain", 1, {-0.03});
  ctl::add_effect(m, "payload_mass", -1, {0.25});
  ctl::add_effect(m, "inertia_error", -1, {0.01, -0.002, 0.3, -0.1});
  ctl::add_effect(m, "actuator_inertia", 2, {157.91367041742973});  // 1e-4 kg m^2 on a 5 mm lead
  ctl::add_effect(m, "actuator_inertia", 0, {-0.75});
  mf.fitted.push_back({"kinematics.limb2.scale", "1", 1.0, 0.99987654321, 1.1e-6});
  mf.fitted.push_back({"effects.coulomb_friction.axis3.f_c", "N", 0.0, 3.0 / 7.0, -1.0});
  mf.history.push_back({"cpm calibrate --method ballbar", "runs/ball bar \"A\".csv",
                        std::string(64, 'a'), "2026-11-22T05:20:00Z", "line one\nline two: # not a comment"});
  mf.history.push_back({"cpm fit --add coulomb_friction:3", "motion.csv", "", "2026-11-23T00:00:00Z",
                        "Ünïcödé, tabs\tand \\backslashes"});
  return mf;
}

TEST(ModelFile, NominalModelRoundTripsBitExactly) {
  ModelFile mf;
  const ModelFile back = parse_model_file(render_model_file(mf), "nominal.yaml");
  expect_same_model(back.model, ctl::MachineModel::elkady());
  EXPECT_TRUE(back.fitted.empty());
  EXPECT_TRUE(back.history.empty());
}

TEST(ModelFile, EveryEffectKindRoundTripsBitExactlyOverManySeeds) {
  ScratchDir dir;
  for (std::uint64_t seed = 1; seed <= 20; ++seed) {
    SCOPED_TRACE("seed " + std::to_string(seed));
    const ModelFile mf = everything(seed);
    const std::string path = dir.path(std::to_string(seed).append("m.yaml"));
    save_model_file(path, mf);
    const ModelFile back = load_model_file(path);
    expect_same_model(back.model, mf.model);
    ASSERT_EQ(back.fitted.size(), mf.fitted.size());
    for (std::size_t i = 0; i < mf.fitted.size(); ++i) {
      EXPECT_EQ(back.fitted[i].name, mf.fitted[i].name);
      EXPECT_EQ(back.fitted[i].unit, mf.fitted[i].unit);
      EXPECT_TRUE(same_bits(back.fitted[i].nominal, mf.fitted[i].nominal));
      EXPECT_TRUE(same_bits(back.fitted[i].value, mf.fitted[i].value));
      EXPECT_TRUE(same_bits(back.fitted[i].std_error, mf.fitted[i].std_error));
    }
    ASSERT_EQ(back.history.size(), mf.history.size());
    for (std::size_t i = 0; i < mf.history.size(); ++i) {
      EXPECT_EQ(back.history[i].tool, mf.history[i].tool);
      EXPECT_EQ(back.history[i].data_file, mf.history[i].data_file);
      EXPECT_EQ(back.history[i].data_sha256, mf.history[i].data_sha256);
      EXPECT_EQ(back.history[i].date, mf.history[i].date);
      EXPECT_EQ(back.history[i].note, mf.history[i].note);
    }
    // Rendering what was loaded gives the same text.
    EXPECT_EQ(render_model_file(back), test::read_text(path));
  }
}

TEST(ModelFile, FileNamesEffectsAndUnitsForAPersonToRead) {
  const std::string text = render_model_file(everything(3));
  // Effects by their docs/effects.md names, parameters by their names, units beside them.
  EXPECT_THAT(text, HasSubstr("      backlash:\n        b: "));
  EXPECT_THAT(text, HasSubstr("  - effect: coulomb_friction\n    axis: 3\n    f_c: "));
  EXPECT_THAT(text, HasSubstr("  - effect: payload_mass\n    dm: 0.25"));
  EXPECT_THAT(text, ::testing::ContainsRegex("  - effect: actuator_inertia\n    axis: 3\n    m: 157.91367041742973 +# kg"));
  EXPECT_THAT(text, ::testing::ContainsRegex("lambda: 0.012 +# m"));
  EXPECT_THAT(text, ::testing::ContainsRegex("force_limit: 150 +# N"));
  // Nominal values print short (shortest exact form, not 17 digits).
  EXPECT_THAT(render_model_file(ModelFile{}), HasSubstr("d0: 0.225 "));
}

TEST(ModelFile, DefaultConfigIsTheNominalMachine) {
  // Tests run in the source tree (tests/CMakeLists.txt WORKING_DIRECTORY).
  const ModelFile mf = load_model_file("config/machine.yaml");
  expect_same_model(mf.model, ctl::MachineModel::elkady());
  EXPECT_TRUE(mf.fitted.empty());
}

TEST(ModelFile, ActuationDelayLoadsFromTheEffectTableAndRoundTrips) {
  // A machine-wide dynamic effect without an axis, like payload_mass.
  const ModelFile mf = parse_model_file(
      render_model_file(ModelFile{}).replace(render_model_file(ModelFile{}).find("dynamic_effects: []"),
                                             std::string("dynamic_effects: []").size(),
                                             "dynamic_effects:\n  - {effect: actuation_delay, tau: 0.001}"),
      "delay.yaml");
  ASSERT_EQ(mf.model.effects.size(), 1u);
  EXPECT_EQ(mf.model.effects[0].type, ctl::DynamicEffectType::actuation_delay);
  EXPECT_EQ(ctl::Machine(mf.model).actuation_delay(), 0.001);
  const ModelFile back = parse_model_file(render_model_file(mf), "back.yaml");
  EXPECT_EQ(ctl::Machine(back.model).actuation_delay(), 0.001);
  // The bounds of the effect library: 0 .. 0.05 s.
  EXPECT_THROW(parse_model_file(render_model_file(ModelFile{}).replace(
                                    render_model_file(ModelFile{}).find("dynamic_effects: []"),
                                    std::string("dynamic_effects: []").size(),
                                    "dynamic_effects:\n  - {effect: actuation_delay, tau: 0.2}"),
                                "far.yaml"),
               Error);
  // canopen.yaml's model: machine.yaml and one period at its 1 kHz, nothing
  // else (the two files must not drift apart).
  ModelFile bus = load_model_file("config/machine-canopen.yaml");
  EXPECT_EQ(ctl::Machine(bus.model).actuation_delay(), 0.001);
  ASSERT_EQ(bus.model.effects.size(), 1u);
  bus.model.effects.clear();
  expect_same_model(bus.model, load_model_file("config/machine.yaml").model);
}

// --- Refusals ---------------------------------------------------------------

std::string nominal_text() { return render_model_file(ModelFile{}); }

// Replace the first occurrence of `from` (which must exist) in the nominal file.
std::string edited(const std::string& from, const std::string& to) {
  std::string t = nominal_text();
  const auto pos = t.find(from);
  if (pos == std::string::npos) throw std::runtime_error("test: '" + from + "' not in the file");
  return t.replace(pos, from.size(), to);
}

int line_of(const std::string& text, const std::string& needle) {
  const auto pos = text.find(needle);
  return 1 + static_cast<int>(std::count(text.begin(), text.begin() + static_cast<long>(pos), '\n'));
}

TEST(ModelFile, ActuatorInertiaLoadsPerAxisAndTheMachineRefusesANegativeTotal) {
  const ModelFile mf = parse_model_file(edited("dynamic_effects: []", "dynamic_effects:\n  - {effect: actuator_inertia, axis: 2, m: 2.5}"),
                                        "rotor.yaml");
  EXPECT_EQ(ctl::Machine(mf.model).reflected_masses(), Vec3(0.0, 2.5, 0.0));
  // Without its axis, or with more mass taken off than the platform puts on axis 1.
  EXPECT_THAT(error_of([&] {
                parse_model_file(edited("dynamic_effects: []", "dynamic_effects:\n  - {effect: actuator_inertia, m: 2.5}"),
                                 "noaxis.yaml");
              }),
              HasSubstr("axis"));
  EXPECT_THAT(error_of([&] {
                parse_model_file(
                    edited("dynamic_effects: []", "dynamic_effects:\n  - {effect: actuator_inertia, axis: 1, m: -4.9}"),
                    "light.yaml");
              }),
              HasSubstr("negative inertia"));
}

TEST(ModelFile, WrongTypeNamesFileLineAndKeyPath) {
  const std::string t = edited("    scale: 1 ", "    scale: 1\n    scale: abc ");
  EXPECT_THAT(error_of([&] { parse_model_file(t, "m.yaml"); }), HasSubstr("key given twice"));
  // The second limb's scale made a word: the message points at it.
  std::string t2 = nominal_text();
  const auto l2 = t2.find("  limb2:");
  const auto sc = t2.find("scale: 1", l2);
  t2.replace(sc, 8, "scale: abc");
  const int line = line_of(t2, "scale: abc");
  EXPECT_EQ(error_of([&] { parse_model_file(t2, "m.yaml"); }),
            "m.yaml:" + std::to_string(line) + ":12: kinematics.limb2.scale: expected a number, got 'abc'");
  EXPECT_THAT(error_of([&] { parse_model_file(edited("normal: [1, 0, 0]", "normal: [1, 0]"), "m.yaml"); }),
              HasSubstr("kinematics.limb1.normal: expected a list of 3 numbers"));
  EXPECT_THAT(error_of([&] { parse_model_file(edited("force_limit: 120", "force_limit: [120]"), "m.yaml"); }),
              HasSubstr("force_limit: expected a number, got a list"));
  EXPECT_THAT(error_of([&] { parse_model_file(edited("    effects: {}", "    effects: backlash"), "m.yaml"); }),
              HasSubstr("kinematics.limb1.effects: expected a mapping (key: value lines), got 'backlash'"));
  EXPECT_THAT(error_of([&] { parse_model_file(edited("m2: 0.695528", "m2: .nan"), "m.yaml"); }),
              HasSubstr("masses.m2: '.nan' is not a finite number"));
}

TEST(ModelFile, UnknownAndMissingKeysAreRefused) {
  const std::string t = edited("    offset: 0 ", "    offest: 0 ");
  const std::string e = error_of([&] { parse_model_file(t, "m.yaml"); });
  EXPECT_THAT(e, HasSubstr("m.yaml:" + std::to_string(line_of(t, "offest")) + ":5: kinematics.limb1.offest: unknown key"));
  const std::string t2 = edited("  m3: 0.2 ", "  m5: 0.2 ");
  EXPECT_THAT(error_of([&] { parse_model_file(t2, "m.yaml"); }), HasSubstr("masses.m5: unknown key"));
  const std::string t3 = edited("  L2: 0.373", "  #L2: 0.373");
  EXPECT_THAT(error_of([&] { parse_model_file(t3, "m.yaml"); }),
              HasSubstr("geometry: missing required key 'L2'"));
  EXPECT_THAT(error_of([&] { parse_model_file(edited("force_limit:", "#force_limit:"), "m.yaml"); }),
              HasSubstr("missing required key 'force_limit'"));
  EXPECT_THAT(error_of([&] { parse_model_file(edited("cpmd_model: 1", "cpmd_model: 2"), "m.yaml"); }),
              HasSubstr("cpmd_model: format version 2 is not known"));
  EXPECT_THAT(error_of([&] { parse_model_file("", "m.yaml"); }), HasSubstr("m.yaml: empty model file"));
  EXPECT_THAT(error_of([&] { parse_model_file("geometry: [1, 2\n", "m.yaml"); }),
              ::testing::MatchesRegex("m\\.yaml:[0-9]+:[0-9]+: not valid YAML: .*"));
}

TEST(ModelFile, OutOfRangeValuesAreRefused) {
  auto err = [](const std::string& from, const std::string& to) {
    return error_of([&] { parse_model_file(edited(from, to), "m.yaml"); });
  };
  EXPECT_THAT(err("  m1: 1.892994", "  m1: -1"), HasSubstr("masses.m1: -1 kg is out of range: must be >= 0"));
  EXPECT_THAT(err("force_limit: 120", "force_limit: 0"), HasSubstr("force_limit: 0 N is out of range"));
  EXPECT_THAT(err("  L1: 0.5", "  L1: -0.5"), HasSubstr("geometry.L1: -0.5 m is out of range"));
  EXPECT_THAT(err("    scale: 1 ", "    scale: 2 "), HasSubstr("kinematics.limb1.scale: 2"));
  EXPECT_THAT(err("normal: [1, 0, 0]", "normal: [1, 0.1, 0]"),
              HasSubstr("kinematics.limb1.normal: the plane normal must be a unit vector"));
  // The message offers the normalized vector, and that vector is accepted.
  const std::string e = err("normal: [1, 0, 0]", "normal: [1, 0.1, 0]");
  const auto b = e.find("normalized: ["), close = e.find(']', b);
  ASSERT_NE(b, std::string::npos);
  EXPECT_EQ(err("normal: [1, 0, 0]", "normal: " + e.substr(b + 12, close - b - 11)), "");
  EXPECT_THAT(err("normal: [1, 0, 0]", "normal: [0, 1, 0]"), HasSubstr("must point along the limb's own axis"));
  EXPECT_THAT(err("assembly_mode: 1", "assembly_mode: 0"), HasSubstr("kinematics.limb1.assembly_mode: must be 1 or -1"));
  EXPECT_THAT(err("stroke: [0, 0.4]", "stroke: [0.4, 0]"), HasSubstr("kinematics.limb1.stroke: min must be below max"));
}

TEST(ModelFile, EffectsAreCheckedByNameParameterAndBounds) {
  auto err = [](const std::string& from, const std::string& to) {
    return error_of([&] { parse_model_file(edited(from, to), "m.yaml"); });
  };
  const std::string limb2_effects = "    effects: {}";
  // Find limb 2's effects line: replace the second occurrence.
  auto limb2 = [&](const std::string& block) {
    std::string t = nominal_text();
    const auto p = t.find(limb2_effects, t.find("  limb2:"));
    t.replace(p, limb2_effects.size(), block);
    return error_of([&] { parse_model_file(t, "m.yaml"); });
  };
  EXPECT_EQ(limb2("    effects:\n      backlash: {b: 2e-5}"), "");
  EXPECT_THAT(limb2("    effects:\n      backlash: {b: -2e-5}"),
              HasSubstr("kinematics.limb2.effects.backlash.b: -2e-05 m is out of range"));
  EXPECT_THAT(limb2("    effects:\n      backlash: {c: 2e-5}"),
              HasSubstr("kinematics.limb2.effects.backlash.c: unknown key"));
  EXPECT_THAT(limb2("    effects:\n      cyclic_error: {a: 1e-6, phi: 0}"),
              HasSubstr("kinematics.limb2.effects.cyclic_error: missing required key 'lambda'"));
  EXPECT_THAT(limb2("    effects:\n      friction: {b: 1}"),
              HasSubstr("kinematics.limb2.effects.friction: unknown key (expected one of: actuator_scale, backlash"));
  EXPECT_THAT(err("dynamic_effects: []", "dynamic_effects:\n  - {effect: coulomb_friction, axis: 3, f_c: -1}"),
              HasSubstr("dynamic_effects[0](coulomb_friction).f_c: -1 N is out of range"));
  EXPECT_THAT(err("dynamic_effects: []", "dynamic_effects:\n  - {effect: coulomb_friction, f_c: 1}"),
              HasSubstr("dynamic_effects[0](coulomb_friction): missing required key 'axis'"));
  EXPECT_THAT(err("dynamic_effects: []", "dynamic_effects:\n  - {effect: coulomb_friction, axis: 4, f_c: 1}"),
              HasSubstr("axis: must be 1, 2 or 3"));
  EXPECT_THAT(err("dynamic_effects: []", "dynamic_effects:\n  - {effect: payload_mass, axis: 1, dm: 1}"),
              HasSubstr("payload_mass acts on all axes together: give no axis"));
  EXPECT_THAT(err("dynamic_effects: []", "dynamic_effects:\n  - {effect: stiction, axis: 1}"),
              HasSubstr("unknown dynamic effect 'stiction'"));
  // The prepared machine's own check: with this inertia error A would be negative.
  EXPECT_THAT(err("dynamic_effects: []", "dynamic_effects:\n  - {effect: inertia_error, dA: -10, dB: 0, dC: 0, dE: 0}"),
              HasSubstr("m.yaml: model: with its effects the machine has A = "));
  EXPECT_THAT(err("history: []", "history:\n  - {tool: x, date: y, data_sha256: abc}"),
              HasSubstr("history[0].data_sha256: expected 64 lowercase hexadecimal digits"));
  EXPECT_THAT(err("fitted: []", "fitted:\n  - {name: a, unit: m, nominal: 0}"),
              HasSubstr("fitted[0]: missing required key 'value'"));
}

// --- Saving -----------------------------------------------------------------

TEST(ModelFile, SaveNeverOverwritesTheInput) {
  ScratchDir dir;
  const std::string in = dir.path("in.yaml");
  save_model_file(in, ModelFile{});
  const std::string before = test::read_text(in);
  const ModelFile changed = everything(5);
  EXPECT_THAT(error_of([&] { save_model_file(in, changed, in); }), HasSubstr("refusing to overwrite the input"));
  // The same file by another spelling.
  const std::string other = (dir.dir() / "." / "sub" / ".." / "in.yaml").string();
  std::filesystem::create_directory(dir.path("sub"));
  EXPECT_THAT(error_of([&] { save_model_file(other, changed, in); }), HasSubstr("refusing"));
  // Through a symbolic link.
  std::filesystem::create_symlink(in, dir.path("link.yaml"));
  EXPECT_THAT(error_of([&] { save_model_file(dir.path("link.yaml"), changed, in); }), HasSubstr("refusing"));
  EXPECT_EQ(test::read_text(in), before);
  // Another file is fine.
  save_model_file(dir.path("out.yaml"), changed, in);
  expect_same_model(load_model_file(dir.path("out.yaml")).model, changed.model);
}

TEST(ModelFile, FailedSaveLeavesTheOldFile) {
  ScratchDir dir;
  std::filesystem::create_directory(dir.path("model.yaml"));
  EXPECT_THAT(error_of([&] { save_model_file(dir.path("model.yaml"), ModelFile{}); }), HasSubstr("cannot rename"));
  EXPECT_TRUE(std::filesystem::is_directory(dir.path("model.yaml")));
  EXPECT_EQ(dir.entries(), 1);
  // A model that would not load back is not written at all.
  const std::string path = dir.path("good.yaml");
  save_model_file(path, ModelFile{});
  const std::string before = test::read_text(path);
  ModelFile bad;
  bad.model.kinematics.effects[0].actuator_scale = 0.2;  // beyond docs/effects.md's physical bound
  EXPECT_THAT(error_of([&] { save_model_file(path, bad); }), HasSubstr("kinematics.limb1.effects.actuator_scale.s"));
  EXPECT_EQ(test::read_text(path), before);
}

TEST(ModelFile, Sha256MatchesTheStandardVectors) {
  ScratchDir dir;
  write_text(dir.path("abc"), "abc");
  write_text(dir.path("empty"), "");
  // FIPS 180-2 example and the hash of no bytes.
  EXPECT_EQ(sha256_file(dir.path("abc")), "ba7816bf8f01cfea414140de5dae2223b00361a396177a9cb410ff61f20015ad");
  EXPECT_EQ(sha256_file(dir.path("empty")), "e3b0c44298fc1c149afbf4c8996fb92427ae41e4649b934ca495991b7852b855");
  EXPECT_THAT(error_of([&] { sha256_file(dir.path("none")); }), HasSubstr("none: cannot read"));
}

TEST(ModelFile, ProvenanceHashesTheDataFile) {
  ScratchDir dir;
  write_text(dir.path("abc.csv"), "abc");
  const Provenance p = make_provenance("cpm calibrate", dir.path("abc.csv"), "note");
  EXPECT_EQ(p.data_sha256, "ba7816bf8f01cfea414140de5dae2223b00361a396177a9cb410ff61f20015ad");
  EXPECT_EQ(p.tool, "cpm calibrate");
  EXPECT_EQ(p.note, "note");
  EXPECT_EQ(p.date.size(), 20u);
  EXPECT_EQ(make_provenance("cpm model init", "").data_sha256, "");
}

TEST(ModelFile, NowIsIso8601Utc) {
  EXPECT_TRUE(std::regex_match(utc_now_iso8601(), std::regex(R"(\d{4}-\d\d-\d\dT\d\d:\d\d:\d\dZ)")));
}

}  // namespace
}  // namespace cpm::io

namespace cpm::io {
namespace {

TEST(ModelFile, TheExampleOfTheDocsLoads) {
  const std::string doc = test::read_text("docs/model-file.md");
  const auto begin = doc.find("```yaml\n");
  ASSERT_NE(begin, std::string::npos);
  const auto end = doc.find("```", begin + 8);
  const ModelFile mf = parse_model_file(doc.substr(begin + 8, end - begin - 8), "docs/model-file.md");
  EXPECT_EQ(mf.model.effects.size(), 3);
  EXPECT_EQ(mf.model.kinematics.effects[1].backlash, 1.2e-5);
  EXPECT_EQ(mf.history.size(), 2u);
  ASSERT_EQ(mf.fitted.size(), 2u);
  EXPECT_EQ(mf.fitted[0].name, "kinematics.limb3.scale");
}

}  // namespace
}  // namespace cpm::io
