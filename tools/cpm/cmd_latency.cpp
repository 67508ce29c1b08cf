// SPDX-License-Identifier: Apache-2.0
// cpm latency: the wake-up latency of a running cpmd's loop over N seconds,
// like LinuxCNC's latency-histogram: the histogram and its maximum over
// time, in text and SVG, beside cyclictest (rt-tests) run at the same period
// and priority when it is installed. It reads cpmd's statistics
// (loop_stats_t, once a second, cumulative since the loop started; signed
// state verified with --daemon-key as everywhere): the window's histogram is
// the last message's less the first's.
#include <signal.h>
#include <fcntl.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <sstream>
#include <vector>

#include "cmd_client_common.hpp"
#include "console.hpp"
#include "cpm/daemon/loop.hpp"

namespace cpm::cli::client {
namespace {

using cpm_msgs::loop_stats_t;
constexpr int kLat = daemon::kSeriesLatency;

std::atomic<bool> g_interrupted{false};
void on_sigint(int) { g_interrupted.store(true); }

// A histogram over latency bins given by their lower edges (us); the last
// bin is open above.
struct Histogram {
  std::vector<double> lo_us;
  std::vector<long long> count;
  [[nodiscard]] long long total() const {
    long long n = 0;
    for (long long c : count) n += c;
    return n;
  }
  // The upper edge of the highest bin with a count (us); 0 when empty.
  [[nodiscard]] double max_upper_us() const {
    for (std::size_t k = count.size(); k-- > 0;)
      if (count[k] > 0) return k + 1 < lo_us.size() ? lo_us[k + 1] : INFINITY;
    return 0;
  }
};

// cpmd's: loop_stats_t's bins, b less a.
Histogram cpmd_window(const loop_stats_t& a, const loop_stats_t& b) {
  Histogram h;
  for (int k = 0; k < daemon::kBins; ++k) {
    h.lo_us.push_back(static_cast<double>(daemon::histogram_bin_floor(k)) * 1e-3);
    h.count.push_back(static_cast<long long>(b.histogram[kLat][k]) - a.histogram[kLat][k]);
  }
  return h;
}

// `fine` counted in the bins of `like` (cyclictest's 1 us bins in cpmd's,
// 50 us wide above 200 us), so that the two plot on one scale.
Histogram rebin(const Histogram& fine, const Histogram& like) {
  Histogram h{like.lo_us, std::vector<long long>(like.count.size(), 0)};
  for (std::size_t k = 0; k < fine.count.size(); ++k) {
    const auto it = std::upper_bound(h.lo_us.begin(), h.lo_us.end(), fine.lo_us[k]);
    h.count[static_cast<std::size_t>(std::max<std::ptrdiff_t>(0, it - h.lo_us.begin() - 1))] += fine.count[k];
  }
  return h;
}

// The q-quantile's bin's upper edge (us), as `cpm stats` gives percentiles
// (console::percentile_us), of a histogram in cpmd's bins.
double percentile_us(const Histogram& h, double q) {
  loop_stats_t s{};
  for (int k = 0; k < daemon::kBins; ++k) s.histogram[kLat][k] = static_cast<std::int32_t>(h.count[k]);
  s.count[kLat] = h.total();
  return console::percentile_us(s, kLat, q);
}

// One second of the run (between two statistics messages).
struct Second {
  double t = 0;              // s since the first message
  double window_max_us = 0;  // upper edge of the highest bin reached in this second
  double max_us = 0;         // cpmd's worst since its loop started (exact, ns resolution)
  long long samples = 0;
};

struct Cyclictest {
  bool ran = false;
  std::string why;  // not run, or failed: why
  Histogram hist;   // 1 us bins, the last one open (-h 2000)
  long long cycles = 0, overflows = 0;
  double min_us = 0, avg_us = 0, max_us = 0;
};

struct Options {
  double seconds = 10;
  std::string svg, json;
  bool no_cyclictest = false;
  std::optional<int> priority;
  Connection connection;
};

// cyclictest at cpmd's period and priority, SECONDS long, its JSON in `file`;
// returns its pid (-1: not started, `why` says).
pid_t start_cyclictest(int period_us, int priority, int seconds, const std::string& file, const std::string& log,
                       std::string& why) {
  const char* paths[] = {"/usr/bin/cyclictest", "/usr/sbin/cyclictest", "/usr/local/bin/cyclictest"};
  std::string exe;
  for (const char* p : paths)
    if (::access(p, X_OK) == 0) exe = p;
  if (exe.empty()) {
    why = "cyclictest is not installed (Debian: rt-tests)";
    return -1;
  }
  std::vector<std::string> args{exe, "-q", "-m", "-t", "1", "-i", std::to_string(period_us), "-D", std::to_string(seconds),
                                "-h", "2000", "--default-system", "--json=" + file};
  if (priority > 0) args.insert(args.begin() + 1, {"-p", std::to_string(priority)});
  const pid_t pid = ::fork();
  if (pid == 0) {
    const int fd = ::open(log.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
    if (fd >= 0) ::dup2(fd, 1), ::dup2(fd, 2);
    std::vector<char*> argv;
    for (auto& a : args) argv.push_back(a.data());
    argv.push_back(nullptr);
    ::execv(argv[0], argv.data());
    ::_exit(127);
  }
  if (pid < 0) why = "cannot start cyclictest";
  return pid;
}

std::string slurp_file(const std::string& path) {
  std::ifstream f(path);
  std::stringstream ss;
  ss << f.rdbuf();
  return ss.str();
}

Cyclictest finish_cyclictest(pid_t pid, const std::string& file, const std::string& log) {
  Cyclictest c;
  int st = 0;
  ::waitpid(pid, &st, 0);
  if (!WIFEXITED(st) || WEXITSTATUS(st) != 0) {
    std::string text = slurp_file(log);
    while (!text.empty() && text.back() == '\n') text.pop_back();
    c.why = "cyclictest failed (exit " + std::to_string(WIFEXITED(st) ? WEXITSTATUS(st) : 128 + WTERMSIG(st)) + ")" +
            (text.empty() ? "" : ": " + text.substr(0, 300));
    return c;
  }
  try {
    const auto j = nlohmann::json::parse(slurp_file(file));
    const auto& t = j.at("thread").at("0");
    c.hist.lo_us.resize(2001);
    c.hist.count.assign(2001, 0);
    for (int k = 0; k <= 2000; ++k) c.hist.lo_us[k] = k;
    for (const auto& [bin, n] : t.at("histogram").items()) {
      const int k = std::stoi(bin);
      if (k >= 0 && k <= 2000) c.hist.count[k] += n.get<long long>();
    }
    c.cycles = t.at("cycles").get<long long>();
    c.min_us = t.at("min").get<double>();
    c.avg_us = t.at("avg").get<double>();
    c.max_us = t.at("max").get<double>();
    c.overflows = std::max(0LL, c.cycles - c.hist.total());
    c.hist.count[2000] += c.overflows;  // beyond the histogram: counted in the open bin
    c.ran = true;
  } catch (const std::exception& e) {
    c.why = std::string("cyclictest's JSON could not be read: ") + e.what();
  }
  return c;
}

// Rows of the text histogram: 1 us up to 20 us, then wider.
const double kRowEdges[] = {0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15, 16, 17, 18, 19, 20,
                            25, 30, 40, 50, 75, 100, 150, 200, 300, 500, 1000, 2000, INFINITY};

long long count_in(const Histogram& h, double lo, double hi) {
  long long n = 0;
  for (std::size_t k = 0; k < h.count.size(); ++k)
    if (h.lo_us[k] >= lo && h.lo_us[k] < hi) n += h.count[k];
  return n;
}

std::string bar(long long n, long long total) {
  if (n <= 0 || total <= 0) return "";
  // Logarithmic, as latency-histogram's: one # per decade of the share from 1e-7.
  const double decades = std::log10(static_cast<double>(n) / static_cast<double>(total)) + 7.0;
  return std::string(static_cast<std::size_t>(std::clamp(std::ceil(decades * 4), 1.0, 28.0)), '#');
}

std::string svg_report(const Histogram& h, const Cyclictest& ct, const std::vector<Second>& secs, double rate_hz,
                       const std::string& title) {
  const int W = 900, H = 640, L = 70, R = 20, top1 = 40, h1 = 240, top2 = 360, h2 = 230;
  std::ostringstream o;
  char b[320];
  o << "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"" << W << "\" height=\"" << H << "\" viewBox=\"0 0 " << W << ' '
    << H << "\" font-family=\"sans-serif\" font-size=\"11\">\n<rect width=\"100%\" height=\"100%\" fill=\"white\"/>\n";
  o << "<text x=\"" << L << "\" y=\"20\" font-size=\"13\">" << title << "</text>\n";
  // Histogram: x = latency (us, linear to the highest bin reached), y = log10 count.
  const Histogram cth = ct.ran ? rebin(ct.hist, h) : Histogram{};
  const double reach = std::min(2000.0, std::max(h.max_upper_us(), ct.ran ? cth.max_upper_us() : 0.0));
  double xmax = 2000;
  for (double nice : {50.0, 100.0, 200.0, 250.0, 500.0, 1000.0})
    if (reach <= nice) {
      xmax = nice;
      break;
    }
  long long cmax = 1;
  for (long long c : h.count) cmax = std::max(cmax, c);
  for (long long c : cth.count) cmax = std::max(cmax, c);
  const double dmax = std::ceil(std::log10(static_cast<double>(cmax)) + 0.01);
  auto X = [&](double us) { return L + std::min(us, xmax) / xmax * (W - L - R); };
  auto Y = [&](long long c) { return top1 + h1 - (c > 0 ? (std::log10(static_cast<double>(c)) + 1) / (dmax + 1) : 0) * h1; };
  o << "<rect x=\"" << L << "\" y=\"" << top1 << "\" width=\"" << W - L - R << "\" height=\"" << h1
    << "\" fill=\"none\" stroke=\"#999\"/>\n";
  for (int d = 0; d <= dmax; ++d) {
    std::snprintf(b, sizeof b, "<text x=\"%d\" y=\"%.1f\" text-anchor=\"end\">1e%d</text>\n", L - 4, Y(static_cast<long long>(std::pow(10, d))) + 4, d);
    o << b;
  }
  for (int k = 0; k <= 5; ++k) {
    const double us = xmax * k / 5;
    std::snprintf(b, sizeof b, "<text x=\"%.1f\" y=\"%d\" text-anchor=\"middle\">%.0f</text>\n", X(us), top1 + h1 + 14, us);
    o << b;
  }
  std::snprintf(b, sizeof b, "<text x=\"%d\" y=\"%d\" text-anchor=\"middle\">wake-up latency (us); count per bin (1 us to 200 us, then 50 us), log scale</text>\n",
                (W + L) / 2, top1 + h1 + 30);
  o << b;
  auto steps = [&](const Histogram& hh, const char* colour) {
    o << "<polyline fill=\"none\" stroke=\"" << colour << "\" stroke-width=\"1.2\" points=\"";
    for (std::size_t k = 0; k < hh.count.size(); ++k) {
      const double lo = hh.lo_us[k], hi = k + 1 < hh.lo_us.size() ? hh.lo_us[k + 1] : lo + 50;
      if (lo >= xmax) break;
      std::snprintf(b, sizeof b, "%.1f,%.1f %.1f,%.1f ", X(lo), Y(hh.count[k]), X(hi), Y(hh.count[k]));
      o << b;
    }
    o << "\"/>\n";
  };
  steps(h, "#1f5fbf");
  if (ct.ran) steps(cth, "#c04000");
  std::snprintf(b, sizeof b,
                "<text x=\"%d\" y=\"%d\" fill=\"#1f5fbf\">cpmd's loop (%.0f Hz): %lld wake-ups, max %.1f us</text>\n",
                W - R - 330, top1 + 14, rate_hz, h.total(), secs.empty() ? 0.0 : secs.back().max_us);
  o << b;
  if (ct.ran) {
    std::snprintf(b, sizeof b, "<text x=\"%d\" y=\"%d\" fill=\"#c04000\">cyclictest: %lld wake-ups, max %.0f us</text>\n",
                  W - R - 330, top1 + 28, ct.cycles, ct.max_us);
    o << b;
  }
  // Max over time: per second, the highest bin reached (upper edge) and the
  // worst since the loop started.
  double ymax = 10;
  for (const Second& s : secs) ymax = std::max(ymax, std::isfinite(s.window_max_us) ? s.window_max_us : 2000.0);
  for (double nice : {50.0, 100.0, 200.0, 250.0, 500.0, 1000.0, 2000.0, 2500.0})
    if (ymax * 1.1 <= nice) {
      ymax = nice;
      break;
    }
  const double tmax = secs.empty() ? 1.0 : std::max(1.0, secs.back().t);
  auto X2 = [&](double t) { return L + t / tmax * (W - L - R); };
  auto Y2 = [&](double us) { return top2 + h2 - std::min(us, ymax) / ymax * h2; };
  o << "<rect x=\"" << L << "\" y=\"" << top2 << "\" width=\"" << W - L - R << "\" height=\"" << h2
    << "\" fill=\"none\" stroke=\"#999\"/>\n";
  for (int k = 0; k <= 4; ++k) {
    std::snprintf(b, sizeof b, "<text x=\"%d\" y=\"%.1f\" text-anchor=\"end\">%.0f</text>\n", L - 4, Y2(ymax * k / 4) + 4, ymax * k / 4);
    o << b;
    std::snprintf(b, sizeof b, "<text x=\"%.1f\" y=\"%d\" text-anchor=\"middle\">%.3g</text>\n", X2(tmax * k / 4), top2 + h2 + 14, tmax * k / 4);
    o << b;
  }
  std::snprintf(b, sizeof b, "<text x=\"%d\" y=\"%d\" text-anchor=\"middle\">time (s); maximum latency (us)</text>\n",
                (W + L) / 2, top2 + h2 + 30);
  o << b;
  auto line = [&](auto get, const char* colour, const char* dash) {
    o << "<polyline fill=\"none\" stroke=\"" << colour << "\" stroke-width=\"1.2\"" << dash << " points=\"";
    for (const Second& s : secs) {
      std::snprintf(b, sizeof b, "%.1f,%.1f ", X2(s.t), Y2(get(s)));
      o << b;
    }
    o << "\"/>\n";
  };
  line([](const Second& s) { return std::isfinite(s.window_max_us) ? s.window_max_us : 2000.0; }, "#1f5fbf", "");
  // cyclictest's maximum (over its whole run: it gives no maximum per second), where it fits the scale.
  if (ct.ran && ct.max_us <= ymax) {
    std::snprintf(b, sizeof b, "<line x1=\"%d\" x2=\"%d\" y1=\"%.1f\" y2=\"%.1f\" stroke=\"#c04000\" stroke-dasharray=\"2 2\"/>\n",
                  L, W - R, Y2(ct.max_us), Y2(ct.max_us));
    o << b;
  }
  std::snprintf(b, sizeof b, "<text x=\"%d\" y=\"%d\" fill=\"#1f5fbf\">cpmd: each second's max (its highest bin's upper edge; 2000: 2 ms or more); "
                "worst since the loop started: %.1f us</text>\n",
                L + 6, top2 + 14, secs.empty() ? 0.0 : secs.back().max_us);
  o << b;
  if (ct.ran) {
    std::snprintf(b, sizeof b, "<text x=\"%d\" y=\"%d\" fill=\"#c04000\">cyclictest: its max over the whole run, %.0f us%s</text>\n",
                  L + 6, top2 + 30, ct.max_us, ct.max_us <= ymax ? " (dotted)" : " (above this scale)");
    o << b;
  }
  return o.str() + "</svg>\n";
}

int latency(const Options& o) {
  if (!(o.seconds >= 1 && o.seconds <= 86400)) throw UsageError("--seconds: 1 to 86400");
  const auto l = lcm_options(o.connection);
  const int priority = o.priority.value_or(o.connection.config ? daemon::load_config(*o.connection.config).loop.priority
                                                                : daemon::LoopConfig{}.priority);
  daemon::Client c(l);
  auto first = c.stats(3.0);
  if (!first) throw Error("no statistics from cpmd within 3 s (channel " + l.stats_channel + ")");
  const double rate = first->rate_hz;
  const int period_us = static_cast<int>(std::lround(1e6 / rate));
  const int whole = static_cast<int>(std::lround(o.seconds));
  std::printf("latency: %d s of cpmd's loop (%.0f Hz, %s) from its statistics", whole, rate,
              first->realtime ? "SCHED_FIFO" : "normal scheduling");
  Cyclictest ct;
  pid_t ct_pid = -1;
  const std::string tmp = "/tmp/cpm-latency-" + std::to_string(::getpid());
  if (o.no_cyclictest) ct.why = "not run (--no-cyclictest)";
  else ct_pid = start_cyclictest(period_us, priority, whole, tmp + ".json", tmp + ".log", ct.why);
  if (ct_pid > 0) std::printf(", cyclictest beside it (%d us, priority %d)", period_us, priority);
  std::printf("\n");
  std::fflush(stdout);

  signal(SIGINT, on_sigint);
  std::vector<Second> secs;
  loop_stats_t prev = *first, last = *first;
  for (int k = 0; k < whole && !g_interrupted.load(); ++k) {
    auto s = c.stats(3.0);
    if (!s) throw Error("cpmd's statistics stopped after " + std::to_string(k) + " s");
    const Histogram w = cpmd_window(prev, *s);
    Second x;
    x.t = k + 1;
    x.window_max_us = w.max_upper_us();
    x.max_us = s->max_ns[kLat] * 1e-3;
    x.samples = w.total();
    secs.push_back(x);
    prev = last = *s;
  }
  if (ct_pid > 0) {
    if (g_interrupted.load()) ::kill(ct_pid, SIGINT);
    ct = finish_cyclictest(ct_pid, tmp + ".json", tmp + ".log");
    std::remove((tmp + ".json").c_str());
    std::remove((tmp + ".log").c_str());
  }

  const Histogram h = cpmd_window(*first, last);
  const long long samples = last.count[kLat] - first->count[kLat], cycles = last.cycles - first->cycles;
  const double max_us = last.max_ns[kLat] * 1e-3;
  const bool max_in_window = last.max_ns[kLat] > first->max_ns[kLat];
  std::printf("\ncpmd: %lld wake-ups in %zu s (%lld cycles run, %lld slots skipped); histogram total %lld\n", samples,
              secs.size(), cycles, static_cast<long long>(last.skipped - first->skipped), h.total());
  const double run_max = h.max_upper_us();
  std::printf("cpmd: worst wake-up latency %.3f us%s; in this run %s us (its histogram's bin)\n", max_us,
              max_in_window ? " (reached in this run)" : " (since the loop started, before this run)",
              std::isinf(run_max) ? ">= 2000" : ("< " + std::to_string(static_cast<long>(run_max))).c_str());
  const Histogram cth = ct.ran ? rebin(ct.hist, h) : Histogram{};
  std::printf("cpmd: percentiles (upper edges of cpmd's bins) p50 %.0f us, p99 %.0f us, p99.9 %.0f us\n",
              percentile_us(h, 0.5), percentile_us(h, 0.99), percentile_us(h, 0.999));
  if (ct.ran) {
    std::printf("cyclictest: %lld wake-ups, min %.0f us, avg %.2f us, max %.0f us%s\n", ct.cycles, ct.min_us, ct.avg_us,
                ct.max_us, ct.overflows ? (" (" + std::to_string(ct.overflows) + " beyond 2 ms)").c_str() : "");
    std::printf("cyclictest: percentiles in the same bins p50 %.0f us, p99 %.0f us, p99.9 %.0f us\n",
                percentile_us(cth, 0.5), percentile_us(cth, 0.99), percentile_us(cth, 0.999));
  } else
    std::printf("cyclictest: %s\n", ct.why.c_str());
  std::printf("\n%-14s %12s %12s   (log bar: cpmd)\n", "latency (us)", "cpmd", ct.ran ? "cyclictest" : "");
  for (std::size_t r = 0; r + 1 < std::size(kRowEdges); ++r) {
    const double lo = kRowEdges[r], hi = kRowEdges[r + 1];
    const long long a = count_in(h, lo, hi), b = ct.ran ? count_in(ct.hist, lo, hi) : 0;
    if (a == 0 && b == 0) continue;
    char range[32];
    if (std::isinf(hi)) std::snprintf(range, sizeof range, ">= %.0f", lo);
    else std::snprintf(range, sizeof range, "%.0f - %.0f", lo, hi);
    if (ct.ran) std::printf("%-14s %12lld %12lld   %s\n", range, a, b, bar(a, h.total()).c_str());
    else std::printf("%-14s %12lld %12s   %s\n", range, a, "", bar(a, h.total()).c_str());
  }
  // Max over time: at most 30 rows, each the worst second of its block.
  const std::size_t per = std::max<std::size_t>(1, (secs.size() + 29) / 30);
  std::printf("\n%-12s %18s %22s\n", "time (s)", "max in block (us)", "worst since start (us)");
  for (std::size_t i = 0; i < secs.size(); i += per) {
    double m = 0;
    const std::size_t end = std::min(secs.size(), i + per);
    for (std::size_t k = i; k < end; ++k) m = std::max(m, secs[k].window_max_us);
    char range[32];
    std::snprintf(range, sizeof range, "%.0f - %.0f", secs[i].t - 1, secs[end - 1].t);
    std::printf("%-12s %18s %22.3f\n", range, std::isinf(m) ? ">= 2000" : ("< " + std::to_string(static_cast<long>(m))).c_str(),
                secs[end - 1].max_us);
  }

  if (!o.svg.empty()) {
    char title[200];
    std::snprintf(title, sizeof title, "cpm latency: %zu s of cpmd's wake-up latency%s", secs.size(),
                  ct.ran ? ", beside cyclictest at the same period and priority" : "");
    std::ofstream(o.svg) << svg_report(h, ct, secs, rate, title);
    std::printf("\nSVG: %s\n", o.svg.c_str());
  }
  if (!o.json.empty()) {
    nlohmann::ordered_json j;
    j["rate_hz"] = rate;
    j["seconds"] = secs.size();
    j["stats_first"] = {{"cycles", first->cycles}, {"utime", first->utime}};
    j["stats_last"] = {{"cycles", last.cycles}, {"utime", last.utime}};
    j["cpmd"] = {{"wakeups", samples},
                 {"cycles", cycles},
                 {"histogram_total", h.total()},
                 {"max_ns", last.max_ns[kLat]},
                 {"max_in_run", max_in_window},
                 {"p50_us", percentile_us(h, 0.5)},
                 {"p99_us", percentile_us(h, 0.99)},
                 {"p999_us", percentile_us(h, 0.999)},
                 {"run_max_bin_upper_us", std::isinf(run_max) ? nlohmann::ordered_json(nullptr) : nlohmann::ordered_json(run_max)},
                 {"bins_lower_us", h.lo_us},
                 {"histogram", h.count}};
    nlohmann::ordered_json over = nlohmann::ordered_json::array();
    for (const Second& s : secs) over.push_back({{"t", s.t}, {"max_bin_upper_us", std::isinf(s.window_max_us) ? nlohmann::ordered_json(nullptr) : nlohmann::ordered_json(s.window_max_us)}, {"worst_us", s.max_us}, {"wakeups", s.samples}});
    j["max_over_time"] = over;
    if (ct.ran)
      j["cyclictest"] = {{"period_us", period_us}, {"priority", priority}, {"cycles", ct.cycles}, {"histogram_total", ct.hist.total()},
                         {"min_us", ct.min_us}, {"avg_us", ct.avg_us}, {"max_us", ct.max_us},
                         {"p50_us", percentile_us(cth, 0.5)}, {"p99_us", percentile_us(cth, 0.99)},
                         {"p999_us", percentile_us(cth, 0.999)}, {"histogram_1us", ct.hist.count}};
    else
      j["cyclictest"] = {{"not_run", ct.why}};
    std::ofstream(o.json) << j.dump(1) << '\n';
  }
  return 0;
}

const Command r1{"latency", "cpmd's wake-up latency over N s: histogram and max over time, beside cyclictest (text, SVG)",
                 [](CLI::App& app) -> Run {
                   auto o = std::make_shared<Options>();
                   add_number(app, "--seconds", o->seconds, "N", "how long (whole seconds: cpmd's statistics come once a second)")
                       ->capture_default_str();
                   app.add_option("--svg", o->svg, "write the histogram and the max over time as SVG")->type_name("FILE.svg");
                   app.add_option("--json", o->json, "write the figures as JSON (the histograms' counts, the max per second)")
                       ->type_name("FILE.json");
                   app.add_flag("--no-cyclictest", o->no_cyclictest, "do not run cyclictest beside it");
                   app.add_option("--priority", o->priority, "cyclictest's SCHED_FIFO priority (0: normal scheduling)")
                       ->type_name("P")
                       ->check(CLI::Range(0, 99))
                       ->default_str("cpmd's loop.priority (--config), else 80");
                   add_connection(app, o->connection);
                   return [o] { return latency(*o); };
                 }};

}  // namespace
}  // namespace cpm::cli::client
