// SPDX-License-Identifier: Apache-2.0
// The `cpm` command line: one tool, one file per subcommand, parsed by CLI11.
//
// A subcommand registers itself with a static `Command` object whose setup
// declares its options on a CLI11 App and returns what runs once they are
// parsed:
//   struct Options { std::optional<std::string> json; };
//   static const cpm::cli::Command reg{"table3", "reproduce Elkady's Table 3", [](CLI::App& app) {
//     auto o = std::make_shared<Options>();
//     app.add_option("--json", o->json, "write the table as JSON to FILE")->type_name("FILE");
//     return [o] { return run(*o); };
//   }};
// CLI11 refuses unknown or malformed options with a message that names them;
// `UsageError` is for what only the command can judge (a missing --out, two
// options that do not go together). Both exit with status 2.
#pragma once

#include <CLI/CLI.hpp>
#include <filesystem>
#include <functional>
#include <map>
#include <memory>
#include <nlohmann/json.hpp>
#include <optional>
#include <stdexcept>
#include <string>
#include <vector>

#include "cpm/io/model_file.hpp"
#include "cpm/kinematics/types.hpp"

namespace cpm::cli {

// Thrown for bad command lines; main prints it and exits with status 2.
struct UsageError : std::runtime_error {
  using std::runtime_error::runtime_error;
};

// What a subcommand runs once its command line is parsed: the exit status.
using Run = std::function<int()>;
// Declares the subcommand's options on `app` and returns its Run, which reads
// the variables the options were bound to.
using Setup = std::function<Run(CLI::App& app)>;

struct Command {
  Command(const char* name, const char* summary, Setup setup);
};

struct CommandEntry {
  std::string summary;
  Setup setup;
};
std::map<std::string, CommandEntry>& registry();

// The whole `cpm` command line: every registered subcommand with its options
// (`runs` receives each one's Run by name). One source for main, the man
// pages (help2man reads --help) and the completion.
std::unique_ptr<CLI::App> make_app(std::map<std::string, Run>* runs = nullptr);

// Option helpers shared by subcommands.
// A finite number (CLI11 alone would take nan and inf).
const CLI::Validator& finite();
// An effect of the library by name, before an optional ':' (NAME, NAME:AXIS,
// NAME:AXIS:V1,...); an unknown name is refused with the list of valid ones.
const CLI::Validator& effect_name();
// Every effect of the library by name: the dynamic ones (ctl::info) and the
// kinematic ones (kin::info), in the tables' order.
std::vector<std::string> effect_names();
// The text listing them for error messages.
std::string effect_list();
// The control laws by name (ctl::law_name).
std::vector<std::string> law_names();
// A finite number named by its unit in the help (M, M/S, HZ, ...); unset
// keeps the variable's value, which the help shows as the default.
CLI::Option* add_number(CLI::App& app, const std::string& name, double& value, const std::string& unit,
                        const std::string& help);
// The same where the default depends on other options: unset is nullopt
// (give the help its default with ->default_str()).
CLI::Option* add_number(CLI::App& app, const std::string& name, std::optional<double>& value, const std::string& unit,
                        const std::string& help);
// A value from a fixed list, shown as A|B|C in the help (and completed).
CLI::Option* add_choice(CLI::App& app, const std::string& name, std::string& value, const std::vector<std::string>& choices,
                        const std::string& help);
// --model MODEL.yaml: unset means default_model_path() at run time.
CLI::Option* add_model_option(CLI::App& app, std::optional<std::string>& model, const std::string& what,
                              const std::string& name = "--model");
inline constexpr const char* kDefaultModelText =
    "config/machine.yaml here, else that of the build tree this cpm is in, else PREFIX/etc/cpmd/machine.yaml "
    "beside PREFIX/bin/cpm, else /etc/cpmd/machine.yaml";

// JSON: nlohmann-json with the keys in the order they are set. Numbers are
// written in their shortest form that reads back to the same double (0.6, not
// 0.59999999999999998); a non-finite number is written as null.
using Json = nlohmann::ordered_json;
// The text of `j` (indent < 0: one line), strings escaped, invalid UTF-8 replaced.
std::string json_text(const Json& j, int indent = 2);
// `j` with an indent of 2 and a final newline, written atomically.
void write_json(const std::string& path, const Json& j);

// io::write_file_atomically (temporary file, fsync, rename).
void write_file_atomically(const std::string& path, const std::string& text);
// The default machine model (the published path config/machine.yaml): from
// the current folder when it has one, else beside the build tree this cpm
// came from (build/bin/cpm -> config/machine.yaml), else beside the install
// prefix (PREFIX/bin/cpm -> PREFIX/etc/cpmd/machine.yaml), else the installed
// copy (/etc/cpmd/machine.yaml). The relative path when none exists, so the
// error names it.
std::string default_model_path();
// The same lookup with its places given: the current folder, this program's
// path and the system-wide file (for tests); `name` the file beside
// machine.yaml that is looked for (cpmd.yaml for the daemon's config).
std::string find_default_model(const std::filesystem::path& cwd, const std::filesystem::path& exe,
                               const std::filesystem::path& system_file, const std::string& name = "machine.yaml");
// The shipped daemon configuration (cpmd.yaml), looked for as the model is
// (config/cpmd.yaml here or beside the build tree, PREFIX/etc/cpmd/cpmd.yaml,
// /etc/cpmd/cpmd.yaml); nullopt when there is none.
std::optional<std::string> default_daemon_config_path();
// The --model given, else default_model_path(); an Error saying where it
// looked when there is none.
std::string model_or_default(const std::optional<std::string>& model);

// A model file after a fit (cpm fit, cpm loop): the fitted parameters replace
// those of the same name, and the history records the tool, the data file with
// its hash, the time and the note.
void record_fit(io::ModelFile& mf, const std::vector<io::FittedParameter>& fitted, const std::string& tool,
                const std::string& data_path, const std::string& note);
// "x,y,z" in metres. Non-finite values are refused unless `allow_non_finite`
// (the daemon client passes them on so that the daemon's refusal can be seen).
Vec3 parse_point(const std::string& what, const std::string& text, bool allow_non_finite = false);

// Completion (cpm __complete): the candidates for the last of `words` (the
// words after `cpm`, the last one being completed, possibly empty). One of
// them alone, "__files__" or "__dirs__", asks the shell to complete a path.
std::vector<std::string> complete(const CLI::App& app, const std::vector<std::string>& words);

}  // namespace cpm::cli
