#!/usr/bin/python3
# SPDX-License-Identifier: Apache-2.0
"""bench/report.py merges the latency turns of each program into one run:
checked against runs built by hand whose merged percentiles are known."""
import os
import sys
import unittest

sys.path.insert(0, os.path.join(os.path.dirname(__file__), "..", "..", "bench"))
import report  # noqa: E402

PERIOD_US = 1000


def coarse_floor_us(us):
    """loop_stats_t's bins: 1 us below 200 us, 50 us to 2 ms, one above."""
    return us if us < 200 else 200 + 50 * ((us - 200) // 50) if us < 2000 else 2000


def cpmd_doc(hist_us, skipped, overruns, mean_ns):
    """A cpmd --stats-json with one wake-up series, in loop_stats_t's bins and in 1 us
    bins (histogram keys as cpmd writes them: strings)."""
    count = sum(hist_us.values())
    coarse = {}
    for k, n in hist_us.items():
        coarse[coarse_floor_us(k)] = coarse.get(coarse_floor_us(k), 0) + n
    lat = {"count": count, "min_ns": min(hist_us) * 1000, "max_ns": max(hist_us) * 1000 + 500, "mean_ns": mean_ns,
           "histogram_us": {str(k): n for k, n in coarse.items()},
           "histogram_1us": {str(min(k, 2000)): n for k, n in hist_us.items()}}
    idle = {"count": 0, "min_ns": 0, "max_ns": 0, "mean_ns": 0.0, "histogram_us": {}}
    return {"rate_hz": 1000, "cycles": count, "overruns": overruns, "skipped": skipped, "realtime": True,
            "memory_locked": True, "series": {"wakeup_latency": lat, "publish": idle}}


def cyclictest_doc(hist_us, avg, above_range=0, max_us=None, seconds=None):
    """cyclictest --json with -h 2000: samples of 2 ms or more are counted in cycles, not in the histogram."""
    cmdline = {"cmdline:": f"cyclictest -q -m -t 1 -p 80 -i 1000 -D {seconds} -h 2000"} if seconds else {}
    return {**cmdline, "rt_test_version:": "2.40", "thread": {"0": {
        "histogram": {str(k): n for k, n in hist_us.items()}, "cycles": str(sum(hist_us.values()) + above_range),
        "min": str(min(hist_us)), "max": str(max_us or max(hist_us)), "avg": str(avg)}}}


class MergeTurns(unittest.TestCase):
    def test_cpmd_turns_add_up_to_one_run(self):
        # Turn 1: 990 wake-ups at 50 us, 10 at 700 us. Turn 2: 980 at 60 us, 20 at 1500 us, 5 slots skipped.
        a = cpmd_doc({50: 990, 700: 10}, skipped=0, overruns=1, mean_ns=56000.0)
        b = cpmd_doc({60: 980, 1500: 20}, skipped=5, overruns=3, mean_ns=88000.0)
        m = report.merge_cpmd_stats([a, b])
        self.assertEqual(m["cycles"], 2000)
        self.assertEqual(m["skipped"], 5)
        self.assertEqual(m["overruns"], 4)
        s = m["series"]["wakeup_latency"]
        self.assertEqual(s["count"], 2000)
        self.assertEqual(s["min_ns"], 50000)
        self.assertEqual(s["max_ns"], 1500500)
        self.assertAlmostEqual(s["mean_ns"], (56000.0 * 1000 + 88000.0 * 1000) / 2000)
        self.assertEqual(m["series"]["publish"]["count"], 0)
        f = report.cpmd_latency(m, PERIOD_US)
        # 2005 slots: 990 at 50 us, 980 at 60, 10 at 700, 20 at 1500, 5 skipped.
        # p50, rank 1003: the 60 us bin (<= 61 us). p99, rank 1985: 1970 + 10 = 1980 < 1985, so among the
        # slots a period or more late: '>= 1000'.
        self.assertEqual((f["p50_us"], f["bounds"]["p50"]), (61, "<="))
        self.assertEqual((f["p99_us"], f["bounds"]["p99"]), (PERIOD_US, ">="))
        self.assertEqual(f["late_slots"], 25)

    def test_one_turn_is_the_run_itself(self):
        a = cpmd_doc({40: 500, 90: 10}, skipped=2, overruns=0, mean_ns=41000.0)
        self.assertEqual(report.cpmd_latency(report.merge_cpmd_stats([a]), PERIOD_US), report.cpmd_latency(a, PERIOD_US))

    def test_cyclictest_turns_count_their_own_skipped_slots(self):
        # Two 1 s turns: 1000 slots each; 998 and 995 samples, so 2 and 5 slots skipped.
        a = cyclictest_doc({55: 990, 300: 8}, avg=57.0)
        b = cyclictest_doc({65: 990}, avg=80.0, above_range=5, max_us=2500)
        f = report.cyclictest_latency([a, b], True, PERIOD_US, 1.0)
        self.assertEqual(f["cycles"], 1993)
        self.assertEqual(f["skipped"], 7)
        self.assertEqual(f["min_us"], 55.0)
        self.assertEqual(f["max_us"], 2500.0)
        self.assertAlmostEqual(f["mean_us"], (57.0 * 998 + 80.0 * 995) / 1993)
        # 2000 slots: p99 rank 1980 = 990 + 990 = 1980 -> the 65 us bin.
        self.assertEqual((f["p99_us"], f["bounds"]["p99"]), (66, "<="))
        # The 5 samples above -h's 2 ms range and the 7 skipped slots are late by a period or more.
        self.assertEqual(f["late_slots"], 12)


class FineBins(unittest.TestCase):
    def test_p99_at_one_microsecond_not_fifty(self):
        # 1000 slots each. cpmd: 985 at 60 us, 15 at 251 us; cyclictest: 985 at 60 us, 15 at 230 us.
        # In loop_stats_t's bins the two p99 would be 300 and 250 us (ratio 1.2); in 1 us bins the upper
        # edges 252 and 231, each capped at its run's measured maximum (251.5 and 230 us).
        c = report.cpmd_latency(cpmd_doc({60: 985, 251: 15}, skipped=0, overruns=0, mean_ns=62000.0), PERIOD_US)
        t = report.cyclictest_latency([cyclictest_doc({60: 985, 230: 15}, avg=62.0)], True, PERIOD_US, 1.0)
        self.assertEqual((c["p99_us"], t["p99_us"]), (251.5, 230.0))
        ratio, bound = report.latency_ratio(c, t)
        self.assertAlmostEqual(ratio["p99"], 251.5 / 230.0)
        self.assertEqual(bound["p99"], "~")
        self.assertEqual(bound["max"], "=")

    def test_cpmd_above_two_ms_counts_as_late(self):
        c = report.cpmd_latency(cpmd_doc({60: 990, 2500: 10}, skipped=30, overruns=10, mean_ns=90000.0), PERIOD_US)
        self.assertEqual(c["late_slots"], 40)
        self.assertEqual((c["p99_us"], c["bounds"]["p99"]), (PERIOD_US, ">="))

    def test_ratio_bounds_when_one_side_is_a_period_or_more(self):
        c = report.cpmd_latency(cpmd_doc({60: 985, 400: 15}, skipped=0, overruns=0, mean_ns=62000.0), PERIOD_US)
        t = report.cyclictest_latency([cyclictest_doc({60: 980}, avg=62.0, above_range=20, max_us=3000)],
                                      True, PERIOD_US, 1.0)
        ratio, bound = report.latency_ratio(c, t)
        self.assertEqual(t["bounds"]["p99"], ">=")
        self.assertEqual(bound["p99"], "<=")   # cpmd 400.5 us, cyclictest a period or more: at most 0.4005
        self.assertAlmostEqual(ratio["p99"], 400.5 / PERIOD_US)
        both_late = report.cpmd_latency(cpmd_doc({60: 980, 1200: 20}, skipped=0, overruns=0, mean_ns=0.0), PERIOD_US)
        ratio, bound = report.latency_ratio(both_late, t)
        self.assertIsNone(ratio["p99"])


class RunLength(unittest.TestCase):
    def test_skipped_slots_from_cyclictests_own_duration(self):
        # A run of 3 s (a together run is a second longer than cpmd's): 2990 samples, 10 skipped,
        # whatever the turn length passed in.
        doc = cyclictest_doc({70: 2990}, avg=70.0, seconds=3)
        self.assertEqual(report.cyclictest_seconds(doc, 1.0), 3.0)
        self.assertEqual(report.cyclictest_latency([doc], True, PERIOD_US, 1.0)["skipped"], 10)
        self.assertEqual(report.cyclictest_seconds(cyclictest_doc({70: 5}, avg=70.0), 1.5), 1.5)


def verdict(ratio, bound, control_ratio, control_bound="~"):
    lat = {"ratio": {"p99": ratio}, "ratio_bound": {"p99": bound},
           "control": {"spread": report.spread_of(control_ratio, control_bound)}}
    return report.wakeup_verdict(lat)


class Verdict(unittest.TestCase):
    """The latency budget against the spread of two identical cyclictests in the same run."""

    def test_within_the_budget_passes_whatever_the_noise(self):
        self.assertEqual(verdict(1.15, "~", 2.5), "PASS")
        self.assertEqual(verdict(0.4, "<=", None, None), "PASS")   # cyclictest >= a period, cpmd well below

    def test_beyond_the_budget_and_the_noise_fails(self):
        self.assertEqual(verdict(1.40, "~", 1.05), "FAIL")
        self.assertEqual(verdict(1.40, "~", 1 / 1.05), "FAIL")     # the spread is symmetric
        self.assertEqual(verdict(2.5, ">=", 1.1), "FAIL")          # cpmd >= a period: at least 2.5

    def test_beyond_the_budget_within_the_noise_is_undecided(self):
        self.assertEqual(verdict(1.40, "~", 2.47), "UNDECIDED")
        self.assertEqual(verdict(1.40, "~", 1 / 1.5), "UNDECIDED")
        self.assertEqual(verdict(1.40, "~", None, None), "UNDECIDED")  # two cyclictests both >= a period
        self.assertEqual(verdict(None, None, 1.0), "UNDECIDED")        # cpmd and cyclictest both >= a period
        self.assertEqual(verdict(1.3, "<=", 1.0), "UNDECIDED")         # only an upper bound above the budget

    def test_spread(self):
        self.assertAlmostEqual(report.spread_of(0.8, "~"), 1.25)
        self.assertAlmostEqual(report.spread_of(1.25, "~"), 1.25)
        self.assertIsNone(report.spread_of(0.5, "<="))


class PerTurn(unittest.TestCase):
    def test_counts_and_geometric_mean(self):
        fig = lambda p99: {"p99_us": p99}  # noqa: E731
        t = report.per_turn([fig(200), fig(100), fig(1000)], [fig(100), fig(200), fig(250)])
        self.assertEqual((t["turns"], t["above"]), (3, 2))
        self.assertAlmostEqual(t["geomean"], (2.0 * 0.5 * 4.0) ** (1 / 3))
        self.assertIsNone(report.per_turn([], [])["geomean"])


class LinuxCnc(unittest.TestCase):
    """LinuxCNC's wake-ups rebuilt from timedelta's periods (halsampler -t lines),
    against wake-ups built by hand: late, a stall, the thread running back to back
    to catch up, on time again."""
    lateness = [2.0, 7.0, 3.0, 1200.0, 200.5, 4.0, 2.0]   # us after each slot, in order

    def write(self, lines):
        import tempfile
        f = tempfile.NamedTemporaryFile("w", suffix=".txt", delete=False)
        f.write("\n".join(lines) + "\n")
        f.close()
        self.addCleanup(os.unlink, f.name)
        return f.name

    def samples(self):
        wake = [k * PERIOD_US + x for k, x in enumerate(self.lateness)]
        lines = ["0 0 100 900 0"]  # the first sample: no period yet
        for k in range(1, len(wake)):
            ns = round((wake[k] - wake[k - 1]) * 1000)
            lines.append(f"{k} {ns} {100 + k} {900 + 10 * k} 5000")
        return lines

    def test_lateness_from_periods_less_the_smallest(self):
        r = report.linuxcnc_run(self.write(self.samples()), PERIOD_US)
        low = min(self.lateness)
        for got, want in zip(r["lateness_us"], self.lateness):
            self.assertAlmostEqual(got, want - low, places=6)
        self.assertEqual(r["lost"], 0)
        f = report.linuxcnc_figures([r], PERIOD_US, 1000.0)   # 1 GHz: a tick is a ns
        self.assertAlmostEqual(f["max_us"], 1198.0)
        self.assertEqual(f["late_slots"], 1)                 # the stall, run late: never skipped
        self.assertAlmostEqual(f["period_min_us"], 0.5)      # catching up back to back
        self.assertAlmostEqual(f["timedelta_jitter_us"], 1197.0)
        self.assertEqual(f["p50_us"], 3)                     # upper edge of the 2 us bin
        costs = sorted(100 + k + 900 + 10 * k for k in range(1, 7)) + [1000]
        self.assertEqual(f["motion_ns"]["max"], max(costs))

    def test_lost_samples_are_counted(self):
        lines = self.samples()
        del lines[3]
        lines.insert(3, "overrun")
        r = report.linuxcnc_run(self.write(lines), PERIOD_US)
        self.assertEqual(r["lost"], 2)  # the overrun line, and the gap in the tags


if __name__ == "__main__":
    unittest.main()
