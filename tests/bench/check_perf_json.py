#!/usr/bin/python3
# SPDX-License-Identifier: Apache-2.0
"""Check that a JSON of bench/run.sh has every field docs/performance.md
reports, each a finite number (or the stated type). Shape only: no timing."""
import json
import math
import shutil
import sys

NUM = (int, float)
NUM_OR_NULL = "number or null"  # a ratio of two '>= one period' bounds has no value
REQUIRED = {
    "machine": {"cpu_model": str, "cores": int, "kernel": str, "preempt_rt": bool, "virtualization": str,
                "realtime_allowed": bool, "date": str},
    "control_cycle": {"samples": int, "median_ns": NUM, "p99_ns": NUM, "p999_ns": NUM, "max_ns": NUM,
                      "median_share": NUM, "p99_share": NUM, "allocations": int, "replay_mismatches": int,
                      "phase_mean_ns": dict},
    "controller_step": {"median_ns": NUM, "p99_ns": NUM},
    "plant_step": {"median_ns": NUM, "p99_ns": NUM, "median_share": NUM, "substeps": int, "substeps_sweep": list},
    "rtf": {"plant": NUM, "plant_shipped": NUM, "closed_loop": NUM, "daemon_loop_sim": NUM},
    "latency": {"seconds": NUM, "segments": int, "priority": int, "interval_us": int, "cpmd": dict, "cyclictest": dict,
                "cyclictest_idle": dict, "ratio": dict, "ratio_idle": dict, "load_effect": dict, "pinning": list},
    "bus": {"drives": int, "bitrate": NUM, "rate_hz": NUM, "best_case_bits_per_cycle": int,
            "rate_at_full_load_hz": NUM, "shipped": dict, "alternative": dict, "fake_bus": dict},
    "calibration": {"poses": int, "cpp_solve_s": NUM, "cpp_fit_s": NUM, "scipy_lm_s": NUM, "scipy_trf_s": NUM,
                    "ratio_scipy_lm_to_cpp": NUM, "ratio_scipy_trf_to_cpp": NUM, "solution_max_diff_sigma": NUM,
                    "residual_check_max_m": NUM},
    "diagnose": {"motion_1khz": dict, "ballbar_32_file": dict, "ballbar_192": dict},
}
LATENCY = {"cycles": int, "min_us": NUM, "mean_us": NUM, "p50_us": NUM, "p99_us": NUM, "p999_us": NUM,
           "max_us": NUM, "period_jitter_bound_us": NUM, "late_slots": int, "bounds": dict, "realtime": bool}
BUS = {"frames_per_cycle": int, "bits_per_cycle": int, "load": NUM, "worst_cycle_load": NUM, "max_rate_hz": NUM}
BUDGETS = {"control_cycle_median", "allocations_per_cycle", "wakeup_p99_ratio", "plant_rtf"}


def check(obj, spec, where, errors):
    for key, kind in spec.items():
        if key not in obj:
            errors.append(f"{where}.{key}: missing")
            continue
        v = obj[key]
        if kind is NUM_OR_NULL:
            ok = v is None or (isinstance(v, NUM) and not isinstance(v, bool) and math.isfinite(v))
        elif kind is NUM:
            ok = isinstance(v, NUM) and not isinstance(v, bool) and math.isfinite(v)
        elif kind is int:
            ok = isinstance(v, int) and not isinstance(v, bool)
        else:
            ok = isinstance(v, kind)
        if not ok:
            errors.append(f"{where}.{key}: {v!r} is not {kind if isinstance(kind, str) else getattr(kind, '__name__', 'a number')}")


def main():
    r = json.load(open(sys.argv[1]))
    errors = []
    check(r, {k: dict for k in REQUIRED}, "", errors)
    for section, spec in REQUIRED.items():
        if isinstance(r.get(section), dict):
            check(r[section], spec, section, errors)
    lat = r.get("latency", {})
    for who in ("cpmd", "cyclictest", "cyclictest_idle"):
        check(lat.get(who, {}), dict(LATENCY, skipped=int), f"latency.{who}", errors)
    ctl = lat.get("control", {})
    check(ctl, {"a": dict, "b": dict, "ratio": dict, "spread": NUM_OR_NULL, "per_turn": dict}, "latency.control", errors)
    for where, t in (("latency.per_turn", lat.get("per_turn", {})), ("latency.control.per_turn", ctl.get("per_turn", {}))):
        check(t, {"turns": int, "above": int, "geomean": NUM_OR_NULL}, where, errors)
    for who in ("a", "b"):
        check(ctl.get(who, {}), dict(LATENCY, skipped=int), f"latency.control.{who}", errors)
    # The together runs: cpmd and cyclictest each on its own CPU in every turn (on a machine of two or more).
    if isinstance(r.get("machine", {}).get("cores"), int) and r["machine"]["cores"] >= 2:
        for k, p in enumerate(lat.get("pinning", []), 1):
            if not isinstance(p, dict) or p.get("cpmd_cpu") in (None, "any") or p.get("cpmd_cpu") == p.get("cyclictest_cpu"):
                errors.append(f"latency.pinning[{k}]: {p!r}: cpmd and cyclictest not on two CPUs")
        if len(lat.get("pinning", [])) != lat.get("segments"):
            errors.append(f"latency.pinning: {len(lat.get('pinning', []))} turns of {lat.get('segments')}")
    # Every turn merged: the slots run or skipped cover the whole run, not one turn of it.
    if isinstance(lat.get("seconds"), NUM) and isinstance(lat.get("interval_us"), int) and lat["interval_us"] > 0:
        slots = lat["seconds"] * 1e6 / lat["interval_us"]
        for who in ("cpmd", "cyclictest", "cyclictest_idle"):
            w = lat.get(who, {})
            if isinstance(w.get("cycles"), int) and isinstance(w.get("skipped"), int) and \
                    w["cycles"] + w["skipped"] < 0.75 * slots:
                errors.append(f"latency.{who}: {w['cycles']} cycles + {w['skipped']} skipped of {slots:.0f} slots")
    for name in ("ratio", "ratio_idle", "load_effect"):
        check(lat.get(name, {}), {k: NUM_OR_NULL for k in ("p50", "p99", "p999", "max")}, f"latency.{name}", errors)
    # LinuxCNC in the together runs: measured where it can run real-time (installed, SCHED_FIFO
    # allowed), else the reason it was left out.
    lc = lat.get("linuxcnc")
    if isinstance(lc, dict) and "skipped" in lc:
        check(lc, {"skipped": str}, "latency.linuxcnc", errors)
        if shutil.which("linuxcnc") and r.get("machine", {}).get("realtime_allowed"):
            errors.append(f"latency.linuxcnc: skipped ({lc['skipped']}) although LinuxCNC is installed and SCHED_FIFO allowed")
    else:
        check(lc if isinstance(lc, dict) else {}, dict(LATENCY, lost_samples=int, period_min_us=NUM, period_max_us=NUM,
                                                      timedelta_jitter_us=NUM, tsc_mhz=NUM, motion_ns=dict,
                                                      ratio_cpmd_to_linuxcnc=dict, ratio_to_cyclictest=dict),
              "latency.linuxcnc", errors)
        if isinstance(lc, dict):
            check(lc.get("motion_ns", {}), {k: NUM for k in ("median", "p99", "max", "mean")}, "latency.linuxcnc.motion_ns", errors)
    for m in ("shipped", "alternative"):
        check(r.get("bus", {}).get(m, {}), BUS, f"bus.{m}", errors)
    for d in ("motion_1khz", "ballbar_32_file", "ballbar_192"):
        check(r.get("diagnose", {}).get(d, {}), {"seconds": NUM, "samples": int}, f"diagnose.{d}", errors)
    got = {b.get("id") for b in r.get("budgets", [])}
    if got != BUDGETS:
        errors.append(f"budgets: {sorted(got)} instead of {sorted(BUDGETS)}")
    for b in r.get("budgets", []):
        check(b, {"measured": NUM_OR_NULL, "limit": NUM, "pass": bool, "verdict": str}, f"budgets.{b.get('id')}", errors)
        if b.get("verdict") not in ("PASS", "FAIL", "UNDECIDED") or (b.get("verdict") == "PASS") != b.get("pass"):
            errors.append(f"budgets.{b.get('id')}: verdict {b.get('verdict')!r} with pass {b.get('pass')!r}")
    if not r.get("table"):
        errors.append("table: missing")
    if errors:
        print("\n".join(errors))
        sys.exit(1)
    print(f"{sys.argv[1]}: every field present ({len(r['table'])} table rows, {len(got)} budgets)")


if __name__ == "__main__":
    main()
