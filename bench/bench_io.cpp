// SPDX-License-Identifier: Apache-2.0
// Speed of the measurement-file reader and writer: a 60 s, 1 kHz motion log
// (60 000 rows, 13 columns of full-precision numbers) must read well under 1 s.
#include <benchmark/benchmark.h>

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <random>

#include "cpm/io/data_files.hpp"

namespace {

cpm::io::MotionData motion_log(int rows) {
  cpm::io::MotionData m;
  m.rate = 1000.0;
  std::mt19937_64 rng(1);
  std::normal_distribution<double> noise(0.0, 1e-6);
  for (int i = 0; i < rows; ++i) {
    const double t = i * 1e-3;
    const double w = 0.5 * M_PI;
    m.t.push_back(t);
    m.d.emplace_back(0.2 + 0.175 * std::cos(w * t) + noise(rng), 0.2 + 0.175 * std::sin(w * t), 0.07);
    m.v.emplace_back(-0.175 * w * std::sin(w * t), 0.175 * w * std::cos(w * t), noise(rng));
    m.f.emplace_back(10.0 * std::sin(w * t) + noise(rng), -5.0 * std::cos(w * t), -60.0 + noise(rng));
    m.a.emplace_back(noise(rng), noise(rng), noise(rng));
  }
  return m;
}

struct LogFile {
  std::string path = (std::filesystem::temp_directory_path() / "cpm_bench_io_motion.csv").string();
  LogFile() { cpm::io::write_motion(path, motion_log(60000)); }
  ~LogFile() { std::remove(path.c_str()); }
};

void BM_ReadMotionLog60k(benchmark::State& state) {
  static const LogFile file;
  for (auto _ : state) {
    const cpm::io::MotionData m = cpm::io::read_motion(file.path);
    benchmark::DoNotOptimize(m.t.data());
  }
  state.SetItemsProcessed(state.iterations() * 60000);
  state.SetBytesProcessed(state.iterations() *
                          static_cast<std::int64_t>(std::filesystem::file_size(file.path)));
}
BENCHMARK(BM_ReadMotionLog60k)->Unit(benchmark::kMillisecond);

void BM_WriteMotionLog60k(benchmark::State& state) {
  const cpm::io::MotionData m = motion_log(60000);
  const std::string path = (std::filesystem::temp_directory_path() / "cpm_bench_io_write.csv").string();
  for (auto _ : state) cpm::io::write_motion(path, m);
  std::remove(path.c_str());
  state.SetItemsProcessed(state.iterations() * 60000);
}
BENCHMARK(BM_WriteMotionLog60k)->Unit(benchmark::kMillisecond);

}  // namespace
