// SPDX-License-Identifier: Apache-2.0
#include "state_log.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <fstream>
#include <lcm/lcm-cpp.hpp>
#include <vector>

namespace cpm::cli {

using cpm_msgs::state_t;

namespace {

bool drives_apply_force(const state_t& s) {
  return s.mode == state_t::MODE_HOLDING || s.mode == state_t::MODE_MOVING || s.mode == state_t::MODE_STOPPING;
}

// The first field of `s` that is not finite, or nullptr.
const char* first_non_finite(const state_t& s) {
  static const char* d_names[3] = {"d1", "d2", "d3"};
  static const char* v_names[3] = {"v1 (d_dot)", "v2 (d_dot)", "v3 (d_dot)"};
  static const char* f_names[3] = {"f1 (force)", "f2 (force)", "f3 (force)"};
  if (!std::isfinite(s.t)) return "t";
  for (int i = 0; i < 3; ++i) {
    if (!std::isfinite(s.d[i])) return d_names[i];
    if (!std::isfinite(s.d_dot[i])) return v_names[i];
    if (!std::isfinite(s.force[i])) return f_names[i];
  }
  return nullptr;
}

}  // namespace

void StateToMotion::add(const state_t& s, int location) {
  if (!drives_apply_force(s)) {
    ++inactive_;
    in_run_ = false;
    return;
  }
  if (!in_run_) ++run_;
  in_run_ = true;
  data_.t.push_back(s.t);
  data_.d.emplace_back(s.d[0], s.d[1], s.d[2]);
  data_.v.emplace_back(s.d_dot[0], s.d_dot[1], s.d_dot[2]);
  data_.f.emplace_back(s.force[0], s.force[1], s.force[2]);
  data_.run.push_back(run_);
  data_.info.line_of_row.push_back(location);
}

io::MotionData StateToMotion::finish(const std::string& path, const std::string& source) const {
  io::MotionData m = data_;
  m.info.path = path;
  if (!source.empty()) m.info.metadata["source"] = source;
  // Nominal sample rate: the median step inside runs (the loop's rate over
  // the state decimation); missing messages do not change it.
  std::vector<double> steps;
  for (std::size_t k = 1; k < m.t.size(); ++k)
    if (m.run[k] == m.run[k - 1] && m.t[k] > m.t[k - 1]) steps.push_back(m.t[k] - m.t[k - 1]);
  if (!steps.empty()) {
    std::nth_element(steps.begin(), steps.begin() + static_cast<long>(steps.size() / 2), steps.end());
    m.rate = std::round(1.0 / steps[steps.size() / 2]);
  }
  // One run only: the column says nothing.
  if (run_ <= 0) m.run.clear();
  return m;
}

bool is_lcm_log(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  std::array<unsigned char, 4> b{};
  if (!in.read(reinterpret_cast<char*>(b.data()), 4)) return false;
  return b[0] == 0xED && b[1] == 0xA1 && b[2] == 0xDA && b[3] == 0x01;  // lcm-logger's sync word
}

StateLogRead read_state_log(const std::string& path, const std::string& channel, bool strict) {
  lcm::LogFile log(path, "r");
  if (!log.good()) throw Error(path + ": cannot open as an LCM log");
  StateLogRead out;
  StateToMotion conv;
  for (const lcm::LogEvent* ev = log.readNextEvent(); ev; ev = log.readNextEvent()) {
    if (ev->channel != channel) continue;
    const std::string where = path + ": event " + std::to_string(ev->eventnum) + " on " + channel;
    state_t s{};  // zeroed: decode fills what it reads, and -O2 cannot see that it fills all
    if (s.decode(ev->data, 0, ev->datalen) < 0) {
      if (strict) throw Error(where + ": not a cpmd state_t (it does not decode)");
      ++out.undecodable;
      continue;
    }
    if (const char* bad = first_non_finite(s)) {
      if (strict) throw Error(where + ": " + bad + " is not a finite number");
      ++out.undecodable;
      continue;
    }
    conv.add(s, static_cast<int>(std::min<std::int64_t>(ev->eventnum, 0x7fffffff)));
  }
  if (conv.rows() == 0)
    throw Error(path + ": no state of cpmd with the drives applying force on channel " + channel + " (" +
                std::to_string(conv.inactive()) + " states with the drives off or faulted)");
  out.inactive = conv.inactive();
  out.data = conv.finish(path, "cpmd state from lcm-logger file, channel " + channel);
  out.data.info.warnings.push_back(path + " is an lcm-logger file: the row numbers in messages are its event numbers");
  if (out.inactive > 0)
    out.data.info.warnings.push_back(std::to_string(out.inactive) +
                                     " states left out: the drives were not applying the commanded force "
                                     "(modes other than holding, moving, stopping)");
  return out;
}

io::DataSet read_measurements(const std::string& path, const std::string& channel) {
  if (is_lcm_log(path)) return read_state_log(path, channel, true).data;
  return io::read_data_file(path);
}

}  // namespace cpm::cli
