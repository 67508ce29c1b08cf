// SPDX-License-Identifier: Apache-2.0
#include "cpm/control/user_effects.hpp"

#include <muParser.h>

#include <algorithm>
#include <array>
#include <atomic>
#include <cmath>
#include <set>
#include <sstream>

#include "cpm/control/machine.hpp"
#include "cpm/kinematics/pitch_table.hpp"

namespace cpm::ctl {
namespace {

std::string where(int index, const std::string& key) {
  return "user_effects[" + std::to_string(index) + "]" + (key.empty() ? "" : "." + key);
}

[[noreturn]] void fail(int index, const std::string& key, const std::string& why) {
  throw Error(where(index, key) + ": " + why);
}

// muparser's message, with the position (counted from 0) when it does not say it.
std::string parser_message(const mu::Parser::exception_type& err) {
  std::string m = err.GetMsg();
  if (m.find("position") == std::string::npos) m += " (at position " + std::to_string(err.GetPos()) + ")";
  return m;
}

bool is_variable(const std::string& s) {
  for (const char* v : kUserVariables)
    if (s == v) return true;
  return false;
}

std::string known_names(const UserEffect& e) {
  std::string s = "d1..d3, v1..v3, a1..a3, t";
  for (const auto& p : e.params) s += ", " + p.name;
  return s;
}

// A parser holding the formula, its variables bound to `vars` (10, in
// kUserVariables order) and its parameters to `params`. Throws Error with
// muparser's message and position when the formula does not parse.
void bind(mu::Parser& parser, const UserEffect& e, int index, double* vars, double* params) {
  try {
    parser.SetExpr(e.formula);
    for (int k = 0; k < 10; ++k) parser.DefineVar(kUserVariables[k], &vars[k]);
    for (std::size_t k = 0; k < e.params.size(); ++k) parser.DefineVar(e.params[k].name, &params[k]);
  } catch (const mu::Parser::exception_type& err) {
    fail(index, "formula", "'" + e.formula + "': " + parser_message(err));
  }
}

}  // namespace

std::string UserEffect::input_name() const {
  return std::string(1, input) + std::to_string(input_axis + 1);
}

std::vector<std::string> formula_variables(const UserEffect& e, int index) {
  if (e.formula.empty()) fail(index, "formula", "is empty");
  std::vector<std::string> used;
  try {
    mu::Parser p;
    p.SetExpr(e.formula);
    for (const auto& [name, ptr] : p.GetUsedVar()) used.push_back(name);
  } catch (const mu::Parser::exception_type& err) {
    std::ostringstream os;
    os << "'" << e.formula << "' does not parse: " << parser_message(err);
    fail(index, "formula", os.str());
  }
  for (const std::string& name : used) {
    const bool param = std::any_of(e.params.begin(), e.params.end(),
                                   [&](const UserParameter& p) { return p.name == name; });
    if (!is_variable(name) && !param)
      fail(index, "formula", "unknown variable '" + name + "' in '" + e.formula + "' (known: " +
                                 known_names(e) + ")");
  }
  return used;
}

void validate_user_effect(const UserEffect& e, int index) {
  if (e.axis < 0 || e.axis > 2) fail(index, "axis", "must be 1, 2 or 3");
  if (e.kind == UserEffectKind::table) {
    if (e.input != 'd' && e.input != 'v') fail(index, "input", "must be d1..d3 or v1..v3");
    if (e.input_axis < 0 || e.input_axis > 2) fail(index, "input", "must be d1..d3 or v1..v3");
    if (e.nodes.size() != e.values.size())
      fail(index, "values", "has " + std::to_string(e.values.size()) + " values for " +
                                std::to_string(e.nodes.size()) + " nodes");
    if (e.nodes.size() < 2 || e.nodes.size() > static_cast<std::size_t>(kUserTableCapacity))
      fail(index, "nodes", "needs 2 to " + std::to_string(kUserTableCapacity) + " nodes, has " +
                               std::to_string(e.nodes.size()));
    for (std::size_t k = 0; k < e.nodes.size(); ++k) {
      if (!std::isfinite(e.nodes[k])) fail(index, "nodes[" + std::to_string(k) + "]", "not a finite number");
      if (!std::isfinite(e.values[k])) fail(index, "values[" + std::to_string(k) + "]", "not a finite number");
      if (k > 0 && !(e.nodes[k] > e.nodes[k - 1])) {
        std::ostringstream os;
        os << "nodes must be strictly increasing: " << e.nodes[k] << " is not above " << e.nodes[k - 1];
        fail(index, "nodes[" + std::to_string(k) + "]", os.str());
      }
    }
    return;
  }
  std::set<std::string> names;
  for (const UserParameter& p : e.params) {
    const std::string key = "params." + p.name;
    const bool ok_name = !p.name.empty() && std::isalpha(static_cast<unsigned char>(p.name[0])) &&
                         std::all_of(p.name.begin(), p.name.end(), [](char c) {
                           return std::isalnum(static_cast<unsigned char>(c)) || c == '_';
                         });
    if (!ok_name) fail(index, key, "a parameter's name is a letter followed by letters, digits or '_'");
    if (is_variable(p.name)) fail(index, key, "'" + p.name + "' is a variable's name (d1..d3, v1..v3, a1..a3, t)");
    if (!names.insert(p.name).second) fail(index, key, "parameter given twice");
    if (!std::isfinite(p.value)) fail(index, key + ".value", "not a finite number");
    if (std::isnan(p.lower) || std::isnan(p.upper) || !(p.lower <= p.upper))
      fail(index, key, "lower must not be above upper");
    if (p.value < p.lower || p.value > p.upper) {
      std::ostringstream os;
      os << p.value << " " << p.unit << " is outside its bounds [" << p.lower << ", " << p.upper << "]";
      fail(index, key + ".value", os.str());
    }
  }
  (void)formula_variables(e, index);
  // Bind and evaluate at rest: catches what only binding finds (a parameter
  // named like a muparser function) and a formula that is not finite at rest.
  double vars[10] = {};
  std::vector<double> params;
  for (const auto& p : e.params) params.push_back(p.value);
  mu::Parser parser;
  bind(parser, e, index, vars, params.data());
  double f = 0.0;
  try {
    f = parser.Eval();
  } catch (const mu::Parser::exception_type& err) {
    fail(index, "formula", "'" + e.formula + "': " + parser_message(err));
  }
  if (!std::isfinite(f)) fail(index, "formula", "'" + e.formula + "' is not finite at rest (all variables 0)");
}

// ------------------------------------------------------------------ runtime

// Several threads may evaluate one prepared machine at once (cpmd's loop and
// its server, which checks a trajectory or gains against the model in use).
// A muparser parser is not reentrant (its variables and its stack are its
// own), so each formula is prepared in kSlots copies; an evaluation takes a
// free slot with an atomic test-and-set (no lock, no wait while a slot is
// free) and gives it back.
constexpr int kSlots = 8;

struct UserEffectsRuntime::Impl {
  struct Table {
    int axis = 0;
    int input = 0;  // index into the 10 variables (d1..t)
    std::vector<double> x, y;
  };
  struct Formula {
    int axis = 0;
    int parser = 0;  // index into each slot's parsers
  };
  struct Slot {
    double vars[10] = {};
    std::vector<std::unique_ptr<mu::Parser>> parsers;
    std::vector<std::unique_ptr<double[]>> params;
    std::atomic_flag busy = ATOMIC_FLAG_INIT;
  };
  std::vector<UserEffect> source;
  std::vector<Table> tables;
  std::vector<Formula> formulas;
  std::array<std::unique_ptr<Slot>, kSlots> slots;
  bool acceleration = false;

  explicit Impl(const std::vector<UserEffect>& effects) : source(effects) {
    for (auto& s : slots) s = std::make_unique<Slot>();
    for (std::size_t i = 0; i < effects.size(); ++i) {
      const UserEffect& e = effects[i];
      const int index = static_cast<int>(i);
      validate_user_effect(e, index);
      if (e.kind == UserEffectKind::table) {
        tables.push_back({e.axis, (e.input == 'd' ? 0 : 3) + e.input_axis, e.nodes, e.values});
        continue;
      }
      for (const std::string& name : formula_variables(e, index))
        if (name == "a1" || name == "a2" || name == "a3") acceleration = true;
      formulas.push_back({e.axis, static_cast<int>(slots[0]->parsers.size())});
      for (auto& s : slots) {
        auto params = std::make_unique<double[]>(e.params.size() + 1);
        for (std::size_t k = 0; k < e.params.size(); ++k) params[k] = e.params[k].value;
        auto parser = std::make_unique<mu::Parser>();
        bind(*parser, e, index, s->vars, params.get());
        // The first Eval parses to bytecode and sizes the stack; later ones
        // only run the bytecode (tests/control/test_user_effects.cpp counts
        // their allocations: none).
        try {
          (void)parser->Eval();
        } catch (const mu::Parser::exception_type& err) {
          fail(index, "formula", "'" + e.formula + "': " + parser_message(err));
        }
        s->parsers.push_back(std::move(parser));
        s->params.push_back(std::move(params));
      }
    }
  }
};

UserEffectsRuntime::UserEffectsRuntime() = default;
UserEffectsRuntime::UserEffectsRuntime(const std::vector<UserEffect>& effects)
    : impl_(effects.empty() ? nullptr : std::make_unique<Impl>(effects)) {}
UserEffectsRuntime::UserEffectsRuntime(const UserEffectsRuntime& other)
    : impl_(other.impl_ ? std::make_unique<Impl>(other.impl_->source) : nullptr) {}
UserEffectsRuntime& UserEffectsRuntime::operator=(const UserEffectsRuntime& other) {
  if (this != &other) impl_ = other.impl_ ? std::make_unique<Impl>(other.impl_->source) : nullptr;
  return *this;
}
UserEffectsRuntime::UserEffectsRuntime(UserEffectsRuntime&&) noexcept = default;
UserEffectsRuntime& UserEffectsRuntime::operator=(UserEffectsRuntime&&) noexcept = default;
UserEffectsRuntime::~UserEffectsRuntime() = default;

bool UserEffectsRuntime::empty() const noexcept { return !impl_; }
bool UserEffectsRuntime::uses_acceleration() const noexcept { return impl_ && impl_->acceleration; }

void UserEffectsRuntime::add_forces(const Vec3& d, const Vec3& v, const Vec3& a, double t,
                                    Vec3& f) const noexcept {
  if (!impl_) return;
  double x[10];
  for (int k = 0; k < 3; ++k) {
    x[k] = d[k];
    x[3 + k] = v[k];
    x[6 + k] = a[k];
  }
  x[9] = t;
  for (const Impl::Table& tb : impl_->tables)
    f[tb.axis] += kin::interpolate_held(tb.x.data(), tb.y.data(), static_cast<int>(tb.x.size()), x[tb.input]);
  if (impl_->formulas.empty()) return;
  // A free slot: one per thread evaluating now (kSlots of them).
  for (int k = 0;; k = (k + 1) % kSlots) {
    Impl::Slot& s = *impl_->slots[static_cast<std::size_t>(k)];
    if (s.busy.test_and_set(std::memory_order_acquire)) continue;
    std::copy(x, x + 10, s.vars);
    // Bytecode only (compiled at preparation): muparser's evaluation of
    // compiled bytecode raises no error of its own; a NaN or inf from the
    // formula reaches the caller's finiteness checks.
    for (const Impl::Formula& fm : impl_->formulas)
      f[fm.axis] += s.parsers[static_cast<std::size_t>(fm.parser)]->Eval();
    s.busy.clear(std::memory_order_release);
    return;
  }
}

// ------------------------------------------------------- command-line form

namespace {

std::vector<std::string> split(const std::string& s, char sep) {
  std::vector<std::string> out;
  std::string part;
  std::istringstream is(s);
  while (std::getline(is, part, sep)) out.push_back(part);
  if (!s.empty() && s.back() == sep) out.emplace_back();
  return out;
}

std::vector<double> numbers(const std::string& spec, const std::string& text) {
  std::vector<double> v;
  for (const std::string& part : split(text, ',')) {
    std::size_t used = 0;
    double x = 0.0;
    try {
      x = std::stod(part, &used);
    } catch (const std::exception&) {
      used = 0;
    }
    if (used == 0 || used != part.size() || !std::isfinite(x))
      throw Error("'" + spec + "': '" + part + "' is not a number");
    v.push_back(x);
  }
  return v;
}

int axis_of(const std::string& spec, const std::string& text) {
  if (text != "1" && text != "2" && text != "3") throw Error("'" + spec + "': axis must be 1, 2 or 3");
  return text[0] - '1';
}

}  // namespace

bool is_user_effect_spec(const std::string& spec) noexcept {
  const std::string kind = spec.substr(0, spec.find(':'));
  return kind == "table" || kind == "expression" || kind == "pitch_table";
}

void add_user_effect(MachineModel& model, const std::string& spec) {
  const std::vector<std::string> f = split(spec, ':');
  const std::string& kind = f.empty() ? spec : f[0];
  if (kind == "pitch_table") {
    if (f.size() != 4) throw Error("'" + spec + "': expected pitch_table:AXIS:N1,N2,...:E1,E2,... (m)");
    const int axis = axis_of(spec, f[1]);
    const std::vector<double> x = numbers(spec, f[2]), y = numbers(spec, f[3]);
    if (x.size() != y.size()) throw Error("'" + spec + "': as many errors as nodes");
    if (x.size() > static_cast<std::size_t>(kin::PitchTable::kCapacity))
      throw Error("'" + spec + "': at most " + std::to_string(kin::PitchTable::kCapacity) + " nodes");
    kin::PitchTable t;
    t.size = static_cast<int>(x.size());
    std::copy(x.begin(), x.end(), t.node.begin());
    std::copy(y.begin(), y.end(), t.error.begin());
    t.validate();
    model.kinematics.effects[static_cast<std::size_t>(axis)].pitch_table = t;
    return;
  }
  UserEffect e;
  if (kind == "table") {
    if (f.size() != 5) throw Error("'" + spec + "': expected table:AXIS:INPUT:N1,N2,...:V1,V2,...");
    e.kind = UserEffectKind::table;
    e.axis = axis_of(spec, f[1]);
    const std::string& in = f[2];
    if (in.size() != 2 || (in[0] != 'd' && in[0] != 'v') || in[1] < '1' || in[1] > '3')
      throw Error("'" + spec + "': input must be d1..d3 or v1..v3");
    e.input = in[0];
    e.input_axis = in[1] - '1';
    e.nodes = numbers(spec, f[3]);
    e.values = numbers(spec, f[4]);
  } else if (kind == "expression") {
    if (f.size() < 3) throw Error("'" + spec + "': expected expression:AXIS:FORMULA[:NAME=VALUE,...]");
    e.kind = UserEffectKind::expression;
    e.axis = axis_of(spec, f[1]);
    // The formula may hold ':' (a ? b : c): the last field is the parameters
    // only when it reads NAME=VALUE,...
    std::size_t end = f.size();
    const std::string& last = f.back();
    if (f.size() >= 4 && last.find('=') != std::string::npos && std::isalpha(static_cast<unsigned char>(last[0]))) {
      for (const std::string& kv : split(last, ',')) {
        const auto eq = kv.find('=');
        if (eq == std::string::npos) throw Error("'" + spec + "': parameter '" + kv + "' is not NAME=VALUE");
        UserParameter p;
        p.name = kv.substr(0, eq);
        p.value = numbers(spec, kv.substr(eq + 1))[0];
        e.params.push_back(p);
      }
      end = f.size() - 1;
    }
    for (std::size_t k = 2; k < end; ++k) e.formula += (k > 2 ? ":" : "") + f[k];
  } else {
    throw Error("'" + spec + "': not a user effect (table, expression, pitch_table)");
  }
  validate_user_effect(e, static_cast<int>(model.user_effects.size()));
  model.user_effects.push_back(std::move(e));
}

}  // namespace cpm::ctl
