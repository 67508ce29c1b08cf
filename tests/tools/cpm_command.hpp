// SPDX-License-Identifier: Apache-2.0
// Running the built `cpm` (CPM_EXE) from a test: its exit status and what it
// printed, through files in a temporary folder of the test's own.
#pragma once

#include <sys/wait.h>
#include <unistd.h>

#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>

namespace cpm::test {

struct CpmResult {
  int status = -1;
  std::string out, err;
};

inline std::string slurp(const std::filesystem::path& p) {
  std::ifstream f(p);
  std::stringstream ss;
  ss << f.rdbuf();
  return ss.str();
}

// A folder removed with everything in it when the test ends; `tag` keeps
// tests that run at once apart.
struct TempFolder {
  std::filesystem::path dir;
  explicit TempFolder(const std::string& tag)
      : dir(std::filesystem::temp_directory_path() / ("cpm-" + tag + "-" + std::to_string(getpid()))) {
    std::filesystem::create_directories(dir);
  }
  ~TempFolder() { std::filesystem::remove_all(dir); }
};

// Any shell command, its standard output and error together in `log`.
struct CommandResult {
  int status = -1;
  std::string out;
};
inline CommandResult run_command(const std::string& cmd, const std::filesystem::path& log) {
  const int rc = std::system((cmd + " >" + log.string() + " 2>&1").c_str());
  return {WIFEXITED(rc) ? WEXITSTATUS(rc) : -1, slurp(log)};
}

// `cpm ARGS`, its output kept in t.dir/out and t.dir/err.
inline CpmResult run_cpm(const std::string& args, const TempFolder& t) {
  const std::string cmd = std::string(CPM_EXE) + " " + args + " >" + (t.dir / "out").string() + " 2>" +
                          (t.dir / "err").string();
  const int rc = std::system(cmd.c_str());
  CpmResult r;
  r.status = WIFEXITED(rc) ? WEXITSTATUS(rc) : -1;
  r.out = slurp(t.dir / "out");
  r.err = slurp(t.dir / "err");
  return r;
}

}  // namespace cpm::test
