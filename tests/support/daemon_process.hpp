// SPDX-License-Identifier: Apache-2.0
// The one harness of the process-level tests (tests/daemon e2e,
// tests/reliability, tests/redteam, tests/sil_daemon): cpmd and other
// programs as child processes with their stderr in a log, a private network
// namespace for LCM, a throw-away operators directory with keys, and
// config/sim.yaml adapted to the test.
//
// Network: a test binary that links support/netns_main.cpp moves itself into
// a fresh network namespace (loopback up, a multicast route on lo) before
// any socket or thread exists, when it may (root, as on CI); every daemon it
// starts lives there and nothing it sends leaves it. gtest_discover_tests
// runs each test as its own process, so each test has its own namespace.
// Without root it uses the host's loopback with ttl=0 and a private port.
#pragma once

#include <fcntl.h>
#include <signal.h>
#include <spawn.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <filesystem>
#include <fstream>
#include <map>
#include <memory>
#include <optional>
#include <regex>
#include <sstream>
#include <string>
#include <thread>
#include <utility>
#include <vector>

#include "cpm/daemon/auth.hpp"
#include "cpm/daemon/config.hpp"

extern char** environ;

namespace cpm::test {

// Set by netns_main.cpp: whether this process runs in its own network namespace.
extern bool g_netns;

// Into a fresh network namespace with lo up and multicast routed on it.
// Call before any socket or thread exists; false when not permitted.
bool enter_private_netns();

// A child process: argv[0] is the program's path; its stderr (and stdout,
// unless `stdout_log` is false: then /dev/null) goes to `log`.
class Process {
 public:
  Process(std::vector<std::string> argv, std::string log, bool stdout_log = false) : log_(std::move(log)) {
    std::vector<char*> args;
    for (auto& a : argv) args.push_back(a.data());
    args.push_back(nullptr);
    posix_spawn_file_actions_t fa;
    posix_spawn_file_actions_init(&fa);
    posix_spawn_file_actions_addopen(&fa, 2, log_.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
    if (stdout_log) posix_spawn_file_actions_adddup2(&fa, 2, 1);
    else posix_spawn_file_actions_addopen(&fa, 1, "/dev/null", O_WRONLY, 0);
    if (posix_spawn(&pid_, args[0], &fa, nullptr, args.data(), environ) != 0) pid_ = -1;
    posix_spawn_file_actions_destroy(&fa);
  }
  ~Process() { kill9(); }
  Process(const Process&) = delete;
  Process& operator=(const Process&) = delete;

  [[nodiscard]] pid_t pid() const { return pid_; }
  // SIGKILL: no handler runs.
  void kill9() {
    if (pid_ > 0) {
      ::kill(pid_, SIGKILL);
      reap(0);
    }
  }
  void signal(int sig) const {
    if (pid_ > 0) ::kill(pid_, sig);
  }
  // SIGTERM, then the exit code (128 + signal when killed).
  int terminate() {
    if (pid_ <= 0) return exit_code_.value_or(-1);
    ::kill(pid_, SIGTERM);
    return wait_exit();
  }
  int wait_exit() {
    if (pid_ > 0) reap(0);
    return exit_code_.value_or(-1);
  }
  // The exit code if it ends within `timeout_s`; nullopt if still running.
  std::optional<int> wait_exit_for(double timeout_s) {
    const auto end = std::chrono::steady_clock::now() + std::chrono::duration<double>(timeout_s);
    while (pid_ > 0 && !reap(WNOHANG)) {
      if (std::chrono::steady_clock::now() > end) return std::nullopt;
      std::this_thread::sleep_for(std::chrono::milliseconds(10));
    }
    return exit_code_;
  }
  bool running() { return pid_ > 0 && !reap(WNOHANG); }
  [[nodiscard]] std::string log() const {
    std::ifstream f(log_);
    std::stringstream ss;
    ss << f.rdbuf();
    return ss.str();
  }
  [[nodiscard]] const std::string& log_path() const { return log_; }

 private:
  // Whether the child was reaped (its exit code kept).
  bool reap(int flags) {
    int st = 0;
    if (::waitpid(pid_, &st, flags) != pid_) return false;
    exit_code_ = WIFEXITED(st) ? WEXITSTATUS(st) : 128 + WTERMSIG(st);
    pid_ = -1;
    return true;
  }
  std::string log_;
  pid_t pid_ = -1;
  std::optional<int> exit_code_;
};

// A fresh directory under the system's temporary directory, removed with its contents.
class TempDir {
 public:
  explicit TempDir(const std::string& what) {
    path_ = (std::filesystem::temp_directory_path() / ("cpm-" + what + "-" + std::to_string(::getpid()))).string();
    std::filesystem::remove_all(path_);
    std::filesystem::create_directories(path_);
  }
  ~TempDir() {
    std::error_code ec;
    std::filesystem::permissions(path_, std::filesystem::perms::owner_all, std::filesystem::perm_options::add, ec);
    std::filesystem::remove_all(path_, ec);
  }
  TempDir(const TempDir&) = delete;
  TempDir& operator=(const TempDir&) = delete;
  [[nodiscard]] const std::string& path() const { return path_; }
  [[nodiscard]] std::string operator/(const std::string& name) const { return path_ + "/" + name; }

 private:
  std::string path_;
};

// An operators directory as cpmd reads it (docs/security.md): NAME.key files
// (fresh random keys, mode 0600) and roles.yaml.
class OperatorsDir {
 public:
  explicit OperatorsDir(std::string dir) : dir_(std::move(dir)) {
    std::filesystem::create_directories(dir_);
    ::chmod(dir_.c_str(), 0700);
    write_roles();
  }
  // A new operator with a fresh key (replaces one of the same name: rotation).
  daemon::Credentials add(const std::string& name, daemon::Role role) {
    daemon::Credentials c{name, daemon::generate_key()};
    ::unlink(key_path(name).c_str());
    daemon::write_key_file(key_path(name), c.key);
    roles_[name] = role;
    write_roles();
    return c;
  }
  [[nodiscard]] std::string key_path(const std::string& name) const { return dir_ + "/" + name + ".key"; }
  [[nodiscard]] const std::string& path() const { return dir_; }

 private:
  void write_roles() {
    std::ofstream f(dir_ + "/roles.yaml");
    f << "# written by the test harness\n";
    for (const auto& [n, r] : roles_) f << n << ": " << daemon::role_name(r) << "\n";
  }
  std::string dir_;
  std::map<std::string, daemon::Role> roles_;
};

#ifdef CPM_SOURCE_DIR
// The LCM port the tests use: the default inside a private namespace, else
// one derived from the process id (the host's loopback is shared).
inline int lcm_port() { return g_netns ? 7667 : 20000 + ::getpid() % 20000; }

// config/sim.yaml written to dir/name for a test: the test's LCM port,
// absolute model paths, tolerant of a noisy CI machine (overruns do not
// fault), security.operators_dir and model_dir as given, and `edits`
// (regex -> replacement) last.
inline std::string sim_config(const std::string& dir, const std::string& name, const std::string& operators_dir,
                              const std::vector<std::pair<std::string, std::string>>& edits = {},
                              const std::string& model_dir = std::string(CPM_SOURCE_DIR) + "/config") {
  std::ifstream f(std::string(CPM_SOURCE_DIR) + "/config/sim.yaml");
  std::stringstream ss;
  ss << f.rdbuf();
  std::string text = ss.str();
  text = std::regex_replace(text, std::regex("udpm://239.255.76.67:7667"),
                            "udpm://239.255.76.67:" + std::to_string(lcm_port()));
  text = std::regex_replace(text, std::regex(" machine\\.yaml"), std::string(" ") + CPM_SOURCE_DIR + "/config/machine.yaml");
  text = std::regex_replace(text, std::regex("max_consecutive_overruns: 5"), "max_consecutive_overruns: 100000");
  text = std::regex_replace(text, std::regex("operators_dir: [^ \\n]+"), "operators_dir: " + operators_dir);
  text = std::regex_replace(text, std::regex("model_dir: [^ \\n]+"), "model_dir: " + model_dir);
  for (const auto& [from, to] : edits) text = std::regex_replace(text, std::regex(from), to);
  const std::string path = dir + "/" + name;
  std::ofstream(path) << text;
  return path;
}

#endif

#ifdef CPMD_EXE
// cpmd as a child: `cpmd --config CONFIG [extra...]`, stderr in `log`.
inline std::unique_ptr<Process> start_cpmd(const std::string& config, const std::string& log,
                                           const std::vector<std::string>& extra = {}) {
  std::vector<std::string> argv{CPMD_EXE, "--config", config};
  argv.insert(argv.end(), extra.begin(), extra.end());
  return std::make_unique<Process>(argv, log);
}
#endif

// VmRSS of a process (kB), from /proc/PID/status; -1 when unreadable.
inline long rss_kb(pid_t pid) {
  std::ifstream f("/proc/" + std::to_string(pid) + "/status");
  std::string line;
  while (std::getline(f, line))
    if (line.rfind("VmRSS:", 0) == 0) return std::stol(line.substr(6));
  return -1;
}

}  // namespace cpm::test
