// SPDX-License-Identifier: Apache-2.0
#include "cpm/daemon/stats_json.hpp"

#include <nlohmann/json.hpp>

namespace cpm::daemon {
namespace {

using Json = nlohmann::ordered_json;

// Non-empty bins only, keyed by their lower edge in us.
template <class Counts, class Floor>
Json histogram_json(const Counts& counts, int bins, Floor floor_us) {
  Json h = Json::object();
  for (int b = 0; b < bins; ++b)
    if (counts[static_cast<std::size_t>(b)]) h[std::to_string(floor_us(b))] = counts[static_cast<std::size_t>(b)];
  return h;
}

Json series_json(const cpm_msgs::loop_stats_t& s, int i) {
  return {{"count", s.count[i]},
          {"min_ns", s.min_ns[i]},
          {"max_ns", s.max_ns[i]},
          {"mean_ns", s.count[i] ? s.sum_ns[i] / static_cast<double>(s.count[i]) : 0.0},
          {"histogram_us", histogram_json(s.histogram[i], kBins, [](int b) { return histogram_bin_floor(b) / 1000; })}};
}

}  // namespace

std::string stats_json(const cpm_msgs::loop_stats_t& s, const FineLatencyHistogram& fine) {
  static const char* names[kSeries] = {"wakeup_latency", "read", "estimate", "trajectory", "inverse_kinematics",
                                       "controller", "safety", "write", "publish", "cycle"};
  Json series = Json::object();
  for (int i = 0; i < kSeries; ++i) {
    Json one = series_json(s, i);
    if (i == kSeriesLatency) one["histogram_1us"] = histogram_json(fine, kFineLatencyBins, [](int b) { return b; });
    series[names[i]] = std::move(one);
  }
  const Json o = {{"rate_hz", s.rate_hz},       {"cycles", s.cycles},
                  {"overruns", s.overruns},     {"skipped", s.skipped},
                  {"realtime", s.realtime != 0}, {"memory_locked", s.memory_locked != 0},
                  {"series", series}};
  return o.dump(2, ' ', false, Json::error_handler_t::replace) + "\n";
}

}  // namespace cpm::daemon
