// SPDX-License-Identifier: Apache-2.0
// cpmd --stats-json: the loop statistics at exit as JSON (bench/report.py
// and docs/performance.md read it).
#pragma once

#include <string>

#include "cpm/daemon/loop.hpp"
#include <cpm_msgs/loop_stats_t.hpp>

namespace cpm::daemon {

// {"rate_hz", "cycles", "overruns", "skipped", "realtime", "memory_locked",
//  "series": {name: {"count", "min_ns", "max_ns", "mean_ns", "histogram_us":
//  {bin floor in us: count}}}}, series in the order of loop_stats_t (ns); the
// wake-up latency also in 1 us bins, `fine`, as "histogram_1us" (empty bins left out).
std::string stats_json(const cpm_msgs::loop_stats_t& s, const FineLatencyHistogram& fine);

}  // namespace cpm::daemon
