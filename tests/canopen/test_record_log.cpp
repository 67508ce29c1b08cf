// SPDX-License-Identifier: Apache-2.0
// The motion log recorded through the CANopen path (record_log.hpp): what it
// holds, and that it survives the CSV layout of docs/data-formats.md.
#include <algorithm>
#include <filesystem>

#include "canopen/record_log.hpp"
#include "cpm/io/data_files.hpp"

namespace cpm::daemon::test {
namespace {

TEST(RecordCanopenLog, TheDaemonsViewOfARichMotionWritesAndReadsBack) {
  const io::MotionData m = record_canopen_motion_log(6.0, 7, true);
  // The move to the Lissajous' centre, then 6 s of it, a row per period.
  ASSERT_GT(m.t.size(), 3000u);
  EXPECT_EQ(m.rate, 500.0);
  for (std::size_t k = 1; k < m.t.size(); ++k) ASSERT_NEAR(m.t[k] - m.t[k - 1], 1.0 / 500, 1e-12) << k;
  // Every axis both ways, at varied speeds.
  for (int i = 0; i < 3; ++i) {
    double lo = 1e9, hi = -1e9, vmin = 1e9, vmax = -1e9;
    for (std::size_t k = 0; k < m.t.size(); ++k) {
      lo = std::min(lo, m.d[k][i]), hi = std::max(hi, m.d[k][i]);
      vmin = std::min(vmin, m.v[k][i]), vmax = std::max(vmax, m.v[k][i]);
    }
    EXPECT_GT(hi - lo, 0.1) << "axis " << i + 1;
    EXPECT_LT(vmin, -0.1) << "axis " << i + 1;
    EXPECT_GT(vmax, 0.1) << "axis " << i + 1;
  }
  // The encoder noise shows: the velocity's period-to-period jitter, where
  // the motion itself changes it by far less (jerk ~3 m/s^3 * (2 ms)^2 =
  // 0.012 mm/s). The second difference of white noise sigma has the
  // deviation sqrt(6) sigma, and a median |.| of 0.6745 times that (the
  // median ignores the few periods where the motion jolts: brake release,
  // the start of the move).
  std::vector<double> jitter;
  for (std::size_t k = 2; k < m.t.size(); ++k)
    for (int i = 0; i < 3; ++i) jitter.push_back(std::abs(m.v[k][i] - 2 * m.v[k - 1][i] + m.v[k - 2][i]));
  std::nth_element(jitter.begin(), jitter.begin() + static_cast<long>(jitter.size() / 2), jitter.end());
  const double expected = 0.6745 * std::sqrt(6.0) * 2e-4;
  EXPECT_NEAR(jitter[jitter.size() / 2], expected, 0.15 * expected);

  const std::string path = (std::filesystem::temp_directory_path() / "cpm_canopen_motion_log.csv").string();
  io::write_motion(path, m);
  const io::MotionData back = io::read_motion(path);
  std::filesystem::remove(path);
  ASSERT_EQ(back.t.size(), m.t.size());
  EXPECT_EQ(back.rate, m.rate);
  for (std::size_t k = 0; k < m.t.size(); ++k) {
    ASSERT_EQ(back.t[k], m.t[k]) << k;  // full precision
    ASSERT_EQ(back.d[k], m.d[k]) << k;
    ASSERT_EQ(back.v[k], m.v[k]) << k;
    ASSERT_EQ(back.f[k], m.f[k]) << k;
  }
}

}  // namespace
}  // namespace cpm::daemon::test
