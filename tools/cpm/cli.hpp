// The `cpm` command line: one tool, one file per subcommand.
//
// A subcommand registers itself with a static `Command` object:
//   static const cpm::cli::Command reg{"table3", "reproduce Elkady's Table 3", run, usage};
// and parses its options with `Args`, which refuses unknown or malformed
// options with a message that names them.
#pragma once

#include <functional>
#include <map>
#include <optional>
#include <set>
#include <stdexcept>
#include <string>
#include <vector>

#include "cpm/io/model_file.hpp"
#include "cpm/kinematics/types.hpp"

namespace cpm::cli {

// Thrown for bad command lines; main prints it with the command's usage.
struct UsageError : std::runtime_error {
  using std::runtime_error::runtime_error;
};

class Args {
 public:
  Args(std::string command, std::vector<std::string> argv);
  // --name (no value)
  bool flag(const std::string& name);
  // --name VALUE or --name=VALUE
  std::optional<std::string> option(const std::string& name);
  // Every value of a repeatable option, in order.
  std::vector<std::string> options(const std::string& name);
  std::string option_or(const std::string& name, const std::string& fallback);
  double number(const std::string& name, double fallback);  // finite number or UsageError
  long integer(const std::string& name, long fallback);
  std::vector<std::string> positionals();
  // Call after reading every option: fails on anything not consumed.
  void finish();
  [[nodiscard]] const std::string& command() const { return command_; }

 private:
  std::string command_;
  std::vector<std::string> argv_;
  std::vector<bool> used_;
};

struct Command {
  using Run = std::function<int(Args&)>;
  Command(const char* name, const char* summary, Run run, const char* usage);
};

struct CommandEntry {
  std::string summary;
  Command::Run run;
  std::string usage;
};
std::map<std::string, CommandEntry>& registry();

// Helpers shared by subcommands.
std::string json_number(double v);                  // finite -> shortest exact text, else null
// io::write_file_atomically (temporary file, fsync, rename).
void write_file_atomically(const std::string& path, const std::string& text);
// The default machine model (the published path config/machine.yaml): from
// the current folder when it has one, else beside the build tree this cpm
// came from (build/bin/cpm -> config/machine.yaml), else the installed copy
// (/etc/cpmd/machine.yaml). The relative path when none exists, so the
// error names it.
std::string default_model_path();

// A model file after a fit (cpm fit, cpm loop): the fitted parameters replace
// those of the same name, and the history records the tool, the data file with
// its hash, the time and the note.
void record_fit(io::ModelFile& mf, const std::vector<io::FittedParameter>& fitted, const std::string& tool,
                const std::string& data_path, const std::string& note);
// "x,y,z" in metres. Non-finite values are refused unless `allow_non_finite`
// (the daemon client passes them on so that the daemon's refusal can be seen).
Vec3 parse_point(const std::string& what, const std::string& text, bool allow_non_finite = false);

}  // namespace cpm::cli
