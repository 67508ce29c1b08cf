// SPDX-License-Identifier: Apache-2.0
#include "cli.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <sstream>

#include "cpm/control/controller.hpp"
#include "cpm/control/effects.hpp"
#include "cpm/io/model_file.hpp"
#include "cpm/kinematics/kinematic_effects.hpp"
#include "cpm/program_cli.hpp"

namespace cpm::cli {

std::map<std::string, CommandEntry>& registry() {
  static std::map<std::string, CommandEntry> r;
  return r;
}

Command::Command(const char* name, const char* summary, Setup setup) {
  registry()[name] = {summary, std::move(setup)};
}

namespace {

using program::is_vector;

std::string join(const std::vector<std::string>& v, const char* sep) {
  std::string out;
  for (const auto& s : v) out += (out.empty() ? "" : sep) + s;
  return out;
}

}  // namespace

std::unique_ptr<CLI::App> make_app(std::map<std::string, Run>* runs) {
  auto app = std::make_unique<CLI::App>(
      "cpm: the command-line tool of cpmd. Simulates, calibrates and identifies the model of a 3-PRRR Cartesian\n"
      "parallel manipulator, and commands a running cpmd over LCM. SI units on the command line and in files\n"
      "(m, s, N, rad); mm and µm on screen, labelled.",
      "cpm");
  program::setup(*app);
  app->get_formatter()->label("SUBCOMMAND", "COMMAND");
  app->require_subcommand(1);
  app->footer("'cpm COMMAND --help' (or man cpm-COMMAND) shows a command's options. Exit status: 0 done, 1 failed\n"
              "(a bad file, a refused command, a fault), 2 a bad command line.");
  for (const auto& [name, entry] : registry()) {
    CLI::App* sub = app->add_subcommand(name, entry.summary)->group("Commands");
    Run r = entry.setup(*sub);
    if (runs) (*runs)[name] = std::move(r);
  }
  return app;
}

const CLI::Validator& finite() { return program::finite(); }

namespace {

std::vector<std::string> dynamic_effect_names() {
  std::vector<std::string> out;
  for (int t = 0; t < ctl::kDynamicEffectTypes; ++t) out.emplace_back(ctl::info(static_cast<ctl::DynamicEffectType>(t)).name);
  return out;
}

std::vector<std::string> kinematic_effect_names() {
  std::vector<std::string> out;
  for (int t = 0; t < kin::kKinematicEffectTypes; ++t)
    out.emplace_back(kin::info(static_cast<kin::KinematicEffectType>(t)).name);
  return out;
}

}  // namespace

std::vector<std::string> effect_names() {
  std::vector<std::string> out = dynamic_effect_names();
  for (auto& n : kinematic_effect_names()) out.push_back(std::move(n));
  return out;
}

std::string effect_list() {
  return "dynamic (forces; seen in motion logs): " + join(dynamic_effect_names(), ", ") +
         "; kinematic (where the platform is; seen in ball-bar and position data): " +
         join(kinematic_effect_names(), ", ");
}

const CLI::Validator& effect_name() {
  static const CLI::Validator v(
      [](std::string& s) -> std::string {
        const std::string name = s.substr(0, s.find(':'));
        if (ctl::dynamic_effect_from_name(name) || kin::kinematic_effect_from_name(name)) return {};
        if (ctl::is_user_effect_spec(s)) return {};  // table, expression, pitch_table (docs/effects.md)
        return "unknown effect '" + name + "'; the effects are: " + effect_list() +
               "; user effects (docs/effects.md): table, expression, pitch_table";
      },
      "");
  return v;
}

std::vector<std::string> law_names() {
  std::vector<std::string> out;
  for (ctl::ControlLaw l : {ctl::ControlLaw::pd, ctl::ControlLaw::pd_gravity, ctl::ControlLaw::pd_feedforward,
                            ctl::ControlLaw::computed_torque})
    out.emplace_back(ctl::law_name(l));
  return out;
}

CLI::Option* add_number(CLI::App& app, const std::string& name, double& value, const std::string& unit,
                        const std::string& help) {
  return app.add_option(name, value, help)->check(finite())->type_name(unit);
}

CLI::Option* add_number(CLI::App& app, const std::string& name, std::optional<double>& value, const std::string& unit,
                        const std::string& help) {
  return app.add_option(name, value, help)->check(finite())->type_name(unit);
}

CLI::Option* add_choice(CLI::App& app, const std::string& name, std::string& value, const std::vector<std::string>& choices,
                        const std::string& help) {
  return app.add_option(name, value, help)->check(CLI::IsMember(choices).description(""))->type_name(join(choices, "|"));
}

CLI::Option* add_model_option(CLI::App& app, std::optional<std::string>& model, const std::string& what,
                              const std::string& name) {
  return app.add_option(name, model, what)->type_name("MODEL.yaml")->default_str(kDefaultModelText);
}

std::string json_text(const Json& j, int indent) {
  return j.dump(indent, ' ', false, Json::error_handler_t::replace);
}

void write_json(const std::string& path, const Json& j) { io::write_file_atomically(path, json_text(j, 2) + "\n"); }

void write_file_atomically(const std::string& path, const std::string& text) {
  io::write_file_atomically(path, text);
}

void record_fit(io::ModelFile& mf, const std::vector<io::FittedParameter>& fitted, const std::string& tool,
                const std::string& data_path, const std::string& note) {
  for (const auto& p : fitted) {
    std::erase_if(mf.fitted, [&](const io::FittedParameter& q) { return q.name == p.name; });
    mf.fitted.push_back(p);
  }
  mf.history.push_back({tool, data_path, io::sha256_file(data_path), io::utc_now_iso8601(), note});
}

std::string find_default_model(const std::filesystem::path& cwd, const std::filesystem::path& exe,
                               const std::filesystem::path& system_file, const std::string& name) {
  namespace fs = std::filesystem;
  const fs::path published = fs::path("config") / name;
  std::error_code ec;
  if (fs::exists(cwd / published, ec)) return published.string();
  if (!exe.empty()) {
    const fs::path exe_dir = exe.parent_path();
    for (const fs::path& candidate :
         {exe_dir / ".." / ".." / published, exe_dir / ".." / "etc" / "cpmd" / name})
      if (fs::exists(candidate, ec)) return fs::weakly_canonical(candidate, ec).string();
  }
  if (fs::exists(system_file, ec)) return system_file.string();
  return published.string();
}

namespace {
std::string default_config_file(const std::string& name) {
  namespace fs = std::filesystem;
  std::error_code ec;
  fs::path exe = fs::read_symlink("/proc/self/exe", ec);
  if (ec) exe.clear();
  return find_default_model(".", exe, "/etc/cpmd/" + name, name);
}
}  // namespace

std::string default_model_path() { return default_config_file("machine.yaml"); }

std::optional<std::string> default_daemon_config_path() {
  const std::string found = default_config_file("cpmd.yaml");
  std::error_code ec;
  if (!std::filesystem::exists(found, ec)) return std::nullopt;
  return found;
}

std::string model_or_default(const std::optional<std::string>& model) {
  if (model) return *model;
  const std::string found = default_model_path();
  std::error_code ec;
  if (!std::filesystem::exists(found, ec))
    throw Error(std::string("no --model given and no default model found: looked for config/machine.yaml in the "
                            "current folder and in the build tree of this cpm, for etc/cpmd/machine.yaml beside "
                            "its install prefix, and for /etc/cpmd/machine.yaml; give --model FILE"));
  return found;
}

Vec3 parse_point(const std::string& what, const std::string& text, bool allow_non_finite) {
  Vec3 v;
  std::istringstream is(text);
  std::string part;
  int n = 0;
  while (std::getline(is, part, ',')) {
    double x = 0;
    if (n >= 3 || !CLI::detail::lexical_cast(part, x) || (!allow_non_finite && !std::isfinite(x)))
      throw UsageError(what + ": expected three finite numbers x,y,z in metres, got '" + text + "'");
    v[n++] = x;
  }
  if (n != 3) throw UsageError(what + ": expected three numbers x,y,z in metres, got '" + text + "'");
  return v;
}

// ------------------------------------------------------------------ completion

namespace {

bool starts_with(const std::string& s, const char* p) { return s.rfind(p, 0) == 0; }

// What a value may be, from the name the help shows for it: A|B|C is a
// choice, EFFECT... an effect of the library, FILE, NAME.yaml or DIR a path.
std::vector<std::string> values_for(const CLI::Option* o) {
  std::string t = o->get_type_name();
  if (starts_with(t, "EFFECT") || starts_with(t, "NAME:AXIS")) return effect_names();
  if (t.find('|') != std::string::npos && t.find(' ') == std::string::npos) {
    std::vector<std::string> out;
    std::istringstream is(t);
    for (std::string c; std::getline(is, c, '|');) out.push_back(c);
    return out;
  }
  if (t.ends_with("DIR")) return {"__dirs__"};
  if (t.find("FILE") != std::string::npos || t.find('.') != std::string::npos) return {"__files__"};
  return {};
}

const CLI::Option* find_option(const CLI::App& sub, const std::string& name) {
  for (const CLI::Option* o : sub.get_options())
    if (!o->get_positional() && o->check_name(name)) return o;
  return nullptr;
}

std::vector<std::string> option_names(const CLI::App& sub) {
  std::vector<std::string> out;
  for (const CLI::Option* o : sub.get_options())
    if (!o->get_positional() && !o->get_group().empty())
      for (const std::string& n : o->get_lnames()) out.push_back("--" + n);
  return out;
}

}  // namespace

std::vector<std::string> complete(const CLI::App& app, const std::vector<std::string>& words) {
  if (words.empty()) return {};
  const std::string& cur = words.back();
  if (words.size() == 1) {
    if (starts_with(cur, "-")) return option_names(app);
    std::vector<std::string> out;
    for (const CLI::App* s : app.get_subcommands([](const CLI::App* a) { return !a->get_group().empty(); }))
      out.push_back(s->get_name());
    return out;
  }
  const CLI::App* sub = nullptr;
  for (const CLI::App* s : app.get_subcommands({}))
    if (s->get_name() == words[0]) sub = s;
  if (!sub) return {};
  // The words before the one being completed: options, their values, positionals.
  const CLI::Option* pending = nullptr;
  std::size_t positionals = 0;
  for (std::size_t k = 1; k + 1 < words.size(); ++k) {
    const std::string& w = words[k];
    if (pending) {
      pending = nullptr;
    } else if (starts_with(w, "-") && w.size() > 1) {
      const auto eq = w.find('=');
      const CLI::Option* o = find_option(*sub, w.substr(0, eq));
      if (o && program::takes_value(o) && eq == std::string::npos) pending = o;
    } else {
      ++positionals;
    }
  }
  if (pending) return values_for(pending);
  if (starts_with(cur, "--") && cur.find('=') != std::string::npos) {
    const std::string name = cur.substr(0, cur.find('='));
    const CLI::Option* o = find_option(*sub, name);
    std::vector<std::string> out;
    if (o)
      for (const auto& v : values_for(o))
        if (!starts_with(v, "__")) out.push_back(name + "=" + v);
    return out;
  }
  if (starts_with(cur, "-")) return option_names(*sub);
  std::vector<const CLI::Option*> pos;
  for (const CLI::Option* o : sub->get_options())
    if (o->get_positional()) pos.push_back(o);
  if (pos.empty()) return option_names(*sub);
  const CLI::Option* p = positionals < pos.size() ? pos[positionals] : (is_vector(pos.back()) ? pos.back() : nullptr);
  return p ? values_for(p) : std::vector<std::string>{};
}

}  // namespace cpm::cli
