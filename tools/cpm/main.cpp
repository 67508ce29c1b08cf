// SPDX-License-Identifier: Apache-2.0
// cpm: the command-line tool of cpmd. Subcommands live in cmd_*.cpp; CLI11
// parses every command line (cli.hpp).
#include <cstdio>
#include <exception>
#include <string>
#include <vector>

#include "cli.hpp"
#include "cpm/program_cli.hpp"

int main(int argc, char** argv) {
  using namespace cpm::cli;
  const std::vector<std::string> args(argv + 1, argv + argc);
  // The shell's completion (tools/completion/cpm): the words to complete are
  // a command line of their own, not options of cpm, so they bypass the parser.
  if (!args.empty() && args[0] == "__complete") {
    const auto app = make_app();
    for (const auto& c : complete(*app, std::vector<std::string>(args.begin() + 1, args.end())))
      std::printf("%s\n", c.c_str());
    return 0;
  }
  std::map<std::string, Run> runs;
  const auto app = make_app(&runs);
  if (args.empty()) {
    std::fputs(app->help().c_str(), stdout);
    return 2;
  }
  const bool known = registry().count(args[0]) > 0;
  const std::string who = known ? "cpm " + args[0] : "cpm";
  if (!known && args[0].rfind('-', 0) != 0) {
    std::fprintf(stderr, "cpm: unknown command '%s'; the commands are:", args[0].c_str());
    for (const auto& [name, entry] : registry()) std::fprintf(stderr, " %s", name.c_str());
    std::fprintf(stderr, "\n'cpm --help' says what each does.\n");
    return 2;
  }
  try {
    app->parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return cpm::program::parse_exit(*app, e, who);
  } catch (const std::exception& e) {  // UsageError from an option's own check
    std::fprintf(stderr, "%s: %s\n'%s --help' shows the options.\n", who.c_str(), e.what(), who.c_str());
    return 2;
  }
  const std::string name = app->get_subcommands().at(0)->get_name();
  try {
    return runs.at(name)();
  } catch (const UsageError& e) {
    std::fprintf(stderr, "%s: %s\n'%s --help' shows the options.\n", who.c_str(), e.what(), who.c_str());
    return 2;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "%s: error: %s\n", who.c_str(), e.what());
    return 1;
  }
}
