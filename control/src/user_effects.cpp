#include "cpm/control/user_effects.hpp"

#include <muParser.h>

#include <algorithm>
#include <cmath>
#include <set>
#include <sstream>

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

struct UserEffectsRuntime::Impl {
  struct Item {
    UserEffectKind kind = UserEffectKind::table;
    int axis = 0;
    int input = 0;  // index into the 10 variables (d1..t)
    std::vector<double> x, y;
    std::unique_ptr<mu::Parser> parser;
    std::unique_ptr<double[]> params;
  };
  std::vector<UserEffect> source;
  std::vector<Item> items;
  mutable double vars[10] = {};
  bool acceleration = false;

  explicit Impl(const std::vector<UserEffect>& effects) : source(effects) {
    items.reserve(effects.size());
    for (std::size_t i = 0; i < effects.size(); ++i) {
      const UserEffect& e = effects[i];
      const int index = static_cast<int>(i);
      validate_user_effect(e, index);
      Item it;
      it.kind = e.kind;
      it.axis = e.axis;
      if (e.kind == UserEffectKind::table) {
        it.input = (e.input == 'd' ? 0 : 3) + e.input_axis;
        it.x = e.nodes;
        it.y = e.values;
      } else {
        for (const std::string& name : formula_variables(e, index))
          if (name == "a1" || name == "a2" || name == "a3") acceleration = true;
        it.params = std::make_unique<double[]>(e.params.size() + 1);
        for (std::size_t k = 0; k < e.params.size(); ++k) it.params[k] = e.params[k].value;
        it.parser = std::make_unique<mu::Parser>();
        bind(*it.parser, e, index, vars, it.params.get());
        // The first Eval parses to bytecode and sizes the stack; later ones
        // only run the bytecode (tests/control/test_user_effects.cpp counts
        // their allocations: none).
        try {
          (void)it.parser->Eval();
        } catch (const mu::Parser::exception_type& err) {
          fail(index, "formula", "'" + e.formula + "': " + parser_message(err));
        }
      }
      items.push_back(std::move(it));
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
  double* x = impl_->vars;
  for (int k = 0; k < 3; ++k) {
    x[k] = d[k];
    x[3 + k] = v[k];
    x[6 + k] = a[k];
  }
  x[9] = t;
  for (const Impl::Item& it : impl_->items) {
    if (it.kind == UserEffectKind::table)
      f[it.axis] += kin::interpolate_held(it.x.data(), it.y.data(), static_cast<int>(it.x.size()), x[it.input]);
    else
      // Bytecode only (compiled at preparation): muparser's evaluation of
      // compiled bytecode raises no error of its own; a NaN or inf from the
      // formula reaches the caller's finiteness checks.
      f[it.axis] += it.parser->Eval();
  }
}

}  // namespace cpm::ctl
