// cpm: the command-line tool of cpmd. Subcommands live in cmd_*.cpp.
#include <cstdio>
#include <exception>

#include "cli.hpp"

namespace {

void print_help() {
  std::printf("usage: cpm <command> [options]\n\ncommands:\n");
  for (const auto& [name, entry] : cpm::cli::registry())
    std::printf("  %-16s %s\n", name.c_str(), entry.summary.c_str());
  std::printf("\n'cpm <command> --help' shows a command's options.\n");
}

}  // namespace

int main(int argc, char** argv) {
  if (argc < 2 || std::string(argv[1]) == "--help" || std::string(argv[1]) == "-h") {
    print_help();
    return argc < 2 ? 2 : 0;
  }
  const std::string name = argv[1];
  auto& reg = cpm::cli::registry();
  const auto it = reg.find(name);
  if (it == reg.end()) {
    std::fprintf(stderr, "cpm: unknown command '%s'\n", name.c_str());
    print_help();
    return 2;
  }
  std::vector<std::string> args(argv + 2, argv + argc);
  for (const auto& a : args)
    if (a == "--help" || a == "-h") {
      std::printf("usage: cpm %s %s\n", name.c_str(), it->second.usage.c_str());
      return 0;
    }
  try {
    cpm::cli::Args parsed(name, args);
    return it->second.run(parsed);
  } catch (const cpm::cli::UsageError& e) {
    std::fprintf(stderr, "cpm %s: %s\nusage: cpm %s %s\n", name.c_str(), e.what(), name.c_str(),
                 it->second.usage.c_str());
    return 2;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "cpm %s: error: %s\n", name.c_str(), e.what());
    return 1;
  }
}
