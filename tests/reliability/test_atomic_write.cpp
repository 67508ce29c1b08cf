// SPDX-License-Identifier: Apache-2.0
// Nothing lost: the model file writer (io::save_model_file renders, then
// io::write_file_atomically: temporary file beside the target, fsync,
// rename) killed with SIGKILL while it writes leaves the target whole —
// byte for byte the old model or the new one, loadable — never a torn file.
// A child process rewrites the file in a loop, alternating two rendered
// models; the parent kills it at staggered moments, 24 times.
#include <gtest/gtest.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <thread>

#include "cpm/io/model_file.hpp"

namespace cpm::daemon::test {
namespace {

namespace fs = std::filesystem;

io::ModelFile model_with_history(const std::string& note, int entries) {
  io::ModelFile m;
  m.model = ctl::MachineModel::elkady();
  for (int i = 0; i < entries; ++i) {
    io::Provenance p;
    p.tool = "cpm test";
    p.date = "2026-01-01T00:00:00Z";
    p.note = note + " entry " + std::to_string(i);
    m.history.push_back(p);
  }
  return m;
}

TEST(NothingLost, ModelFileKilledMidWriteIsOldOrNewNeverTorn) {
  const fs::path dir = fs::temp_directory_path() / ("cpm-reliab-atomic-" + std::to_string(getpid()));
  fs::remove_all(dir);
  fs::create_directories(dir);
  const std::string path = (dir / "machine.yaml").string();
  // Large files (a few 100 kB) make a write take long enough to be hit.
  const io::ModelFile a = model_with_history("old", 4000), b = model_with_history("new", 4000);
  const std::string text_a = io::render_model_file(a), text_b = io::render_model_file(b);
  ASSERT_NE(text_a, text_b);
  io::save_model_file(path, a);
  ASSERT_EQ(io::load_model_file(path).history.size(), a.history.size());  // both texts load
  ASSERT_EQ(io::parse_model_file(text_b, "b.yaml").history.back().note, "new entry 3999");
  int torn = 0, hit_mid_write = 0, was_a = 0, was_b = 0;
  for (int round = 0; round < 24; ++round) {
    const pid_t pid = fork();
    ASSERT_GE(pid, 0);
    if (pid == 0) {
      for (int n = 0;; ++n) {
        try {
          io::write_file_atomically(path, (n % 2) ? text_a : text_b);
        } catch (...) {
          _exit(3);
        }
      }
    }
    // Staggered: 2 to 25 ms into the child's loop of writes.
    std::this_thread::sleep_for(std::chrono::microseconds(2000 + 1000 * round));
    kill(pid, SIGKILL);
    int st = 0;
    waitpid(pid, &st, 0);
    ASSERT_TRUE(WIFSIGNALED(st)) << "the writer ended on its own (status " << st << ")";
    // A temporary file left behind: the kill landed inside a write.
    for (const auto& e : fs::directory_iterator(dir)) {
      if (e.path().filename().string().rfind(".machine.yaml.tmp.", 0) == 0) {
        ++hit_mid_write;
        fs::remove(e.path());
      }
    }
    const std::string now = [&] {
      std::ifstream f(path);
      std::stringstream ss;
      ss << f.rdbuf();
      return ss.str();
    }();
    if (now == text_a) ++was_a;
    else if (now == text_b) ++was_b;
    else ++torn;
  }
  std::printf("atomic write: 24 kills, %d inside a write (temporary file left), file old %d / new %d, torn %d\n",
              hit_mid_write, was_a, was_b, torn);
  EXPECT_EQ(torn, 0);
  EXPECT_GT(hit_mid_write, 0) << "no kill landed inside a write: the test proves nothing";
  fs::remove_all(dir);
}

}  // namespace
}  // namespace cpm::daemon::test
