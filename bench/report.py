#!/usr/bin/python3
# SPDX-License-Identifier: Apache-2.0
"""The table and JSON of bench/run.sh, from the raw outputs of one run.

    report.py --dir RAW --json OUT --quick 0|1 --seconds S --segments K --priority P --interval-us I
              --realtime-allowed 0|1 --allocation-test passed|failed
    report.py --markdown OUT.json      the table of a finished run in Markdown (docs/performance.md)

RAW holds perf.json (cpm_perf), scipy.json (scipy_ballbar.py), gbench.json
(cpm_bench), and for each of the K latency turns: cpmd_stats_<k>.json (cpmd
--stats-json) with cyclictest_<k>.json, run at the same time on two CPUs
(cpus_<k>.txt says which), cyclictest_idle_<k>.json, run alone, and
control_a_<k>.json with control_b_<k>.json, two cyclictests at once; the turns
of each are merged into one histogram.
Standard library only. Units: ns and µs for times of the cycle, s for tools,
bit and Hz for the bus; shares are of the loop period.
"""
import argparse
import datetime
import json
import math
import os
import platform
import subprocess

# The daemon's histogram (daemon/src/loop.cpp, msgs/lcm/loop_stats_t.lcm):
# 1 µs bins below 200 µs, 50 µs bins to 2 ms, one bin for everything above.
FINE_LIMIT_US, COARSE_WIDTH_US, TOP_US = 200, 50, 2000
# The wake-up latency of both programs is compared in 1 µs bins to 2 ms:
# cyclictest -h 2000 and cpmd's histogram_1us.


def bin_ceiling_us(floor, max_us, fine_limit_us=FINE_LIMIT_US):
    if floor < fine_limit_us:
        return floor + 1
    if floor < TOP_US:
        return floor + COARSE_WIDTH_US
    return max_us


def percentiles(hist, max_us, late=0, period_us=None, qs=(0.5, 0.99, 0.999), fine_limit_us=FINE_LIMIT_US):
    """Nearest-rank percentiles over the slots of a run: `hist` {bin floor µs: count},
    1 µs bins below `fine_limit_us` (the daemon's bins above), plus `late` slots known
    only to be late by a period or more (the slots skipped after a stall). Each is
    (value, bound): the upper edge of its bin with '<=' (never above the measured
    maximum), or, among the slots late by a period or more, whose order the histogram
    cannot give, the period with '>='."""
    total = sum(hist.values()) + late
    out = {}
    for q in qs:
        rank = max(1, math.ceil(q * total))
        seen = 0
        out[q] = (period_us, ">=")
        for floor in sorted(hist):
            if period_us is not None and floor >= period_us:
                break
            seen += hist[floor]
            if seen >= rank:
                out[q] = (min(bin_ceiling_us(floor, max_us, fine_limit_us), max_us), "<=")
                break
    return out


def latency_figures(hist, late, period_us, max_us, min_us, mean_us, cycles):
    """`hist`: {µs: count} in 1 µs bins to 2 ms, everything above in the bin at 2 ms."""
    p = percentiles(hist, max_us, late, period_us, fine_limit_us=TOP_US)
    late_slots = late + sum(n for floor, n in hist.items() if floor >= period_us)
    return {"cycles": cycles, "min_us": min_us, "mean_us": mean_us, "p50_us": p[0.5][0], "p99_us": p[0.99][0],
            "p999_us": p[0.999][0], "max_us": max_us,
            "bounds": {"p50": p[0.5][1], "p99": p[0.99][1], "p999": p[0.999][1]},
            # Slots in which the loop did not run on time: woke a whole period late, or skipped.
            "late_slots": late_slots,
            # A period is the difference of two wake-ups: its error is bounded by the spread of the latency.
            "period_jitter_bound_us": max_us - min_us}


def merge_series(series):
    """One of cpmd's timing series over several runs: counts and histograms add."""
    ran = [s for s in series if s["count"]]
    count = sum(s["count"] for s in ran)
    out = {"count": count, "min_ns": min((s["min_ns"] for s in ran), default=0),
           "max_ns": max((s["max_ns"] for s in ran), default=0),
           "mean_ns": sum(s["mean_ns"] * s["count"] for s in ran) / count if count else 0.0}
    for name in ("histogram_us", "histogram_1us"):
        if not all(name in s for s in series):
            continue
        hist = {}
        for s in ran:
            for k, n in s[name].items():
                hist[k] = hist.get(k, 0) + n
        out[name] = hist
    return out


def merge_cpmd_stats(docs):
    """cpmd's --stats-json of several runs as if of one."""
    out = dict(docs[0])
    for k in ("cycles", "overruns", "skipped"):
        out[k] = sum(d[k] for d in docs)
    for k in ("realtime", "memory_locked"):
        out[k] = all(d[k] for d in docs)
    out["series"] = {name: merge_series([d["series"][name] for d in docs]) for name in docs[0]["series"]}
    return out


def cpmd_latency(stats, period_us):
    s = stats["series"]["wakeup_latency"]
    if "histogram_1us" not in s:
        raise SystemExit("report.py: cpmd's --stats-json has no histogram_1us (a cpmd older than this report)")
    hist = {}
    for k, n in s["histogram_1us"].items():
        hist[int(k)] = hist.get(int(k), 0) + n
    f = latency_figures(hist, stats["skipped"], period_us, s["max_ns"] / 1000.0, s["min_ns"] / 1000.0,
                        s["mean_ns"] / 1000.0, s["count"])
    f.update({"realtime": stats["realtime"], "memory_locked": stats["memory_locked"], "overruns": stats["overruns"],
              "skipped": stats["skipped"]})
    phases = {}
    for name, series in stats["series"].items():
        if name == "wakeup_latency" or not series["count"]:
            continue
        h = {int(k): n for k, n in series["histogram_us"].items()}
        phases[name] = {"mean_ns": series["mean_ns"], "p99_us": percentiles(h, series["max_ns"] / 1000.0)[0.99][0],
                        "max_us": series["max_ns"] / 1000.0}
    f["phases"] = phases
    return f


def cyclictest_seconds(doc, default):
    """The -D of a cyclictest run, from the command line its JSON records."""
    words = doc.get("cmdline:", "").split()
    if "-D" in words[:-1]:
        try:
            return float(words[words.index("-D") + 1])
        except ValueError:
            pass
    return default


def cyclictest_latency(docs, realtime, period_us, seconds_each):
    """cyclictest's 1 µs histograms (-h 2000) of several runs, each `seconds_each`
    long unless its command line says otherwise. After a stall cyclictest, like
    cpmd, takes one sample (the whole lateness) and moves on to the first slot
    still ahead: the slots it skipped are the run's slots it has no sample for
    (seconds / period - cycles; its start-up may shift this by a slot or two per run)."""
    hist = {}
    cycles = skipped = 0
    mins, maxs, weighted_mean = [], [], 0.0
    for doc in docs:
        t = doc["thread"]["0"]
        n_cycles = int(t["cycles"])
        counted = 0
        for k, n in t["histogram"].items():
            b = min(int(k), TOP_US)
            hist[b] = hist.get(b, 0) + n
            counted += n
        overflow = n_cycles - counted          # above the -h range (2 ms)
        if overflow > 0:
            hist[TOP_US] = hist.get(TOP_US, 0) + overflow
        skipped += max(0, round(cyclictest_seconds(doc, seconds_each) * 1e6 / period_us) - n_cycles)
        cycles += n_cycles
        mins.append(float(t["min"]))
        maxs.append(float(t["max"]))
        weighted_mean += float(t["avg"]) * n_cycles
    f = latency_figures(hist, skipped, period_us, max(maxs), min(mins), weighted_mean / max(cycles, 1), cycles)
    f.update({"realtime": realtime, "memory_locked": True, "skipped": skipped,
              "version": docs[0].get("rt_test_version:", ""), "cpus": sorted({int(d["thread"]["0"].get("cpu", -1)) for d in docs})})
    return f


def tsc_mhz():
    """The TSC's rate as the kernel states it (constant_tsc): LinuxCNC's
    function .time figures are rdtsc ticks."""
    with open("/proc/cpuinfo") as f:
        for line in f:
            if line.startswith("cpu MHz"):
                return float(line.split(":", 1)[1])
    return None


def linuxcnc_run(path, period_us):
    """One LinuxCNC turn from halsampler -t (bench/linuxcnc/cpm-ldelta.hal):
    tag, timedelta.0.out (ns since the servo thread's previous run),
    motion-command-handler.time, motion-controller.time, servo-thread.time
    (TSC ticks; the thread's is of the period before). timedelta gives
    periods, not wake-ups: the lateness of wake-up k against the thread's own
    schedule is the sum of (period - T) up to k, plus that of the first
    (unknown). rtapi_app never skips a slot (a late thread runs at once and
    catches up), so taking the run's earliest wake-up as on time gives every
    wake-up's lateness less that smallest one: a lower bound, short by the
    thread's minimum latency (cyclictest's minimum, a few us, in the same run)."""
    periods, cost, thread, lost = [], [], [], 0
    last_tag = None
    with open(path) as f:
        for line in f:
            w = line.split()
            if not w or w[0] == "overrun":
                lost += 1 if w else 0
                continue
            tag, out, cmd, ctl, thr = (int(x) for x in w[:5])
            if last_tag is not None and tag != last_tag + 1:
                lost += tag - last_tag - 1
            last_tag = tag
            if out > 0:
                periods.append(out / 1000.0)
            cost.append(cmd + ctl)
            if thr > 0:
                thread.append(thr)
    lateness, acc = [], 0.0
    for p in periods:
        acc += p - period_us
        lateness.append(acc)
    low = min(lateness + [0.0])
    return {"periods_us": periods, "lateness_us": [0.0 - low] + [x - low for x in lateness],
            "cost_ticks": cost, "thread_ticks": thread, "lost": lost}


def linuxcnc_figures(runs, period_us, mhz):
    hist = {}
    lateness = [x for r in runs for x in r["lateness_us"]]
    for x in lateness:
        b = min(int(x), TOP_US)
        hist[b] = hist.get(b, 0) + 1
    f = latency_figures(hist, 0, period_us, max(lateness), min(lateness), sum(lateness) / len(lateness), len(lateness))
    periods = sorted(x for r in runs for x in r["periods_us"])

    def pct(v, q):
        return v[min(len(v) - 1, max(0, math.ceil(q * len(v)) - 1))]

    cost = sorted(x * 1000.0 / mhz for r in runs for x in r["cost_ticks"])
    thread = sorted(x * 1000.0 / mhz for r in runs for x in r["thread_ticks"])
    f.update({"realtime": True, "lost_samples": sum(r["lost"] for r in runs),
              "period_min_us": periods[0], "period_max_us": periods[-1],
              "period_mean_us": sum(periods) / len(periods),
              # LinuxCNC's latency-test figure: the largest |period - T|.
              "timedelta_jitter_us": max(periods[-1] - period_us, period_us - periods[0]),
              "tsc_mhz": mhz,
              "motion_ns": {"median": pct(cost, 0.5), "p99": pct(cost, 0.99), "max": cost[-1], "mean": sum(cost) / len(cost)},
              "thread_ns": {"median": pct(thread, 0.5), "p99": pct(thread, 0.99), "max": thread[-1]} if thread else None})
    return f


def latency_ratio(a, b):
    """a / b for p50, p99, p99.9 and max, each with what kind of figure it is:
    '~' (two bin edges of the same bins), '=' (maxima), '>=' or '<=' where one
    side is only a bound; None where both are '>= one period'."""
    value, bound = {}, {}
    for k in ("p50", "p99", "p999", "max"):
        ba, bb = a["bounds"].get(k, "="), b["bounds"].get(k, "=")
        if not b[k + "_us"] or (ba == ">=" and bb == ">="):
            value[k], bound[k] = None, None
            continue
        value[k] = a[k + "_us"] / b[k + "_us"]
        bound[k] = ">=" if ba == ">=" else "<=" if bb == ">=" else "=" if k == "max" else "~"
    return value, bound


def per_turn(first, second):
    """Turn by turn, the p99 of two programs run at the same time (lists of latency
    figures, one per turn): in how many turns the first's was above the second's,
    and the geometric mean of the per-turn ratios. A bursty background moves the
    p99 of a whole run; the turns say whether one program is worse in most of them.
    A p99 known only as '>= a period' counts as the period."""
    ratios = [a["p99_us"] / b["p99_us"] for a, b in zip(first, second) if a["p99_us"] and b["p99_us"]]
    if not ratios:
        return {"turns": 0, "above": 0, "geomean": None}
    return {"turns": len(ratios), "above": sum(q > 1 for q in ratios),
            "geomean": math.exp(sum(math.log(q) for q in ratios) / len(ratios))}


def seconds_of(bash_time):
    """'1m2.500s' (bash's `times`) in seconds."""
    m, rest = bash_time.split("m")
    return 60 * float(m) + float(rest.rstrip("s"))


def machine_use(path):
    """Per step of the run: the share of all cores busy (every process) and the
    share this run's own processes took; the difference is the background."""
    marks = []
    with open(path) as f:
        for line in f:
            name, stat, times = line.rstrip("\n").split("|")
            v = [int(x) for x in stat.split()[1:]]
            user, system = (seconds_of(x) for x in times.split())
            marks.append((name, sum(v), v[3] + v[4], user + system))   # total, idle + iowait (jiffies), own (s)
    hz = os.sysconf("SC_CLK_TCK")
    out = {}
    for (_, t0, i0, o0), (name, t1, i1, o1) in zip(marks, marks[1:]):
        capacity_s = (t1 - t0) / hz                  # CPU seconds of all cores in the step
        busy = ((t1 - t0) - (i1 - i0)) / hz
        out[name] = {"busy": busy / capacity_s, "own": (o1 - o0) / capacity_s,
                     "other": max(0.0, (busy - (o1 - o0)) / capacity_s)}
    return out


def gbench(doc, prefix):
    for b in doc["benchmarks"]:
        if b["name"].startswith(prefix) and b.get("run_type", "iteration") == "iteration":
            scale = {"ns": 1e-9, "us": 1e-6, "ms": 1e-3, "s": 1.0}[b["time_unit"]]
            return {"name": b["name"], "seconds": b["real_time"] * scale, "iterations": b["iterations"],
                    "samples": int(b.get("samples", 0))}
    raise SystemExit(f"report.py: no benchmark {prefix} in the Google Benchmark output")


def machine(realtime_allowed):
    model = "unknown"
    flags = ""
    with open("/proc/cpuinfo") as f:
        for line in f:
            if line.startswith("model name") and model == "unknown":
                model = line.split(":", 1)[1].strip()
            if line.startswith("flags") and not flags:
                flags = line
    virt = ""
    try:
        virt = subprocess.run(["systemd-detect-virt"], capture_output=True, text=True).stdout.strip()
    except OSError:
        pass
    if not virt:
        virt = "hypervisor flag set" if " hypervisor" in flags else "none detected"
    u = platform.uname()
    return {"cpu_model": model, "cores": os.cpu_count(), "kernel": u.release, "kernel_build": u.version,
            "preempt_rt": "PREEMPT_RT" in u.version, "virtualization": virt,
            "realtime_allowed": bool(realtime_allowed),
            "date": datetime.date.today().isoformat()}


def spread_of(ratio, bound):
    """How far from 1 a p99 ratio of two identical programs came (>= 1): the
    noise of this measurement on this machine; None (unbounded) where the ratio
    has no value or only a bound."""
    if ratio is None or bound in (">=", "<=") or ratio <= 0:
        return None
    return max(ratio, 1 / ratio)


def wakeup_verdict(lat, limit=1.2):
    """PASS when cpmd's p99 is within `limit` of cyclictest's; FAIL when it is
    beyond the limit and beyond the spread of two identical cyclictests in the
    same run (the control); otherwise UNDECIDED: the run cannot tell it from noise."""
    return ratio_verdict(lat["ratio"]["p99"], lat["ratio_bound"]["p99"], lat["control"]["spread"], limit)


def ratio_verdict(q, qb, spread, limit=1.2):
    """The budget's rule for any p99 ratio q (bound qb) of two programs run at once,
    against the control's spread."""
    spread = math.inf if spread is None else spread
    if q is not None and qb in ("~", "<=") and q <= limit:
        return "PASS"
    if q is not None and qb in ("~", ">=") and q > max(limit, spread):
        return "FAIL"
    return "UNDECIDED"


def verdict_of(b):
    """A budget's verdict; JSONs from before the three-valued verdict have only `pass`."""
    return b.get("verdict", "PASS" if b["pass"] else "FAIL")


def budgets(r):
    cc, lat, rtf = r["control_cycle"], r["latency"], r["rtf"]
    wake = wakeup_verdict(lat)
    b = [
        {"id": "control_cycle_median", "text": "control cycle compute, median", "measured": cc["median_ns"],
         "limit": 2000, "unit": "ns", "rule": "<", "pass": cc["median_ns"] < 2000},
        {"id": "allocations_per_cycle", "text": "heap allocations per cycle", "measured": cc["allocations"],
         "limit": 0, "unit": "", "rule": "=",
         "pass": cc["allocations"] == 0 and r["allocation_test"] == "passed"},
        {"id": "wakeup_p99_ratio", "text": "cpmd wake-up latency p99 / cyclictest p99",
         "measured": lat["ratio"]["p99"], "limit": 1.2, "unit": "x", "rule": "<=",
         "pass": wake == "PASS", "verdict": wake},
        {"id": "plant_rtf", "text": "simulator real-time factor, plant alone (as shipped)",
         "measured": rtf["plant_shipped"], "limit": 100, "unit": "x", "rule": ">", "pass": rtf["plant_shipped"] > 100},
    ]
    return b


def build(a):
    d = a.dir
    load = lambda name: json.load(open(os.path.join(d, name)))  # noqa: E731
    perf, sp, gb = load("perf.json"), load("scipy.json"), load("gbench.json")
    segments = range(1, a.segments + 1)

    def ct_of(docs):   # cyclictest's figures over these runs (turns)
        return cyclictest_latency(docs, bool(a.realtime_allowed), a.interval_us, a.seconds / a.segments)

    def each_turn(docs):
        return [ct_of([x]) for x in docs]

    cpmd_docs = [load(f"cpmd_stats_{k}.json") for k in segments]
    ct_docs = [load(f"cyclictest_{k}.json") for k in segments]
    cpmd = cpmd_latency(merge_cpmd_stats(cpmd_docs), a.interval_us)
    ct = ct_of(ct_docs)
    turns = per_turn([cpmd_latency(x, a.interval_us) for x in cpmd_docs], each_turn(ct_docs))
    idle = ct_of([load(f"cyclictest_idle_{k}.json") for k in segments])
    pinning = []
    for k in segments:
        path = os.path.join(d, f"cpus_{k}.txt")
        if os.path.exists(path):
            pinning.append(dict(x.split("=", 1) for x in open(path).read().split()))
    cpmd["cpus"] = sorted({p["cpmd_cpu"] for p in pinning})
    ratio, ratio_bound = latency_ratio(cpmd, ct)
    ratio_idle, ratio_idle_bound = latency_ratio(cpmd, idle)
    load_effect, load_effect_bound = latency_ratio(ct, idle)
    a_docs = [load(f"control_a_{k}.json") for k in segments]
    b_docs = [load(f"control_b_{k}.json") for k in segments]
    ctl_a, ctl_b = ct_of(a_docs), ct_of(b_docs)
    ctl_ratio, ctl_bound = latency_ratio(ctl_a, ctl_b)
    control = {"a": ctl_a, "b": ctl_b, "ratio": ctl_ratio, "ratio_bound": ctl_bound,
               "spread": spread_of(ctl_ratio["p99"], ctl_bound["p99"]),
               "per_turn": per_turn(each_turn(a_docs), each_turn(b_docs))}
    linuxcnc = None
    lc_paths = [os.path.join(d, f"linuxcnc_{k}.txt") for k in segments]
    if all(os.path.exists(x) for x in lc_paths):
        lc_runs = [linuxcnc_run(x, a.interval_us) for x in lc_paths]
        if all(r["periods_us"] for r in lc_runs):
            linuxcnc = linuxcnc_figures(lc_runs, a.interval_us, tsc_mhz())
            linuxcnc["cpus"] = sorted({p.get("linuxcnc_cpu") for p in pinning if p.get("linuxcnc_cpu")})
            ratio_lc, ratio_lc_bound = latency_ratio(cpmd, linuxcnc)
            lc_ct, lc_ct_bound = latency_ratio(linuxcnc, ct)
            linuxcnc.update({"ratio_cpmd_to_linuxcnc": ratio_lc, "ratio_cpmd_to_linuxcnc_bound": ratio_lc_bound,
                             "ratio_to_cyclictest": lc_ct, "ratio_to_cyclictest_bound": lc_ct_bound,
                             "per_turn_cpmd_vs_linuxcnc": per_turn(
                                 [cpmd_latency(x, a.interval_us) for x in cpmd_docs],
                                 [linuxcnc_figures([r], a.interval_us, tsc_mhz()) for r in lc_runs])})
    elif os.path.exists(os.path.join(d, "linuxcnc_skipped.txt")):
        linuxcnc = {"skipped": open(os.path.join(d, "linuxcnc_skipped.txt")).read().strip()}
    kim = perf["kim"]
    lm, trf = sp["methods"]["lm"], sp["methods"]["trf"]
    cpp_solve_s = kim["solve"]["median_ns"] * 1e-9
    r = {
        "schema": 1,
        "quick": bool(a.quick),
        "machine": machine(a.realtime_allowed),
        "driver": perf["driver"],
        "control_cycle": perf["control_cycle"],
        "controller_step": perf["controller_step"],
        "plant_step": perf["plant_step"],
        "rtf": perf["rtf"],
        "allocation_test": a.allocation_test,
        "machine_use": machine_use(os.path.join(d, "cpu_marks.txt")),
        "latency": {
            "seconds": a.seconds, "priority": a.priority, "interval_us": a.interval_us,
            "segments": a.segments,
            "order": f"{a.segments} turns of {a.seconds / a.segments:g} s, each three runs in ABBA order: cpmd and "
                     "cyclictest at once, each pinned to its own CPU, swapped every turn (cyclictest from 0.5 s before "
                     "cpmd starts to about 0.4 s after it ends); cyclictest alone (idle); two cyclictests at once "
                     "(control, swapped likewise); same priority, period and memory locking",
            "pinning": pinning,
            "histogram": "1 us bins to 2 ms, one bin above; percentiles over slots, as bin upper edges (<=), "
                         "or >= one period among the slots a period or more late",
            "cpmd": cpmd, "cyclictest": ct, "ratio": ratio, "ratio_bound": ratio_bound,
            "cyclictest_idle": idle, "ratio_idle": ratio_idle, "ratio_idle_bound": ratio_idle_bound,
            "load_effect": load_effect, "load_effect_bound": load_effect_bound,
            "per_turn": turns, "control": control, "linuxcnc": linuxcnc},
        "bus": perf["bus"],
        "calibration": {
            "problem": "Kim's 32-point ball-bar, 9 unknowns, analytic Jacobian, the same tolerances",
            "poses": kim["poses"], "repeat": kim["repeat"],
            "cpp_solve_s": cpp_solve_s, "cpp_solve_iterations": kim["solve"]["iterations"],
            "cpp_fit_s": kim["fit"]["median_ns"] * 1e-9,
            "scipy_lm_s": lm["median_s"], "scipy_lm_nfev": lm["nfev"],
            "scipy_trf_s": trf["median_s"], "scipy_trf_nfev": trf["nfev"],
            "ratio_scipy_lm_to_cpp": lm["median_s"] / cpp_solve_s,
            "ratio_scipy_trf_to_cpp": trf["median_s"] / cpp_solve_s,
            "solution_max_diff_sigma": max(lm["max_abs_diff_sigma"], trf["max_abs_diff_sigma"]),
            "cost_cpp_m2": kim["solve"]["cost"], "cost_scipy_lm_m2": lm["cost"],
            "residual_check_max_m": sp["residual_check_max_m"],
            "scipy_import_s": sp["import_s"], "scipy_version": sp["scipy_version"]},
        "diagnose": {
            "motion_1khz": gbench(gb, "BM_DiagnoseMotion1kHz"),
            "ballbar_32_file": gbench(gb, "BM_DiagnoseBallbar32File"),
            "ballbar_192": gbench(gb, "BM_DiagnoseBallbar192")},
    }
    r["budgets"] = budgets(r)
    for b in r["budgets"]:
        b["verdict"] = verdict_of(b)
    return r


def table(r):
    rows = []

    def row(group, what, value, ref="", verdict=""):
        rows.append((group, what, value, ref, verdict))

    ok = verdict_of

    B = {b["id"]: b for b in r["budgets"]}
    cc, cs, ps = r["control_cycle"], r["controller_step"], r["plant_step"]
    per = cc["period_s"] * 1e3
    row("control cycle", "compute median (cpmd's cycle, I/O replayed)",
        f"{cc['median_ns']} ns = {100 * cc['median_share']:.3f} % of {per:g} ms", "< 2000 ns",
        ok(B["control_cycle_median"]))
    row("control cycle", "compute p99 / p99.9 / max",
        f"{cc['p99_ns']} / {cc['p999_ns']} / {cc['max_ns']} ns ({100 * cc['p99_share']:.3f} % at p99)")
    row("control cycle", "heap allocations",
        f"{cc['allocations']} in {cc['samples']} cycles; NoAllocation test {r['allocation_test']}", "0",
        ok(B["allocations_per_cycle"]))
    ph = cc["phase_mean_ns"]
    row("control cycle", "phases, mean ns",
        ", ".join(f"{k.replace('inverse_kinematics', 'IK')} {ph[k]:.0f}" for k in
                  ("estimate", "trajectory", "inverse_kinematics", "controller", "safety", "publish")))
    row("control cycle", "controller step alone median / p99", f"{cs['median_ns']} / {cs['p99_ns']} ns")
    row("control cycle", "timer overhead in each figure", f"{r['driver']['timer_overhead_ns']} ns")
    row("simulator", "plant step median / p99",
        f"{ps['median_ns']} / {ps['p99_ns']} ns = {100 * ps['median_share']:.2f} % of {per:g} ms")
    rtf = r["rtf"]
    row("simulator", "real-time factor, plant alone, as shipped (config/sim.yaml: its truth model, "
        f"{ps['substeps']} sub-steps)", f"{rtf['plant_shipped']:.1f}", "> 100", ok(B["plant_rtf"]))
    row("simulator", "real-time factor, plant alone, the calibrated model with effects above",
        f"{rtf['plant']:.1f}")
    row("simulator", f"plant RTF at 1 / 2 / 4 / {ps['substeps']} RK4 sub-steps (shipped: {ps['substeps']})",
        " / ".join(f"{x['rtf']:.0f}" for x in ps["substeps_sweep"]),
        "one-period error vs 40 sub-steps: " + " / ".join(f"{x['max_step_error_m']:.1e}" for x in ps["substeps_sweep"]) + " m")
    row("simulator", "real-time factor, closed loop (sim)", f"{rtf['closed_loop']:.1f}")
    row("simulator", "real-time factor, cpmd loop on its sim backend", f"{rtf['daemon_loop_sim']:.1f}")
    L = r["latency"]
    c, t, i = L["cpmd"], L["cyclictest"], L["cyclictest_idle"]
    sched = lambda x: "SCHED_FIFO " + str(L["priority"]) if x["realtime"] else "normal scheduling"  # noqa: E731
    cpus = lambda x: "CPU " + "/".join(str(v) for v in x.get("cpus", [])) if x.get("cpus") else "any CPU"  # noqa: E731
    segs = L["segments"]
    row("wake-up latency", f"{L['seconds']:g} s at {L['interval_us']} us, {segs} turns of {L['seconds'] / segs:g} s, "
        "cpmd and cyclictest at once (CPUs swapped each turn)",
        f"cpmd: {sched(c)}, {cpus(c)}, {c['cycles']} cycles", f"cyclictest: {sched(t)}, {cpus(t)}, {t['cycles']} cycles")

    def fig(x, k):
        return (x["bounds"].get(k, "") + " " if k in x["bounds"] else "") + f"{x[k + '_us']:.0f} us"

    def ratio_text(q, qb, k):
        if q[k] is None:
            return "no ratio (both >= a period)"
        return f"ratio {'' if qb[k] in ('~', '=') else qb[k] + ' '}{q[k]:.2f}"

    for k, name in (("p50", "p50"), ("p99", "p99"), ("p999", "p99.9"), ("max", "max")):
        verdict = " " + ok(B["wakeup_p99_ratio"]) if k == "p99" else ""
        row("wake-up latency", name + (" over slots" if k != "max" else ""), "cpmd " + fig(c, k),
            "cyclictest " + fig(t, k) + ("; budget ratio <= 1.2" if k == "p99" else ""),
            ratio_text(L["ratio"], L["ratio_bound"], k) + verdict)
    row("wake-up latency", "slots late by a period or more", f"cpmd {c['late_slots']} ({c['skipped']} skipped)",
        f"cyclictest {t['late_slots']} ({t['skipped']} skipped)")
    row("wake-up latency", "mean / min (us)", f"cpmd {c['mean_us']:.1f} / {c['min_us']:.1f}",
        f"cyclictest {t['mean_us']:.1f} / {t['min_us']:.1f}")
    row("wake-up latency", "period jitter bound (max - min)", f"cpmd {c['period_jitter_bound_us']:.1f} us",
        f"cyclictest {t['period_jitter_bound_us']:.1f} us")
    row("wake-up latency", "cpmd overruns / skipped slots", f"{c['overruns']} / {c['skipped']}")
    cyc = c["phases"].get("cycle", {})
    if cyc:
        row("wake-up latency", "cpmd whole cycle in the run: mean / p99 / max",
            f"{cyc['mean_ns'] / 1000:.1f} / {cyc['p99_us']:g} / {cyc['max_us']:.1f} us")
    row("wake-up latency", f"the idle machine: cyclictest alone, {i['cycles']} cycles, p50 / p99 / p99.9",
        f"{fig(i, 'p50')} / {fig(i, 'p99')} / {fig(i, 'p999')}; {i['late_slots']} slots late",
        "cpmd against it: p99 " + ratio_text(L["ratio_idle"], L["ratio_idle_bound"], "p99"),
        "cyclictest with cpmd running / idle: p99 " + ratio_text(L["load_effect"], L["load_effect_bound"], "p99"))
    C = L["control"]
    g = lambda x: "-" if x["geomean"] is None else f"{x['geomean']:.2f}"  # noqa: E731
    row("wake-up latency", "turn by turn: p99 above the other's in / geometric mean of the p99 ratios",
        f"cpmd above cyclictest in {L['per_turn']['above']} of {L['per_turn']['turns']} turns / {g(L['per_turn'])}",
        f"control: first cyclictest above the second in {C['per_turn']['above']} of {C['per_turn']['turns']} / "
        f"{g(C['per_turn'])}")
    spread = "unbounded" if C["spread"] is None else f"{C['spread']:.2f}"
    row("wake-up latency", "control: two cyclictests at once, p99 / slots late",
        f"{fig(C['a'], 'p99')} / {C['a']['late_slots']}", f"{fig(C['b'], 'p99')} / {C['b']['late_slots']}",
        f"p99 {ratio_text(C['ratio'], C['ratio_bound'], 'p99')}: spread {spread}")
    lc = L.get("linuxcnc")
    if lc and "skipped" in lc:
        row("LinuxCNC", "not run", lc["skipped"])
    elif lc:
        def verdict_against(q, qb):
            return ratio_verdict(q["p99"], qb["p99"], C["spread"])

        row("LinuxCNC", "servo thread 1 kHz (rtapi_app POSIX real-time), motmod + lineardeltakins circling, "
            "timedelta + sampler, in the same seconds",
            f"SCHED_FIFO {L['priority']}, {cpus(lc)}, {lc['cycles']} periods ({lc['lost_samples']} lost)",
            "sharing its CPU with cyclictest in half the turns, with cpmd in the other half")
        for k, name in (("p50", "p50"), ("p99", "p99"), ("p999", "p99.9"), ("max", "max")):
            row("LinuxCNC", f"wake-up latency {name} (from its periods: a lower bound, short by its minimum)",
                "LinuxCNC " + fig(lc, k),
                "cpmd " + fig(c, k) + " / cyclictest " + fig(t, k),
                "cpmd/LinuxCNC " + ratio_text(lc["ratio_cpmd_to_linuxcnc"], lc["ratio_cpmd_to_linuxcnc_bound"], k) +
                ("; LinuxCNC/cyclictest " + ratio_text(lc["ratio_to_cyclictest"], lc["ratio_to_cyclictest_bound"], k) +
                 " " + verdict_against(lc["ratio_to_cyclictest"], lc["ratio_to_cyclictest_bound"]) +
                 "; cpmd/LinuxCNC " + verdict_against(lc["ratio_cpmd_to_linuxcnc"], lc["ratio_cpmd_to_linuxcnc_bound"])
                 if k == "p99" else ""))
        row("LinuxCNC", "timedelta: period min / max, jitter max |period - T| (its latency-test figure)",
            f"{lc['period_min_us']:.1f} / {lc['period_max_us']:.1f} us, jitter {lc['timedelta_jitter_us']:.1f} us",
            f"cpmd jitter bound {c['period_jitter_bound_us']:.1f} us / cyclictest {t['period_jitter_bound_us']:.1f} us")
        row("LinuxCNC", "wake-ups late by a period or more (run late, never skipped)", f"{lc['late_slots']}",
            f"cpmd {c['late_slots']} / cyclictest {t['late_slots']}")
        ptl = lc["per_turn_cpmd_vs_linuxcnc"]
        row("LinuxCNC", "turn by turn: cpmd's p99 above LinuxCNC's in / geometric mean of the ratios",
            f"{ptl['above']} of {ptl['turns']} / {g(ptl)}")
        mo, th = lc["motion_ns"], lc["thread_ns"]
        row("LinuxCNC", "cost per cycle: motion-command-handler + motion-controller (lineardeltakins) .time, "
            "median / p99 / max",
            f"{mo['median']:.0f} / {mo['p99']:.0f} / {mo['max']:.0f} ns (TSC {lc['tsc_mhz']:.0f} MHz)",
            f"cpmd's cycle compute {cc['median_ns']} / {cc['p99_ns']} / {cc['max_ns']} ns",
            f"LinuxCNC/cpmd median {mo['median'] / cc['median_ns']:.2f}, p99 {mo['p99'] / cc['p99_ns']:.2f}")
        if th:
            row("LinuxCNC", "servo thread .time (all its functions) in the run, median / p99 / max",
                f"{th['median'] / 1000:.1f} / {th['p99'] / 1000:.1f} / {th['max'] / 1000:.1f} us",
                f"cpmd whole cycle in the run mean / p99 / max {cyc['mean_ns'] / 1000:.1f} / {cyc['p99_us']:g} / "
                f"{cyc['max_us']:.1f} us" if cyc else "")
    bus = r["bus"]
    s, alt, fb = bus["shipped"], bus["alternative"], bus["fake_bus"]
    row("CAN bus", f"{bus['drives']} drives, {bus['bitrate'] / 1e6:g} Mbit/s, {bus['rate_hz']:g} Hz: frames per cycle",
        f"{s['frames_per_cycle']} (SYNC + RPDO1 + TPDO1 per drive)")
    row("CAN bus", "bits per cycle, worst-case stuffing / no stuffing",
        f"{s['bits_per_cycle']} / {bus['best_case_bits_per_cycle']} bit + {s['periodic_bits_per_cycle']:.1f} heartbeats",
        f"budget {s['bits_available']:.0f} bit per cycle")
    row("CAN bus", "load (average / worst cycle with a blocking frame)",
        f"{100 * s['load']:.1f} % / {100 * s['worst_cycle_load']:.1f} %", f"refused above {100 * bus['max_bus_load']:.0f} %")
    row("CAN bus", "highest loop rate (<= 80 % and no cycle over)", f"{s['max_rate_hz']:.0f} Hz",
        f"at 100 % load: {bus['rate_at_full_load_hz']:.0f} Hz")
    row("CAN bus", "with the velocity TPDO2 as well", f"{alt['frames_per_cycle']} frames, {100 * alt['load']:.1f} %",
        f"highest rate {alt['max_rate_hz']:.0f} Hz")
    row("CAN bus", "counted on the fake bus (master + 3 virtual drives)",
        f"{fb['frames_per_cycle']:.2f} frames, {fb['bits_per_cycle']:.1f} bit per cycle = {100 * fb['load']:.1f} %")
    cal = r["calibration"]
    row("calibration", f"Kim's {cal['poses']}-point ball-bar: C++ LM solve, median",
        f"{cal['cpp_solve_s'] * 1e6:.1f} us ({cal['cpp_solve_iterations']} iterations)",
        f"SciPy lm {cal['scipy_lm_s'] * 1e6:.1f} us ({cal['scipy_lm_nfev']} evaluations)",
        f"SciPy/C++ {cal['ratio_scipy_lm_to_cpp']:.1f}x")
    row("calibration", "SciPy trf on the same problem", f"{cal['scipy_trf_s'] * 1e6:.1f} us",
        f"SciPy {cal['scipy_version']}", f"SciPy/C++ {cal['ratio_scipy_trf_to_cpp']:.1f}x")
    row("calibration", "C++ whole fit (solve + identifiability + frame)", f"{cal['cpp_fit_s'] * 1e6:.1f} us")
    row("calibration", "solutions: max |C++ - SciPy| / std. error", f"{cal['solution_max_diff_sigma']:.2g}",
        f"cost C++ {cal['cost_cpp_m2']:.6g}, SciPy {cal['cost_scipy_lm_m2']:.6g} m^2")
    dg = r["diagnose"]
    m = dg["motion_1khz"]
    row("diagnose", f"motion log {m['samples'] / 1000:g} s at 1 kHz, whole dynamic library", f"{m['seconds']:.3f} s")
    row("diagnose", "ball-bar file, 32 points (Kim's poses), whole kinematic library",
        f"{dg['ballbar_32_file']['seconds'] * 1e3:.1f} ms")
    row("diagnose", "ball-bar, 192 points, whole kinematic library", f"{dg['ballbar_192']['seconds'] * 1e3:.1f} ms")
    return rows


def render(r, rows):
    mc = r["machine"]
    lines = []
    if r["quick"]:
        lines.append("QUICK RUN: small samples and short runs; these are not the figures of docs/performance.md")
    lines.append(f"{mc['cpu_model']}, {mc['cores']} cores, Linux {mc['kernel']} ({'PREEMPT_RT' if mc['preempt_rt'] else 'not PREEMPT_RT'}), "
                 f"virtualization: {mc['virtualization']}, SCHED_FIFO {'allowed' if mc['realtime_allowed'] else 'refused'}, {mc['date']}")
    w = [max(len(x[i]) for x in rows) for i in range(5)]
    w[0] = max(w[0], len("group"))
    head = ("group", "figure", "measured", "reference / budget", "verdict")
    fmt = lambda x: " | ".join(s.ljust(w[i]) for i, s in enumerate(x)).rstrip()  # noqa: E731
    use = r["machine_use"]
    lines.append("other processes' share of all cores while measuring: " + ", ".join(
        f"{k.replace('_', ' ')} {100 * v['other']:.0f} %" for k, v in use.items()) +
        ("  (a busy machine: figures are not comparable)" if any(v["other"] > 0.1 for v in use.values()) else ""))
    lines.append(fmt(head))
    lines.append("-+-".join("-" * n for n in w))
    for x in rows:
        lines.append(fmt(x))
    lines.append("budgets: " + ", ".join(f"{b['text']} {verdict_of(b)}" for b in r["budgets"]))
    return "\n".join(lines)


def markdown(r):
    esc = lambda x: x.replace("|", "\\|")  # noqa: E731
    lines = ["| group | figure | measured | reference / budget | verdict |", "|---|---|---|---|---|"]
    lines += ["| " + " | ".join(esc(c) for c in row) + " |" for row in table(r)]
    return "\n".join(lines)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--markdown", metavar="JSON")
    ap.add_argument("--dir")
    ap.add_argument("--json")
    ap.add_argument("--quick", type=int, default=0)
    ap.add_argument("--seconds", type=float)
    ap.add_argument("--segments", type=int, default=1)
    ap.add_argument("--priority", type=int)
    ap.add_argument("--interval-us", type=int)
    ap.add_argument("--realtime-allowed", type=int)
    ap.add_argument("--allocation-test")
    a = ap.parse_args()
    if a.markdown:
        print(markdown(json.load(open(a.markdown))))
        return
    if None in (a.dir, a.json, a.seconds, a.priority, a.interval_us, a.realtime_allowed, a.allocation_test):
        ap.error("--dir, --json, --seconds, --priority, --interval-us, --realtime-allowed and --allocation-test")
    r = build(a)
    rows = table(r)
    r["table"] = [list(x) for x in rows]
    text = render(r, rows)
    print(text)
    with open(a.json, "w") as f:
        json.dump(r, f, indent=1)
        f.write("\n")


if __name__ == "__main__":
    main()
