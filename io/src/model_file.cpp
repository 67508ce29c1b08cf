// SPDX-License-Identifier: Apache-2.0
// The YAML model file (docs/model-file.md): rendering by hand, so that the
// file carries a unit comment on every number and doubles in their shortest
// exact form; loading through yaml-cpp with a strict walker that refuses
// unknown keys, missing keys, wrong types and out-of-range values, naming
// FILE:LINE:COLUMN and the key path.
#include "cpm/io/model_file.hpp"

#include <yaml-cpp/yaml.h>

#include <cmath>
#include <algorithm>
#include <filesystem>
#include <map>
#include <numbers>
#include <set>
#include <sstream>

#include "util.hpp"

namespace cpm::io {

namespace {

constexpr int kFormatVersion = 1;

// ------------------------------------------------------------------ loading

std::string join(const std::string& path, const std::string& key) {
  return path.empty() ? key : path + "." + key;
}

std::string describe_node(const YAML::Node& n) {
  switch (n.Type()) {
    case YAML::NodeType::Null: return "nothing (null)";
    case YAML::NodeType::Sequence: return "a list";
    case YAML::NodeType::Map: return "a mapping";
    case YAML::NodeType::Scalar: return "'" + n.Scalar() + "'";
    default: return "an undefined value";
  }
}

class Loader {
 public:
  explicit Loader(std::string file) : file_(std::move(file)) {}

  // `why` says what is wrong without a byte of the file (it may go over the
  // network: ModelFileError::summary); `told` (default: `why`) may quote
  // what was read, for the local user. `public_path` replaces `path` in the
  // summary when the path itself holds a name from the file.
  [[noreturn]] void fail(const YAML::Node& n, const std::string& path, const std::string& why,
                         const std::string& told = "", const std::string* public_path = nullptr) const {
    std::string where = file_;
    const YAML::Mark m = n.Mark();
    const int line = m.line >= 0 ? m.line + 1 : 0;
    if (m.line >= 0) where += ":" + std::to_string(line) + ":" + std::to_string(m.column + 1);
    const std::string& pp = public_path ? *public_path : path;
    throw ModelFileError(where + ": " + (path.empty() ? "" : path + ": ") + (told.empty() ? why : told), line,
                         (pp.empty() ? "" : pp + ": ") + why);
  }
  // "WHAT, got <what the node is>" locally; "WHAT" in the summary.
  [[noreturn]] void fail_got(const YAML::Node& n, const std::string& path, const std::string& what) const {
    fail(n, path, what, what + ", got " + describe_node(n));
  }

  double number(const YAML::Node& n, const std::string& path) const {
    if (!n.IsScalar()) fail_got(n, path, "expected a number");
    const std::string& s = n.Scalar();
    double v;
    if (!detail::parse_double(detail::trim(s), v)) {
      if (s == ".inf" || s == "-.inf" || s == "+.inf" || s == ".nan" || s == ".NaN" || s == ".Inf")
        fail(n, path, "not a finite number", "'" + s + "' is not a finite number");
      fail(n, path, "expected a number", "expected a number, got '" + s + "'");
    }
    if (!std::isfinite(v)) fail(n, path, "not a finite number", "'" + s + "' is not a finite number");
    return v;
  }

  double number_in(const YAML::Node& n, const std::string& path, double lo, double hi,
                   const char* unit, bool open_lo = false) const {
    const double v = number(n, path);
    if (v < lo || v > hi || (open_lo && v == lo)) {
      std::ostringstream range;
      range << "out of range: must be " << (open_lo ? "> " : ">= ") << lo;
      if (hi < 1e300) range << " and <= " << hi;
      std::ostringstream told;
      told << v << " " << unit << " is " << range.str();
      fail(n, path, range.str() + (*unit ? std::string(" ") + unit : ""), told.str());
    }
    return v;
  }

  long integer(const YAML::Node& n, const std::string& path) const {
    const double v = number(n, path);
    if (v != std::floor(v) || std::abs(v) > 1e9)
      fail(n, path, "expected an integer", "expected an integer, got '" + n.Scalar() + "'");
    return static_cast<long>(v);
  }

  std::string text(const YAML::Node& n, const std::string& path) const {
    if (n.IsNull()) return "";
    if (!n.IsScalar()) fail_got(n, path, "expected a text");
    return n.Scalar();
  }

  Vec3 vec3(const YAML::Node& n, const std::string& path) const {
    if (!n.IsSequence() || n.size() != 3)
      fail(n, path, "expected a list of 3 numbers [x, y, z]",
           "expected a list of 3 numbers [x, y, z], got " + describe_node(n) +
               (n.IsSequence() ? " of " + std::to_string(n.size()) : ""));
    static const char* axis[] = {"x", "y", "z"};
    Vec3 v;
    for (std::size_t i = 0; i < 3; ++i) v[static_cast<int>(i)] = number(n[i], join(path, axis[i]));
    return v;
  }

  const std::string& file() const { return file_; }

 private:
  std::string file_;
};

// A mapping whose keys are checked: unknown and duplicate keys are refused.
class Map {
 public:
  Map(const Loader& ld, const YAML::Node& n, std::string path, std::set<std::string> allowed)
      : ld_(ld), node_(n), path_(std::move(path)) {
    if (!n.IsMap()) ld.fail_got(n, path_, "expected a mapping (key: value lines)");
    for (auto it = n.begin(); it != n.end(); ++it) {
      if (!it->first.IsScalar()) ld.fail(it->first, path_, "a key must be a plain name");
      const std::string key = it->first.Scalar();
      if (!allowed.count(key)) {
        std::string list;
        for (const auto& a : allowed) list += (list.empty() ? "" : ", ") + a;
        const std::string where = path_.empty() ? "(top level)" : path_;
        ld.fail(it->first, join(path_, key), "unknown key (expected one of: " + list + ")", "", &where);
      }
      if (!items_.emplace(key, it->second).second)
        ld.fail(it->first, join(path_, key), "key given twice");
    }
  }
  bool has(const std::string& key) const { return items_.count(key) != 0; }
  YAML::Node get(const std::string& key) const {
    const auto it = items_.find(key);
    if (it == items_.end()) ld_.fail(node_, path_, "missing required key '" + key + "'");
    return it->second;
  }
  std::string path(const std::string& key) const { return join(path_, key); }
  const std::map<std::string, YAML::Node>& items() const { return items_; }
  double number(const std::string& key) const { return ld_.number(get(key), path(key)); }

 private:
  const Loader& ld_;
  YAML::Node node_;
  std::string path_;
  std::map<std::string, YAML::Node> items_;
};

std::set<std::string> kinematic_effect_names() {
  std::set<std::string> s;
  for (int t = 0; t < kin::kKinematicEffectTypes; ++t)
    s.insert(kin::info(static_cast<kin::KinematicEffectType>(t)).name);
  return s;
}

bool is_hex64(const std::string& s) {
  if (s.size() != 64) return false;
  for (char c : s)
    if (!((c >= '0' && c <= '9') || (c >= 'a' && c <= 'f'))) return false;
  return true;
}

void load_limb(const Loader& ld, const Map& parent, int i, ctl::MachineModel& m) {
  const std::string key = "limb" + std::to_string(i + 1);
  const Map limb(ld, parent.get(key), parent.path(key),
                 {"assembly_mode", "d0", "stroke", "normal", "scale", "offset", "effects"});
  kin::KinematicModel& km = m.kinematics;
  {
    const long mode = ld.integer(limb.get("assembly_mode"), limb.path("assembly_mode"));
    if (mode != 1 && mode != -1)
      ld.fail(limb.get("assembly_mode"), limb.path("assembly_mode"), "must be 1 or -1");
    km.limbs.mode[i] = static_cast<int>(mode);
  }
  km.d0[i] = limb.number("d0");
  {
    const YAML::Node s = limb.get("stroke");
    if (!s.IsSequence() || s.size() != 2)
      ld.fail_got(s, limb.path("stroke"), "expected [min, max] in m");
    m.strokes.min[i] = ld.number(s[0], limb.path("stroke") + ".min");
    m.strokes.max[i] = ld.number(s[1], limb.path("stroke") + ".max");
    if (!(m.strokes.max[i] > m.strokes.min[i]))
      ld.fail(s, limb.path("stroke"), "min must be below max");
  }
  kin::LimbPlane& pl = km.planes[i];
  pl.normal = ld.vec3(limb.get("normal"), limb.path("normal"));
  if (std::abs(pl.normal.norm() - 1.0) > 1e-9) {
    std::ostringstream os;
    os.precision(17);
    os << "the plane normal must be a unit vector; its length is " << pl.normal.norm();
    if (pl.normal.norm() > 0.0) {
      const Vec3 u = pl.normal.normalized();
      os << " (normalized: [" << detail::format_double(u.x()) << ", " << detail::format_double(u.y())
         << ", " << detail::format_double(u.z()) << "])";
    }
    ld.fail(limb.get("normal"), limb.path("normal"), "the plane normal must be a unit vector", os.str());
  }
  if (!(pl.normal[i] > 0.5))
    ld.fail(limb.get("normal"), limb.path("normal"),
            "the plane normal must point along the limb's own axis (component " +
                std::string(1, "xyz"[i]) + " > 0.5)");
  pl.scale = ld.number_in(limb.get("scale"), limb.path("scale"), 0.5, 1.5, "", true);
  if (pl.scale == 1.5) ld.fail(limb.get("scale"), limb.path("scale"), "must be < 1.5");
  pl.offset = limb.number("offset");
  if (!limb.has("effects")) return;
  const YAML::Node en = limb.get("effects");
  if (en.IsNull()) return;
  const Map effects(ld, en, limb.path("effects"), kinematic_effect_names());
  for (const auto& [name, node] : effects.items()) {
    const auto type = *kin::kinematic_effect_from_name(name);
    const kin::KinematicEffectInfo& in = kin::info(type);
    std::set<std::string> pnames;
    for (int j = 0; j < in.n_params; ++j) pnames.insert(in.params[j].name);
    const Map pm(ld, node, effects.path(name), pnames);
    std::array<double, 3> v{};
    for (int j = 0; j < in.n_params; ++j) {
      const auto& p = in.params[j];
      v[j] = ld.number_in(pm.get(p.name), pm.path(p.name), p.lower, p.upper, p.unit);
    }
    kin::set_params(km.effects[i], type, v);
  }
}

ctl::DynamicEffect load_dynamic_effect(const Loader& ld, const YAML::Node& n, const std::string& path) {
  if (!n.IsMap()) ld.fail(n, path, "expected a mapping {effect: NAME, axis: N, params...}");
  const YAML::Node name_node = n["effect"];
  if (!name_node) ld.fail(n, path, "missing required key 'effect' (the effect's name of docs/effects.md)");
  const std::string name = ld.text(name_node, join(path, "effect"));
  const auto type = ctl::dynamic_effect_from_name(name);
  if (!type) {
    std::string list;
    for (int t = 0; t < ctl::kDynamicEffectTypes; ++t)
      list += (t ? ", " : "") + std::string(ctl::info(static_cast<ctl::DynamicEffectType>(t)).name);
    ld.fail(name_node, join(path, "effect"), "unknown dynamic effect (one of: " + list + ")",
            "unknown dynamic effect '" + name + "' (one of: " + list + ")");
  }
  const ctl::DynamicEffectInfo& in = ctl::info(*type);
  std::set<std::string> allowed{"effect"};
  if (in.per_axis) allowed.insert("axis");
  for (int j = 0; j < in.n_params; ++j) allowed.insert(in.params[j].name);
  const std::string epath = path + "(" + name + ")";
  if (!in.per_axis && n["axis"])
    ld.fail(n["axis"], join(epath, "axis"), name + " acts on all axes together: give no axis");
  const Map m(ld, n, epath, allowed);
  ctl::DynamicEffect e;
  e.type = *type;
  if (in.per_axis) {
    const long axis = ld.integer(m.get("axis"), m.path("axis"));
    if (axis < 1 || axis > 3) ld.fail(m.get("axis"), m.path("axis"), "must be 1, 2 or 3");
    e.axis = static_cast<std::int8_t>(axis - 1);
  }
  for (int j = 0; j < in.n_params; ++j) {
    const auto& p = in.params[j];
    e.param[j] = ld.number_in(m.get(p.name), m.path(p.name), p.lower, p.upper, p.unit);
  }
  try {
    e.validate();
  } catch (const Error& err) {
    ld.fail(n, epath, err.what());
  }
  return e;
}


// user_effects (docs/model-file.md): table and expression effects go to the
// model's user_effects, a pitch_table to its limb's kinematics.
std::vector<double> number_list(const Loader& ld, const YAML::Node& n, const std::string& path) {
  if (!n.IsSequence()) ld.fail_got(n, path, "expected a list of numbers [a, b, ...]");
  std::vector<double> v;
  for (std::size_t k = 0; k < n.size(); ++k) v.push_back(ld.number(n[k], path + "[" + std::to_string(k) + "]"));
  return v;
}

void load_user_effect(const Loader& ld, const YAML::Node& n, int index, ctl::MachineModel& m) {
  const std::string path = "user_effects[" + std::to_string(index) + "]";
  if (!n.IsMap()) ld.fail_got(n, path, "expected a mapping {kind: table|expression|pitch_table, axis: N, ...}");
  const YAML::Node kind_node = n["kind"];
  if (!kind_node) ld.fail(n, path, "missing required key 'kind' (table, expression or pitch_table)");
  const std::string kind = ld.text(kind_node, join(path, "kind"));
  std::set<std::string> allowed;
  if (kind == "table") allowed = {"kind", "axis", "input", "nodes", "values"};
  else if (kind == "expression") allowed = {"kind", "axis", "formula", "params"};
  else if (kind == "pitch_table") allowed = {"kind", "axis", "nodes", "values"};
  else
    ld.fail(kind_node, join(path, "kind"), "unknown kind (one of: table, expression, pitch_table)",
            "unknown kind '" + kind + "' (one of: table, expression, pitch_table)");
  const Map mp(ld, n, path, allowed);
  const long axis = ld.integer(mp.get("axis"), mp.path("axis"));
  if (axis < 1 || axis > 3) ld.fail(mp.get("axis"), mp.path("axis"), "must be 1, 2 or 3");
  if (kind == "pitch_table") {
    kin::PitchTable& t = m.kinematics.effects[static_cast<std::size_t>(axis - 1)].pitch_table;
    if (!t.empty())
      ld.fail(mp.get("axis"), mp.path("axis"), "a second pitch_table on this axis (one per axis)");
    const std::vector<double> x = number_list(ld, mp.get("nodes"), mp.path("nodes"));
    const std::vector<double> y = number_list(ld, mp.get("values"), mp.path("values"));
    if (x.size() != y.size())
      ld.fail(mp.get("values"), mp.path("values"),
              "has " + std::to_string(y.size()) + " values for " + std::to_string(x.size()) + " nodes");
    if (x.size() < 2 || x.size() > static_cast<std::size_t>(kin::PitchTable::kCapacity))
      ld.fail(mp.get("nodes"), mp.path("nodes"),
              "needs 2 to " + std::to_string(kin::PitchTable::kCapacity) + " nodes, has " + std::to_string(x.size()));
    t.size = static_cast<int>(x.size());
    std::copy(x.begin(), x.end(), t.node.begin());
    std::copy(y.begin(), y.end(), t.error.begin());
    try {
      t.validate();
    } catch (const Error& e) {
      ld.fail(mp.get("nodes"), path, e.what());
    }
    return;
  }
  ctl::UserEffect e;
  e.axis = static_cast<int>(axis - 1);
  if (kind == "table") {
    e.kind = ctl::UserEffectKind::table;
    const std::string in = ld.text(mp.get("input"), mp.path("input"));
    if (in.size() != 2 || (in[0] != 'd' && in[0] != 'v') || in[1] < '1' || in[1] > '3')
      ld.fail(mp.get("input"), mp.path("input"), "must be d1..d3 (position) or v1..v3 (velocity)",
              "'" + in + "' must be d1..d3 (position) or v1..v3 (velocity)");
    e.input = in[0];
    e.input_axis = in[1] - '1';
    e.nodes = number_list(ld, mp.get("nodes"), mp.path("nodes"));
    e.values = number_list(ld, mp.get("values"), mp.path("values"));
  } else {
    e.kind = ctl::UserEffectKind::expression;
    e.formula = ld.text(mp.get("formula"), mp.path("formula"));
    if (mp.has("params") && !mp.get("params").IsNull()) {
      const YAML::Node pn = mp.get("params");
      if (!pn.IsMap()) ld.fail_got(pn, mp.path("params"), "expected a mapping NAME: {value: ..., lower: ..., upper: ..., unit: ...}");
      // In the file's order (the order `fitted` and reports list them).
      for (auto it = pn.begin(); it != pn.end(); ++it) {
        ctl::UserParameter p;
        p.name = it->first.Scalar();
        const std::string ppath = mp.path("params") + "." + p.name;
        const std::string public_path = mp.path("params");
        if (std::any_of(e.params.begin(), e.params.end(), [&](const auto& q) { return q.name == p.name; }))
          ld.fail(it->first, ppath, "parameter given twice", "", &public_path);
        const Map pm(ld, it->second, ppath, {"value", "lower", "upper", "unit"});
        p.value = pm.number("value");
        if (pm.has("lower")) p.lower = pm.number("lower");
        if (pm.has("upper")) p.upper = pm.number("upper");
        if (pm.has("unit")) p.unit = ld.text(pm.get("unit"), pm.path("unit"));
        e.params.push_back(std::move(p));
      }
    }
  }
  try {
    ctl::validate_user_effect(e, index);
  } catch (const Error& err) {
    // "user_effects[i].KEY: reason": point at KEY's node. The reason may
    // quote the formula or a parameter's name: only the local message has it.
    const std::string what = err.what();
    const std::string rest = what.substr(path.size() + (what.size() > path.size() && what[path.size()] == '.' ? 1 : 0));
    const std::string key = rest.substr(0, rest.find_first_of(".[:"));
    const YAML::Node at = mp.has(key) ? mp.get(key) : n;
    ld.fail(at, "", "not a usable user effect", what, &path);
  }
  m.user_effects.push_back(std::move(e));
}
}  // namespace

ModelFile parse_model_file(const std::string& text, const std::string& name) {
  const Loader ld(name);
  YAML::Node root;
  try {
    root = YAML::Load(text);
  } catch (const YAML::Exception& e) {
    std::string where = name;
    if (e.mark.line >= 0)
      where += ":" + std::to_string(e.mark.line + 1) + ":" + std::to_string(e.mark.column + 1);
    throw ModelFileError(where + ": not valid YAML: " + e.msg, e.mark.line >= 0 ? e.mark.line + 1 : 0,
                         "not valid YAML: " + e.msg.substr(0, 60));
  }
  if (!root || root.IsNull()) throw ModelFileError(name + ": empty model file", 0, "empty model file");
  const Map top(ld, root, "",
                {"cpmd_model", "geometry", "masses", "force_limit", "kinematics", "dynamic_effects",
                 "user_effects", "fitted", "history"});
  {
    const long v = ld.integer(top.get("cpmd_model"), "cpmd_model");
    if (v != kFormatVersion)
      ld.fail(top.get("cpmd_model"), "cpmd_model",
              "format version " + std::to_string(v) + " is not known (this build reads " +
                  std::to_string(kFormatVersion) + ")");
  }
  ModelFile out;
  ctl::MachineModel& m = out.model;
  m = ctl::MachineModel::elkady();
  {
    const Map g(ld, top.get("geometry"), "geometry", {"L", "L1", "L2", "D", "singularity_margin"});
    kin::LimbGeometry& lg = m.kinematics.limbs;
    lg.L = ld.number_in(g.get("L"), g.path("L"), 0.0, 10.0, "m", true);
    lg.L1 = ld.number_in(g.get("L1"), g.path("L1"), 0.0, 10.0, "m", true);
    lg.L2 = ld.number_in(g.get("L2"), g.path("L2"), 0.0, 10.0, "m", true);
    lg.D = ld.number_in(g.get("D"), g.path("D"), 0.0, 10.0, "m", true);
    lg.singularity_margin = ld.number_in(g.get("singularity_margin"), g.path("singularity_margin"),
                                         0.0, std::numbers::pi / 4, "rad");
  }
  {
    const Map ms(ld, top.get("masses"), "masses", {"m1", "m2", "m3", "m4"});
    m.masses.m1 = ld.number_in(ms.get("m1"), ms.path("m1"), 0.0, 1e4, "kg");
    m.masses.m2 = ld.number_in(ms.get("m2"), ms.path("m2"), 0.0, 1e4, "kg");
    m.masses.m3 = ld.number_in(ms.get("m3"), ms.path("m3"), 0.0, 1e4, "kg");
    m.masses.m4 = ld.number_in(ms.get("m4"), ms.path("m4"), 0.0, 1e4, "kg");
  }
  m.force_limit = ld.number_in(top.get("force_limit"), "force_limit", 0.0, 1e6, "N", true);
  {
    const Map k(ld, top.get("kinematics"), "kinematics", {"limb1", "limb2", "limb3"});
    m.kinematics.effects = {};
    for (int i = 0; i < 3; ++i) load_limb(ld, k, i, m);
  }
  m.effects.clear();
  if (top.has("dynamic_effects")) {
    const YAML::Node de = top.get("dynamic_effects");
    if (!de.IsNull()) {
      if (!de.IsSequence())
        ld.fail_got(de, "dynamic_effects", "expected a list of effects");
      if (de.size() > static_cast<std::size_t>(ctl::DynamicEffects::kCapacity))
        ld.fail(de, "dynamic_effects",
                "at most " + std::to_string(ctl::DynamicEffects::kCapacity) + " dynamic effects");
      for (std::size_t i = 0; i < de.size(); ++i)
        m.effects.add(load_dynamic_effect(ld, de[i], "dynamic_effects[" + std::to_string(i) + "]"));
    }
  }
  m.user_effects.clear();
  if (top.has("user_effects") && !top.get("user_effects").IsNull()) {
    const YAML::Node ue = top.get("user_effects");
    if (!ue.IsSequence()) ld.fail_got(ue, "user_effects", "expected a list of effects");
    for (std::size_t i = 0; i < ue.size(); ++i) load_user_effect(ld, ue[i], static_cast<int>(i), m);
  }
  if (top.has("fitted") && !top.get("fitted").IsNull()) {
    const YAML::Node fl = top.get("fitted");
    if (!fl.IsSequence()) ld.fail_got(fl, "fitted", "expected a list");
    for (std::size_t i = 0; i < fl.size(); ++i) {
      const Map f(ld, fl[i], "fitted[" + std::to_string(i) + "]",
                  {"name", "unit", "nominal", "value", "std_error"});
      FittedParameter p;
      p.name = ld.text(f.get("name"), f.path("name"));
      if (p.name.empty()) ld.fail(f.get("name"), f.path("name"), "must not be empty");
      p.unit = ld.text(f.get("unit"), f.path("unit"));
      p.nominal = f.number("nominal");
      p.value = f.number("value");
      if (f.has("std_error")) {
        p.std_error = f.number("std_error");
        if (p.std_error < 0.0 && p.std_error != -1.0)
          ld.fail(f.get("std_error"), f.path("std_error"), "must be >= 0, or -1 when unknown");
      }
      out.fitted.push_back(std::move(p));
    }
  }
  if (top.has("history") && !top.get("history").IsNull()) {
    const YAML::Node hl = top.get("history");
    if (!hl.IsSequence()) ld.fail_got(hl, "history", "expected a list");
    for (std::size_t i = 0; i < hl.size(); ++i) {
      const Map h(ld, hl[i], "history[" + std::to_string(i) + "]",
                  {"tool", "data_file", "data_sha256", "date", "note"});
      Provenance p;
      p.tool = ld.text(h.get("tool"), h.path("tool"));
      p.date = ld.text(h.get("date"), h.path("date"));
      if (h.has("data_file")) p.data_file = ld.text(h.get("data_file"), h.path("data_file"));
      if (h.has("data_sha256")) {
        p.data_sha256 = ld.text(h.get("data_sha256"), h.path("data_sha256"));
        if (!p.data_sha256.empty() && !is_hex64(p.data_sha256))
          ld.fail(h.get("data_sha256"), h.path("data_sha256"),
                  "expected 64 lowercase hexadecimal digits (SHA-256)");
      }
      if (h.has("note")) p.note = ld.text(h.get("note"), h.path("note"));
      out.history.push_back(std::move(p));
    }
  }
  // The model's own checks (planes meeting in a point, effect consistency)
  // and the prepared machine's (positive inertia with the effects).
  try {
    m.validate();
    const ctl::Machine machine(m);
    (void)machine;
  } catch (const Error& e) {
    // The model's own checks say what is inconsistent in numbers they derive,
    // never the file's text.
    throw ModelFileError(name + ": " + e.what(), 0, std::string(e.what()).substr(0, 160));
  }
  return out;
}

ModelFile load_model_file(const std::string& path) {
  return parse_model_file(detail::read_whole_file(path), path);
}

// ---------------------------------------------------------------- rendering

namespace {

// YAML double-quoted scalar: always safe, whatever the text holds.
std::string quoted(const std::string& s) {
  std::string out = "\"";
  for (unsigned char c : s) {
    switch (c) {
      case '"': out += "\\\""; break;
      case '\\': out += "\\\\"; break;
      case '\n': out += "\\n"; break;
      case '\t': out += "\\t"; break;
      case '\r': out += "\\r"; break;
      default:
        if (c < 0x20 || c == 0x7f) {
          static const char* hex = "0123456789abcdef";
          out += "\\x";
          out.push_back(hex[c >> 4]);
          out.push_back(hex[c & 15]);
        } else {
          out.push_back(static_cast<char>(c));
        }
    }
  }
  return out + "\"";
}

class Writer {
 public:
  // "  key: value      # comment" with comments aligned in one column.
  void kv(int indent, const std::string& key, const std::string& value, const std::string& comment = "") {
    std::string line(static_cast<std::size_t>(indent), ' ');
    line += key + ":";
    if (!value.empty()) line += " " + value;
    if (!comment.empty()) {
      if (line.size() < kCommentColumn) line.resize(kCommentColumn, ' ');
      else line += "  ";
      line += "# " + comment;
    }
    out_ += line + "\n";
  }
  void raw(const std::string& s) { out_ += s; }
  std::string str() const { return out_; }

 private:
  static constexpr std::size_t kCommentColumn = 32;
  std::string out_;
};

std::string num(double v) { return detail::format_double(v); }
std::string vec(const Vec3& v) { return "[" + num(v.x()) + ", " + num(v.y()) + ", " + num(v.z()) + "]"; }


std::string num_list(const double* v, std::size_t n) {
  std::string s = "[";
  for (std::size_t k = 0; k < n; ++k) s += (k ? ", " : "") + num(v[k]);
  return s + "]";
}

// Written only when the model has some, so that files without them stay as they were.
void render_user_effects(Writer& w, const ctl::MachineModel& m) {
  bool any_pitch = false;
  for (const auto& e : m.kinematics.effects) any_pitch |= !e.pitch_table.empty();
  if (m.user_effects.empty() && !any_pitch) return;
  w.raw("\n# Effects added by the user (docs/effects.md, \"Effects you add\"): tables and formulas.\n"
        "# table: a force (N) on `axis` against `input` (d_j in m, v_j in m/s), linear between the\n"
        "# nodes, held at the end values beyond them; expression: a force (N) on `axis` from a\n"
        "# formula over d1..d3, v1..v3, a1..a3, t and its parameters; pitch_table: the error e (m)\n"
        "# of axis' effective displacement against its position (m), d~ = d + e(d).\n");
  w.kv(0, "user_effects", "");
  for (const ctl::UserEffect& e : m.user_effects) {
    if (e.kind == ctl::UserEffectKind::table) {
      w.kv(2, "- kind", "table");
      w.kv(4, "axis", std::to_string(e.axis + 1), "the force acts on this axis");
      w.kv(4, "input", e.input_name(), e.input == 'd' ? "position of an axis (m)" : "velocity of an axis (m/s)");
      w.kv(4, "nodes", num_list(e.nodes.data(), e.nodes.size()), e.input == 'd' ? "m" : "m/s");
      w.kv(4, "values", num_list(e.values.data(), e.values.size()), "N");
    } else {
      w.kv(2, "- kind", "expression");
      w.kv(4, "axis", std::to_string(e.axis + 1), "the force (N) acts on this axis");
      w.kv(4, "formula", quoted(e.formula));
      if (e.params.empty()) {
        w.kv(4, "params", "{}");
        continue;
      }
      w.kv(4, "params", "");
      for (const ctl::UserParameter& p : e.params) {
        std::string v = "{value: " + num(p.value);
        if (std::isfinite(p.lower)) v += ", lower: " + num(p.lower);
        if (std::isfinite(p.upper)) v += ", upper: " + num(p.upper);
        v += ", unit: " + quoted(p.unit) + "}";
        w.kv(6, p.name, v);
      }
    }
  }
  for (int i = 0; i < 3; ++i) {
    const kin::PitchTable& t = m.kinematics.effects[i].pitch_table;
    if (t.empty()) continue;
    const auto n = static_cast<std::size_t>(t.size);
    w.kv(2, "- kind", "pitch_table");
    w.kv(4, "axis", std::to_string(i + 1));
    w.kv(4, "nodes", num_list(t.node.data(), n), "m, axis position");
    w.kv(4, "values", num_list(t.error.data(), n), "m, error e of the effective displacement");
  }
}
}  // namespace

std::string render_model_file(const ModelFile& mf) {
  const ctl::MachineModel& m = mf.model;
  const kin::KinematicModel& km = m.kinematics;
  const kin::LimbGeometry& g = km.limbs;
  Writer w;
  w.raw("# cpmd machine model: the 3-PRRR Cartesian parallel manipulator\n"
        "# (docs/model.md and docs/effects.md; the schema is docs/model-file.md).\n"
        "# SI units throughout: m, s, kg, N, rad. Each number's unit is in the comment beside it.\n");
  w.kv(0, "cpmd_model", std::to_string(kFormatVersion), "format version of this file");
  w.raw("\n# Limb geometry (Elkady Table 1).\n");
  w.kv(0, "geometry", "");
  w.kv(2, "L", num(g.L), "m, half side of the platform square");
  w.kv(2, "L1", num(g.L1), "m, first link A_i M_i");
  w.kv(2, "L2", num(g.L2), "m, second link M_i B_i");
  w.kv(2, "D", num(g.D), "m, offset of limb 3's base along y");
  w.kv(2, "singularity_margin", num(g.singularity_margin),
       "rad, elbow angle from straight/folded that counts as singular");
  w.raw("\n# Link masses of one limb (Elkady Table 2).\n");
  w.kv(0, "masses", "");
  w.kv(2, "m1", num(m.masses.m1), "kg, first link (uniform rod)");
  w.kv(2, "m2", num(m.masses.m2), "kg, second link");
  w.kv(2, "m3", num(m.masses.m3), "kg, prismatic joint and actuator");
  w.kv(2, "m4", num(m.masses.m4), "kg, tool");
  w.raw("\n");
  w.kv(0, "force_limit", num(m.force_limit), "N, largest |F_i| an actuator may be commanded");
  w.raw("\n# Per limb i (limb i drives axis i): the assembly mode, the actuator, the calibrated\n"
        "# plane u^T p = (d~ + d0) c + n (Kim eq. 5) and the kinematic effects of docs/effects.md.\n");
  w.kv(0, "kinematics", "");
  static const char* drives[] = {"drives x", "drives y", "drives z"};
  for (int i = 0; i < 3; ++i) {
    const kin::LimbPlane& pl = km.planes[i];
    w.kv(2, "limb" + std::to_string(i + 1), "", drives[i]);
    w.kv(4, "assembly_mode", std::to_string(g.mode[i]), "+1 or -1, the elbow's branch");
    w.kv(4, "d0", num(km.d0[i]), "m, actuator offset: p_i = d_i + d0_i nominally");
    w.kv(4, "stroke", "[" + num(m.strokes.min[i]) + ", " + num(m.strokes.max[i]) + "]",
         "m, encoder range [min, max]");
    w.kv(4, "normal", vec(pl.normal), "u, unit normal of the limb's plane");
    w.kv(4, "scale", num(pl.scale), "c (1), cos(gamma) in Kim's terms");
    w.kv(4, "offset", num(pl.offset), "n (m), projected offset of the plane");
    std::vector<kin::KinematicEffectType> present;
    for (int t = 0; t < kin::kKinematicEffectTypes; ++t) {
      const auto type = static_cast<kin::KinematicEffectType>(t);
      const auto v = kin::get_params(km.effects[i], type);
      bool any = false;
      for (int j = 0; j < kin::info(type).n_params; ++j) any |= (v[j] != 0.0);
      if (any) present.push_back(type);
    }
    if (present.empty()) {
      w.kv(4, "effects", "{}", "kinematic effects by name (docs/effects.md)");
      continue;
    }
    w.kv(4, "effects", "", "kinematic effects by name (docs/effects.md)");
    for (const auto type : present) {
      const kin::KinematicEffectInfo& in = kin::info(type);
      const auto v = kin::get_params(km.effects[i], type);
      w.kv(6, in.name, "");
      for (int j = 0; j < in.n_params; ++j) w.kv(8, in.params[j].name, num(v[j]), in.params[j].unit);
    }
  }
  w.raw("\n# Dynamic effects (docs/effects.md): forces beyond Elkady's rigid-body model, in the order\n"
        "# the model adds them. Per-axis effects name their axis (1..3).\n");
  if (m.effects.size() == 0) {
    w.kv(0, "dynamic_effects", "[]");
  } else {
    w.kv(0, "dynamic_effects", "");
    for (const ctl::DynamicEffect& e : m.effects) {
      const ctl::DynamicEffectInfo& in = ctl::info(e.type);
      w.kv(2, "- effect", in.name);
      if (in.per_axis) w.kv(4, "axis", std::to_string(e.axis + 1));
      for (int j = 0; j < in.n_params; ++j) w.kv(4, in.params[j].name, num(e.param[j]), in.params[j].unit);
    }
  }
  render_user_effects(w, m);
  w.raw("\n# Parameters a tool fitted: nominal (before) and fitted value, standard error\n"
        "# (-1: unknown), in `unit`.\n");
  if (mf.fitted.empty()) {
    w.kv(0, "fitted", "[]");
  } else {
    w.kv(0, "fitted", "");
    for (const FittedParameter& p : mf.fitted) {
      w.kv(2, "- name", quoted(p.name));
      w.kv(4, "unit", quoted(p.unit));
      w.kv(4, "nominal", num(p.nominal));
      w.kv(4, "value", num(p.value));
      w.kv(4, "std_error", num(p.std_error < 0.0 ? -1.0 : p.std_error));
    }
  }
  w.raw("\n# Where this model came from, oldest first.\n");
  if (mf.history.empty()) {
    w.kv(0, "history", "[]");
  } else {
    w.kv(0, "history", "");
    for (const Provenance& p : mf.history) {
      w.kv(2, "- tool", quoted(p.tool));
      w.kv(4, "data_file", quoted(p.data_file));
      w.kv(4, "data_sha256", quoted(p.data_sha256));
      w.kv(4, "date", quoted(p.date), "ISO 8601, UTC");
      w.kv(4, "note", quoted(p.note));
    }
  }
  return w.str();
}

void save_model_file(const std::string& path, const ModelFile& m, const std::string& forbid_path) {
  namespace fs = std::filesystem;
  if (!forbid_path.empty()) {
    std::error_code ec;
    const bool same = (fs::exists(path, ec) && fs::exists(forbid_path, ec) &&
                       fs::equivalent(path, forbid_path, ec)) ||
                      fs::weakly_canonical(path, ec) == fs::weakly_canonical(forbid_path, ec);
    if (same)
      throw Error(path + ": refusing to overwrite the input model file " + forbid_path +
                  "; write the new model to another file");
  }
  const std::string text = render_model_file(m);
  // Never write a file that would not load: the same checks as a reader.
  try {
    parse_model_file(text, path);
  } catch (const Error& e) {
    throw Error(std::string("refusing to save a model that would not load back (nothing written): ") +
                e.what());
  }
  write_file_atomically(path, text);
}

}  // namespace cpm::io
