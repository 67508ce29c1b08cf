// SPDX-License-Identifier: Apache-2.0
// cpm scope: a live oscilloscope of cpmd's state in a browser, like
// LinuxCNC's halscope. It subscribes to the state channel as cpm watch and
// cpm record do (daemon::Client, signed state verified with --daemon-key),
// keeps the last --buffer seconds in a ring, and serves a page (the
// tools/cpm/scope/ files, compiled in) and its data over HTTP from
// cpp-httplib. cpp-httplib 0.11 (bookworm) has no WebSocket: the page polls
// JSON (docs/cli.md). The trigger is evaluated here, on every state message,
// so no sample is lost to the page's polling rate.
#include <signal.h>

#include <algorithm>
#include <array>
#include <atomic>
#include <charconv>
#include <chrono>
#include <cmath>
#include <deque>
#include <mutex>
#include <sstream>
#include <thread>
#include <vector>

#include "cmd_client_common.hpp"
#include "scope_assets.hpp"
// Last: it brings <resolv.h>, whose macro _res breaks Eigen's headers.
#include <httplib.h>

namespace cpm::cli::client {
namespace {

using cpm_msgs::state_t;

std::atomic<bool> g_stop{false};
void on_signal(int) { g_stop.store(true); }

// The signals one can plot, in the order of the CSV's columns. `scale`
// turns the SI value into the page's unit.
struct Signal {
  const char* name;
  const char* what;
  const char* unit;         // SI, as the CSV and the JSON carry it
  const char* screen_unit;  // as the page shows it
  double scale;
  double (*get)(const state_t&);
};
// One signal per axis (x, y, z) or per actuator (1, 2, 3) of a state_t array.
#define CPM_AXIS(name, field, k, what, unit, screen, scale) \
  Signal { name, what, unit, screen, scale, [](const state_t& s) { return double(s.field[k]); } }
#define CPM_AXES(prefix, suffix, field, what, unit, screen, scale)          \
  CPM_AXIS(prefix "x" suffix, field, 0, what " x", unit, screen, scale),    \
      CPM_AXIS(prefix "y" suffix, field, 1, what " y", unit, screen, scale), \
      CPM_AXIS(prefix "z" suffix, field, 2, what " z", unit, screen, scale)
#define CPM_ACTUATORS(prefix, field, what, unit, screen, scale)      \
  CPM_AXIS(prefix "1", field, 0, what " 1", unit, screen, scale),    \
      CPM_AXIS(prefix "2", field, 1, what " 2", unit, screen, scale), \
      CPM_AXIS(prefix "3", field, 2, what " 3", unit, screen, scale)
const Signal kSignals[] = {
    CPM_AXES("", "_ref", position_ref, "reference", "m", "mm", 1e3),
    CPM_AXES("", "", position, "position", "m", "mm", 1e3),
    CPM_AXES("err_", "", position_error, "tracking error", "m", "um", 1e6),
    CPM_AXES("v", "", velocity, "velocity", "m/s", "mm/s", 1e3),
    CPM_AXES("v", "_ref", velocity_ref, "velocity reference", "m/s", "mm/s", 1e3),
    CPM_ACTUATORS("f", force, "force on actuator", "N", "N", 1.0),
    CPM_ACTUATORS("d", d, "actuator displacement", "m", "mm", 1e3),
    CPM_ACTUATORS("v", d_dot, "actuator velocity", "m/s", "mm/s", 1e3),
    Signal{"err_norm", "tracking error |e|", "m", "um", 1e6, [](const state_t& s) { return s.position_error_norm; }},
    Signal{"latency_max", "worst wake-up latency so far", "s", "us", 1e6,
           [](const state_t& s) { return s.max_latency_ns * 1e-9; }},
    Signal{"cycle_max", "worst cycle time so far", "s", "us", 1e6, [](const state_t& s) { return s.max_cycle_ns * 1e-9; }},
    Signal{"skipped", "slots skipped by late cycles", "1", "1", 1.0,
           [](const state_t& s) { return static_cast<double>(s.skipped); }},
};
#undef CPM_AXES
#undef CPM_AXIS
#undef CPM_ACTUATORS
constexpr std::size_t kN = std::size(kSignals);

int signal_index(const std::string& name) {
  for (std::size_t i = 0; i < kN; ++i)
    if (name == kSignals[i].name) return static_cast<int>(i);
  return -1;
}

struct Sample {
  std::int64_t cycle = 0, segment_id = -1;
  double t = 0;
  int mode = 0;
  std::array<double, kN> v{};
};

Sample sample_of(const state_t& s) {
  Sample x;
  x.cycle = s.cycle;
  x.segment_id = s.segment_id;
  x.t = s.t;
  x.mode = s.mode;
  for (std::size_t i = 0; i < kN; ++i) x.v[i] = kSignals[i].get(s);
  return x;
}

// A trigger as a scope's: a signal crossing a level (rising or falling), or
// the start of a segment (segment_id turns to a new id); single shot: once
// fired and the window after it filled, the capture is kept until re-armed.
struct Trigger {
  enum Kind { none, level, segment } kind = none;
  int signal = -1;
  double threshold = 0;
  bool rising = true;
  double pre = 0.5, post = 2.0;  // s of the window before and after the trigger
};

Trigger parse_trigger(const std::string& kind, const std::string& signal, double level, const std::string& edge,
                      double pre, double post) {
  Trigger t;
  if (kind == "none" || kind.empty()) t.kind = Trigger::none;
  else if (kind == "segment" || kind == "segment-start") t.kind = Trigger::segment;
  else if (kind == "level") t.kind = Trigger::level;
  else throw UsageError("trigger '" + kind + "': give none, level or segment-start");
  if (t.kind == Trigger::level) {
    t.signal = signal_index(signal);
    if (t.signal < 0) throw UsageError("trigger signal '" + signal + "' is not one of the scope's signals");
    if (!std::isfinite(level)) throw UsageError("trigger level must be a finite number (SI unit of the signal)");
    if (edge != "rising" && edge != "falling") throw UsageError("trigger edge '" + edge + "': give rising or falling");
  }
  t.threshold = level;
  t.rising = edge != "falling";
  if (!(pre >= 0 && post > 0 && pre + post <= 600))
    throw UsageError("trigger window: pre >= 0 s, post > 0 s, at most 600 s in all");
  t.pre = pre, t.post = post;
  return t;
}

class Scope {
 public:
  explicit Scope(double buffer_s) : buffer_s_(buffer_s) {}

  void add(const state_t& s) {
    const Sample x = sample_of(s);
    std::lock_guard<std::mutex> lock(m_);
    ++received_;
    if (!ring_.empty() && x.cycle <= ring_.back().cycle) ring_.clear();  // cpmd restarted
    if (armed_ && !ring_.empty() && fires(ring_.back(), x)) {
      armed_ = false;
      fired_ = true;
      trigger_cycle_ = x.cycle;
      trigger_t_ = x.t;
    }
    ring_.push_back(x);
    while (ring_.size() > 1 && ring_.back().t - ring_.front().t > buffer_s_) ring_.pop_front();
    if (fired_ && !captured_ && x.t >= trigger_t_ + trigger_.post) {
      capture_.clear();
      for (const Sample& r : ring_)
        if (r.t >= trigger_t_ - trigger_.pre && r.t <= trigger_t_ + trigger_.post) capture_.push_back(r);
      captured_ = true;
    }
  }

  void arm(const Trigger& t) {
    std::lock_guard<std::mutex> lock(m_);
    trigger_ = t;
    armed_ = t.kind != Trigger::none;
    fired_ = captured_ = false;
    capture_.clear();
    ++arms_;
  }

  nlohmann::ordered_json status() const {
    std::lock_guard<std::mutex> lock(m_);
    const char* kinds[] = {"none", "level", "segment-start"};
    nlohmann::ordered_json j{{"received", received_},
                             {"buffer_s", buffer_s_},
                             {"newest_cycle", ring_.empty() ? -1 : ring_.back().cycle},
                             {"trigger",
                              {{"kind", kinds[trigger_.kind]},
                               {"signal", trigger_.signal >= 0 ? kSignals[trigger_.signal].name : ""},
                               {"level", trigger_.threshold},
                               {"edge", trigger_.rising ? "rising" : "falling"},
                               {"pre_s", trigger_.pre},
                               {"post_s", trigger_.post},
                               {"arms", arms_}}},
                             {"state", captured_ ? "captured" : fired_ ? "fired" : armed_ ? "armed" : "idle"}};
    if (fired_) j["trigger"]["cycle"] = trigger_cycle_, j["trigger"]["t"] = trigger_t_;
    if (captured_) j["capture_samples"] = capture_.size();
    return j;
  }

  // The last `window` s of the ring (live), or the capture, at most
  // `max_points` (every k-th sample), as columns for the page's plots.
  nlohmann::ordered_json columns(bool capture, double window, std::size_t max_points,
                                 const std::vector<int>& signals) const {
    std::lock_guard<std::mutex> lock(m_);
    std::vector<const Sample*> rows;
    if (capture) {
      for (const Sample& s : capture_) rows.push_back(&s);
    } else if (!ring_.empty()) {
      const double from = ring_.back().t - window;
      for (auto it = ring_.rbegin(); it != ring_.rend() && it->t >= from; ++it) rows.push_back(&*it);
      std::reverse(rows.begin(), rows.end());
    }
    const std::size_t step = std::max<std::size_t>(1, (rows.size() + max_points - 1) / std::max<std::size_t>(1, max_points));
    const double t0 = capture ? trigger_t_ : (rows.empty() ? 0.0 : rows.back()->t);
    nlohmann::ordered_json t = nlohmann::ordered_json::array(), cyc = nlohmann::ordered_json::array();
    std::vector<nlohmann::ordered_json> cols(signals.size(), nlohmann::ordered_json::array());
    for (std::size_t k = 0; k < rows.size(); k += step) {
      t.push_back(rows[k]->t - t0);
      cyc.push_back(rows[k]->cycle);
      for (std::size_t j = 0; j < signals.size(); ++j) cols[j].push_back(rows[k]->v[signals[j]]);
    }
    nlohmann::ordered_json out{{"t0", t0}, {"t", t}, {"cycle", cyc}, {"signals", nlohmann::ordered_json::object()}};
    for (std::size_t j = 0; j < signals.size(); ++j) out["signals"][kSignals[signals[j]].name] = cols[j];
    return out;
  }

  // Every sample of the capture (or, before one, of the last `window` s), every signal, SI units.
  std::string csv(bool capture, double window) const {
    std::lock_guard<std::mutex> lock(m_);
    std::string o = "# cpm scope: " + std::string(capture ? "the captured window" : "the live window") +
                    "; SI units: t s; positions, errors, displacements m; velocities m/s; forces N; times s\n";
    o += "cycle,t,mode,segment_id";
    for (const Signal& s : kSignals) o += std::string(",") + s.name;
    o += '\n';
    // Each number as the shortest text that reads back as the same double, as the data files are written.
    char b[40];
    auto num = [&](double v) {
      o += ',';
      o.append(b, std::to_chars(b, b + sizeof b, v).ptr);
    };
    auto put = [&](const Sample& r) {
      o += std::to_string(r.cycle);
      num(r.t);
      o += ',' + std::string(daemon::mode_text(static_cast<std::int8_t>(r.mode))) + ',' + std::to_string(r.segment_id);
      for (double v : r.v) num(v);
      o += '\n';
    };
    if (capture)
      for (const Sample& r : capture_) put(r);
    else if (!ring_.empty())
      for (const Sample& r : ring_)
        if (r.t >= ring_.back().t - window) put(r);
    return o;
  }

  bool has_capture() const {
    std::lock_guard<std::mutex> lock(m_);
    return captured_;
  }

 private:
  bool fires(const Sample& prev, const Sample& x) const {
    if (trigger_.kind == Trigger::segment) return x.segment_id >= 0 && x.segment_id != prev.segment_id;
    const double a = prev.v[trigger_.signal], b = x.v[trigger_.signal], l = trigger_.threshold;
    return trigger_.rising ? (a < l && b >= l) : (a > l && b <= l);
  }

  mutable std::mutex m_;
  double buffer_s_;
  std::deque<Sample> ring_;
  std::vector<Sample> capture_;
  Trigger trigger_;
  bool armed_ = false, fired_ = false, captured_ = false;
  long arms_ = 0, received_ = 0;
  std::int64_t trigger_cycle_ = -1;
  double trigger_t_ = 0;
};

// The chosen signals' plots as one SVG: one panel per signal, time from the
// trigger (or from the newest sample), in the page's units.
std::string svg_of(const nlohmann::ordered_json& cols, const std::vector<int>& signals, const std::string& title) {
  const int W = 900, ph = 160, left = 70, right = 20, top = 30, gap = 30;
  const int H = top + static_cast<int>(signals.size()) * (ph + gap) + 10;
  std::ostringstream o;
  o << "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"" << W << "\" height=\"" << H << "\" viewBox=\"0 0 " << W
    << ' ' << H << "\" font-family=\"sans-serif\" font-size=\"11\">\n<rect width=\"100%\" height=\"100%\" fill=\"white\"/>\n"
    << "<text x=\"" << left << "\" y=\"18\" font-size=\"13\">" << title << "</text>\n";
  const auto& t = cols["t"];
  if (t.empty()) return o.str() + "</svg>\n";
  const double t0 = t.front().get<double>(), t1 = std::max(t.back().get<double>(), t0 + 1e-9);
  for (std::size_t j = 0; j < signals.size(); ++j) {
    const Signal& s = kSignals[signals[j]];
    const auto& v = cols["signals"][s.name];
    double lo = INFINITY, hi = -INFINITY;
    for (const auto& x : v) lo = std::min(lo, x.get<double>() * s.scale), hi = std::max(hi, x.get<double>() * s.scale);
    if (hi - lo < 1e-12) lo -= 0.5, hi += 0.5;
    const int y0 = top + static_cast<int>(j) * (ph + gap);
    auto X = [&](double tt) { return left + (tt - t0) / (t1 - t0) * (W - left - right); };
    auto Y = [&](double yy) { return y0 + ph - (yy - lo) / (hi - lo) * ph; };
    o << "<rect x=\"" << left << "\" y=\"" << y0 << "\" width=\"" << W - left - right << "\" height=\"" << ph
      << "\" fill=\"none\" stroke=\"#999\"/>\n";
    o << "<text x=\"" << left + 4 << "\" y=\"" << y0 + 12 << "\">" << s.name << " (" << s.what << ", " << s.screen_unit
      << ")</text>\n";
    char b[64];
    for (int k = 0; k <= 2; ++k) {
      const double yy = lo + (hi - lo) * k / 2.0;
      std::snprintf(b, sizeof b, "%.4g", yy);
      o << "<text x=\"" << left - 4 << "\" y=\"" << Y(yy) + 4 << "\" text-anchor=\"end\">" << b << "</text>\n";
    }
    for (int k = 0; k <= 4; ++k) {
      const double tt = t0 + (t1 - t0) * k / 4.0;
      std::snprintf(b, sizeof b, "%.3g s", tt);
      o << "<text x=\"" << X(tt) << "\" y=\"" << y0 + ph + 13 << "\" text-anchor=\"middle\">" << b << "</text>\n";
    }
    o << "<polyline fill=\"none\" stroke=\"#1f5fbf\" stroke-width=\"1\" points=\"";
    for (std::size_t k = 0; k < v.size(); ++k) {
      std::snprintf(b, sizeof b, "%.1f,%.1f ", X(t[k].get<double>()), Y(v[k].get<double>() * s.scale));
      o << b;
    }
    o << "\"/>\n";
  }
  return o.str() + "</svg>\n";
}

struct Options {
  int port = 8088;
  std::string bind = "127.0.0.1";
  double buffer = 30, duration = -1;
  std::string trigger = "none", trigger_signal = "x", edge = "rising";
  double level = 0, pre = 0.5, post = 2.0;
  Connection connection;
};

std::vector<int> signals_of(const httplib::Request& req, std::vector<int> fallback) {
  if (!req.has_param("signals")) return fallback;
  std::vector<int> out;
  std::istringstream is(req.get_param_value("signals"));
  for (std::string name; std::getline(is, name, ',');)
    if (const int i = signal_index(name); i >= 0) out.push_back(i);
  return out;
}

double number_param(const httplib::Request& req, const char* name, double fallback) {
  if (!req.has_param(name)) return fallback;
  try {
    return std::stod(req.get_param_value(name));
  } catch (const std::exception&) {
    throw UsageError(std::string("parameter ") + name + ": '" + req.get_param_value(name) + "' is not a number");
  }
}

int scope(const Options& o) {
  const auto l = lcm_options(o.connection);
  if (!(o.buffer > 0 && o.buffer <= 600)) throw UsageError("--buffer: 0 < S <= 600 s");
  const Trigger first = parse_trigger(o.trigger, o.trigger_signal, o.level, o.edge, o.pre, o.post);
  if (first.pre + first.post > o.buffer) throw UsageError("the trigger's window (--pre + --post) exceeds --buffer");
  daemon::Client c(l);
  Scope sc(o.buffer);
  sc.arm(first);
  c.on_state([&](const state_t& s) { sc.add(s); });

  httplib::Server http;
  // A bad query (a parameter that is not a number) is the caller's: 400 with the reason.
  http.set_exception_handler([](const httplib::Request&, httplib::Response& res, std::exception_ptr ep) {
    try {
      std::rethrow_exception(ep);
    } catch (const UsageError& e) {
      res.status = 400;
      res.set_content(std::string(e.what()) + "\n", "text/plain");
    } catch (const std::exception& e) {
      res.status = 500;
      res.set_content(std::string(e.what()) + "\n", "text/plain");
    }
  });
  auto json = [](httplib::Response& res, const nlohmann::ordered_json& j) {
    res.set_content(j.dump(), "application/json");
  };
  for (const ScopeAsset& a : scope_assets()) {
    const std::string path = a.name == std::string("index.html") ? "/" : "/" + std::string(a.name);
    http.Get(path, [a](const httplib::Request&, httplib::Response& res) {
      res.set_content(reinterpret_cast<const char*>(a.data), a.size, a.type);
    });
  }
  http.Get("/api/signals", [&](const httplib::Request&, httplib::Response& res) {
    nlohmann::ordered_json j = nlohmann::ordered_json::array();
    for (const Signal& s : kSignals)
      j.push_back({{"name", s.name}, {"what", s.what}, {"unit", s.unit}, {"screen_unit", s.screen_unit}, {"scale", s.scale}});
    json(res, j);
  });
  http.Get("/api/status", [&](const httplib::Request&, httplib::Response& res) { json(res, sc.status()); });
  const std::vector<int> all = [] {
    std::vector<int> v;
    for (std::size_t i = 0; i < kN; ++i) v.push_back(static_cast<int>(i));
    return v;
  }();
  http.Get("/api/data", [&](const httplib::Request& req, httplib::Response& res) {
    const bool capture = req.get_param_value("source") == "capture";
    const double window = number_param(req, "window", 5.0);
    const auto points = static_cast<std::size_t>(std::clamp(number_param(req, "points", 2000), 10.0, 100000.0));
    json(res, sc.columns(capture, window, points, signals_of(req, all)));
  });
  http.Get("/api/arm", [&](const httplib::Request& req, httplib::Response& res) {
    try {
      const Trigger t = parse_trigger(req.get_param_value("kind"), req.get_param_value("signal"),
                                      number_param(req, "level", 0), req.has_param("edge") ? req.get_param_value("edge") : "rising",
                                      number_param(req, "pre", o.pre), number_param(req, "post", o.post));
      if (t.pre + t.post > o.buffer) throw UsageError("the window (pre + post) exceeds the buffer of " + std::to_string(o.buffer) + " s");
      sc.arm(t);
      json(res, sc.status());
    } catch (const std::exception& e) {
      res.status = 400;
      json(res, {{"error", e.what()}});
    }
  });
  // The capture (or the live window: ?source=live&window=S) as CSV and SVG.
  auto want_capture = [&](const httplib::Request& req) { return req.get_param_value("source") != "live"; };
  http.Get("/export.csv", [&](const httplib::Request& req, httplib::Response& res) {
    const bool capture = want_capture(req);
    if (capture && !sc.has_capture()) {
      res.status = 404;
      res.set_content("no capture yet: the trigger has not fired (or its window has not filled)\n", "text/plain");
      return;
    }
    res.set_header("Content-Disposition", capture ? "attachment; filename=\"scope-capture.csv\""
                                                  : "attachment; filename=\"scope-live.csv\"");
    res.set_content(sc.csv(capture, number_param(req, "window", 5.0)), "text/csv");
  });
  http.Get("/export.svg", [&](const httplib::Request& req, httplib::Response& res) {
    const bool capture = want_capture(req);
    if (capture && !sc.has_capture()) {
      res.status = 404;
      res.set_content("no capture yet\n", "text/plain");
      return;
    }
    const std::vector<int> sig = signals_of(req, {signal_index("x_ref"), signal_index("x"), signal_index("err_x")});
    const auto st = sc.status();
    const std::string title = capture ? "cpm scope: capture, trigger " + st["trigger"]["kind"].get<std::string>() +
                                            " at cycle " + std::to_string(st["trigger"].value("cycle", -1L)) +
                                            " (t = 0 s)"
                                      : "cpm scope: live window (t = 0 s: the newest sample)";
    res.set_header("Content-Disposition", "attachment; filename=\"scope.svg\"");
    res.set_content(svg_of(sc.columns(capture, number_param(req, "window", 5.0), 4000, sig), sig, title), "image/svg+xml");
  });

  if (!http.bind_to_port(o.bind.c_str(), o.port))
    throw Error("cannot listen on " + o.bind + ":" + std::to_string(o.port) + " (in use, or not an address of this machine)");
  std::thread server([&] { http.listen_after_bind(); });
  std::printf("scope: http://%s:%d/ (cpmd's state on %s%s); Ctrl-C stops\n", o.bind.c_str(), o.port,
              l.state_channel.c_str(), c.verifying() ? ", verified" : ", NOT VERIFIED: no --daemon-key");
  std::fflush(stdout);
  signal(SIGINT, on_signal);
  signal(SIGTERM, on_signal);
  const auto start = std::chrono::steady_clock::now();
  while (!g_stop.load()) {
    if (o.duration >= 0 && std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count() >= o.duration) break;
    c.handle(0.05);
  }
  http.stop();
  server.join();
  return 0;
}

const Command r1{"scope", "a live scope of cpmd's state in a browser: plots per signal, trigger, freeze, CSV/SVG export",
                 [](CLI::App& app) -> Run {
                   auto o = std::make_shared<Options>();
                   app.add_option("--http", o->port, "serve the page on this TCP port")
                       ->type_name("PORT")
                       ->check(CLI::Range(1, 65535))
                       ->capture_default_str();
                   app.add_option("--bind", o->bind, "the address to listen on (0.0.0.0: every interface; the page "
                                                     "has no login, so keep it on loopback or a trusted network)")
                       ->type_name("ADDR")
                       ->capture_default_str();
                   add_number(app, "--buffer", o->buffer, "S", "seconds of state kept (the ring)")->capture_default_str();
                   add_choice(app, "--trigger", o->trigger, {"none", "level", "segment-start"},
                              "arm at start: a signal crossing --level, or the start of a segment (the page can re-arm)");
                   app.add_option("--signal", o->trigger_signal, "the level trigger's signal (names: the page, or docs/cli.md)")
                       ->type_name("NAME")
                       ->capture_default_str();
                   add_number(app, "--level", o->level, "V", "the level trigger's level, in the signal's SI unit");
                   add_choice(app, "--edge", o->edge, {"rising", "falling"}, "the level trigger's edge");
                   add_number(app, "--pre", o->pre, "S", "seconds kept before the trigger")->capture_default_str();
                   add_number(app, "--post", o->post, "S", "seconds kept after the trigger")->capture_default_str();
                   add_number(app, "--duration", o->duration, "S", "stop after S seconds")->default_str("until Ctrl-C");
                   add_connection(app, o->connection);
                   return [o] { return scope(*o); };
                 }};

}  // namespace
}  // namespace cpm::cli::client
