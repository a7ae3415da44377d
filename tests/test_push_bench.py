#!/usr/bin/python3
"""Tests of the push-recovery benchmark's bookkeeping (bench/push.py), on
hand-made trial records, no simulation: the job list (size, trial-major
order, --first-trial to grow a grid later), delta-v50's interpolation, and
merging trial files and earlier merged files into one table (a trial seen
twice must agree, unless one was disturbed by the load; bad input is refused
naming the file), the table's per-controller means (heading, sliding, kinetic
energy, the fallback), and a trial run again while the load disturbs it (a
stand-in for build/pushstep). Prints cmocka's summary lines for
tools/run-tests.sh.
"""
import json
import os
import subprocess
import sys
import tempfile
import unittest

HERE = os.path.dirname(os.path.abspath(__file__))
PUSH = os.path.join(HERE, "..", "bench", "push.py")
sys.path.insert(0, os.path.join(HERE, "..", "bench"))
import push  # noqa: E402


def cli(*args):
    p = subprocess.run([sys.executable, PUSH] + list(args), stdout=subprocess.PIPE,
                       stderr=subprocess.PIPE, text=True)
    return p.returncode, p.stdout, p.stderr


def record(ctl, d, v, t, k, fell):
    spec = (ctl, float(d), float(v), float(t), k)
    return {"id": push.spec_id(spec), "controller": ctl, "direction_deg": float(d),
            "dv_m_s": float(v), "duration_s": float(t), "trial": k, "fell": fell,
            "force_n": v * push.MASS_KG / t}


def write_trials(directory, rows):
    os.makedirs(directory, exist_ok=True)
    for r in rows:
        with open(os.path.join(directory, r["id"] + ".json"), "w") as fh:
            json.dump(r, fh)


def cell(v, rate, n=4):
    return {"controller": "c", "duration_s": 0.1, "direction_deg": 0.0, "dv_m_s": v,
            "n": n, "n_success": int(rate * n), "success_rate": rate}


class Jobs(unittest.TestCase):
    def test_size_and_trial_major_order(self):
        rc, out, _ = cli("jobs", "--controllers", "stand,mlp", "--directions", "4",
                         "--trials", "3")
        self.assertEqual(rc, 0)
        specs = [push.parse_spec(line) for line in out.splitlines()]
        self.assertEqual(len(specs), 2 * 4 * 5 * 2 * 3)
        self.assertEqual(len(set(specs)), len(specs))
        ks = [s[4] for s in specs]
        self.assertEqual(ks, sorted(ks), "a cell's trial k+1 before another's trial k")
        self.assertEqual({s[1] for s in specs}, {0.0, 90.0, 180.0, 270.0})

    def test_first_trial_grows_a_grid(self):
        whole = cli("jobs", "--directions", "2", "--trials", "5")[1].splitlines()
        head = cli("jobs", "--directions", "2", "--trials", "2")[1].splitlines()
        tail = cli("jobs", "--directions", "2", "--trials", "5", "--first-trial", "2")[1]
        self.assertEqual(head + tail.splitlines(), whole)
        self.assertTrue(all(push.parse_spec(s)[4] >= 2 for s in tail.splitlines()))


class Dv50(unittest.TestCase):
    def dv50(self, cells):
        return push.dv50(cells)["c"]["0.1"]["0"]

    def test_interpolates_between_the_points_around_50_percent(self):
        cells = [cell(0.15, 1.0), cell(0.30, 0.75), cell(0.45, 0.25), cell(0.60, 0.0)]
        self.assertAlmostEqual(self.dv50(cells), 0.375)

    def test_order_of_cells_does_not_matter(self):
        cells = [cell(0.60, 0.0), cell(0.30, 1.0), cell(0.45, 0.0), cell(0.15, 1.0)]
        self.assertAlmostEqual(self.dv50(cells), 0.375)

    def test_never_below_half_gives_the_largest_push(self):
        self.assertEqual(self.dv50([cell(0.15, 1.0), cell(0.80, 0.5)]), 0.80)

    def test_failing_the_smallest_push_gives_zero(self):
        self.assertEqual(self.dv50([cell(0.15, 0.25), cell(0.30, 0.0)]), 0.0)


class Merge(unittest.TestCase):
    def setUp(self):
        self.tmp = tempfile.TemporaryDirectory()
        self.d = self.tmp.name

    def tearDown(self):
        self.tmp.cleanup()

    def path(self, name):
        return os.path.join(self.d, name)

    def merged_both_ways(self, a, b):
        """Merges directories a and b in both orders: each order's trials and table."""
        out = []
        for order in ((a, b), (b, a)):
            rc, table, err = cli("merge", *[self.path(x) for x in order],
                                 "--out", self.path("o.json"))
            self.assertEqual(rc, 0, err)
            out.append((json.load(open(self.path("o.json")))["trials"], table))
        return out

    def test_trial_files_and_a_merged_file_combine(self):
        first = [record("mlp", 0, 0.3, 0.1, k, k == 1) for k in range(2)]
        later = [record("mlp", 0, 0.3, 0.1, k, k != 2) for k in range(2, 4)]
        write_trials(self.path("a"), first)
        write_trials(self.path("b"), later + first[:1])  # one trial run twice: same result
        rc, _, err = cli("merge", self.path("a"), "--out", self.path("a.json"))
        self.assertEqual(rc, 0, err)
        rc, table, err = cli("merge", self.path("a.json"), self.path("b"),
                             "--out", self.path("all.json"))
        self.assertEqual(rc, 0, err)
        doc = json.load(open(self.path("all.json")))
        self.assertEqual(len(doc["trials"]), 4)
        (c,) = doc["cells"]
        self.assertEqual((c["n"], c["n_success"]), (4, 2))  # k 0 and 2 stood
        self.assertIn("| mlp | 2/4 |", table)

    def test_an_older_record_without_the_newer_fields_merges(self):
        old = record("mlp", 0, 0.3, 0.1, 0, False)
        new = dict(old, fallback_steps=3, policy_steps=400,
                   fallback_takeovers={"out_of_range": 1, "late": 0})
        write_trials(self.path("a"), [old])
        write_trials(self.path("b"), [new])
        for trials, _ in self.merged_both_ways("a", "b"):
            self.assertEqual(trials, [new])

    def test_per_controller_means_and_fallback(self):
        rows = [dict(record("mlp", 0, 0.3, 0.1, 0, False), heading_dev_deg=10.0,
                     foot_slide_m=0.10, kinetic_energy_j=40.0, policy_steps=400,
                     fallback_steps=0, fallback_takeovers={"late": 0, "out_of_range": 0}),
                dict(record("mlp", 0, 0.3, 0.3, 1, True), heading_dev_deg=20.0,
                     foot_slide_m=0.30, kinetic_energy_j=60.0, policy_steps=400,
                     fallback_steps=100, fallback_takeovers={"late": 1, "out_of_range": 2},
                     first_fall_t_s=4.5, first_takeover_t_s=4.0),
                dict(record("mlp", 90, 0.3, 0.3, 1, True), policy_steps=400,
                     fallback_steps=50, fallback_takeovers={"observation": 1},
                     first_fall_t_s=4.5, first_takeover_t_s=4.6),
                dict(record("stand", 0, 0.3, 0.1, 0, True), heading_dev_deg=5.0)]
        write_trials(self.path("a"), rows)
        rc, table, err = cli("merge", self.path("a"), "--out", self.path("o.json"))
        self.assertEqual(rc, 0, err)
        self.assertIn("| mlp | all | 3 | 1 | 15.0 | 20.0 | 50.0 | in 2 of 3 trials "
                      "(late 1, observation 1, out_of_range 2), 1 of them before a fall or "
                      "without one, 12.5 % of steps |", table)
        self.assertIn("| mlp | 0.1 s | 1 | 1 | 10.0 | 10.0 | 40.0 | in 0 of 1 trials "
                      "(never), 0 of them before a fall or without one, 0.0 % of steps |", table)
        self.assertIn("| stand | all | 1 | 0 | 5.0 | - | - | - |", table)

    def test_a_trial_with_two_results_is_refused(self):
        write_trials(self.path("a"), [record("mlp", 0, 0.3, 0.1, 0, False)])
        write_trials(self.path("b"), [record("mlp", 0, 0.3, 0.1, 0, True)])
        rc, _, err = cli("merge", self.path("a"), self.path("b"), "--out", self.path("o.json"))
        self.assertEqual(rc, 2)
        self.assertIn("mlp_d000_v0.30_t0.1_k00", err)
        self.assertIn("differs", err)
        self.assertFalse(os.path.exists(self.path("o.json")))

    def test_a_disturbed_record_gives_way_to_an_undisturbed_one(self):
        calm = record("mlp", 0, 0.3, 0.1, 0, False)
        disturbed = dict(record("mlp", 0, 0.3, 0.1, 0, True), disturbed=True)
        write_trials(self.path("a"), [calm])
        write_trials(self.path("b"), [disturbed])
        for trials, table in self.merged_both_ways("a", "b"):
            self.assertEqual(trials, [calm])
            self.assertNotIn("disturbed", table)
        rc, table, err = cli("merge", self.path("b"), "--out", self.path("o.json"))
        self.assertEqual(rc, 0, err)
        self.assertIn("1 trial(s) disturbed by the machine's load in every run", table)
        self.assertIn("mlp_d000_v0.30_t0.1_k00", table)

    def test_bad_sources_are_named(self):
        with open(self.path("bad.json"), "w") as fh:
            fh.write("{not json")
        with open(self.path("other.json"), "w") as fh:
            json.dump({"cells": []}, fh)
        for src, words in (("bad.json", "not JSON"), ("other.json", "not a merged push file"),
                           ("missing.json", "missing.json")):
            rc, _, err = cli("merge", self.path(src), "--out", self.path("o.json"))
            self.assertEqual(rc, 2, src)
            self.assertTrue(err.startswith("push.py merge: "), err)
            self.assertIn(words, err)
            self.assertIn(src, err)


# A stand-in for build/pushstep: writes a --summary whose overruns come from
# the counter file's next line (one line per run), not deterministic when
# there are any, as the runtime's, and counts its runs.
FAKE_PUSHSTEP = """#!/bin/sh
summary=""
while [ $# -gt 0 ]; do [ "$1" = --summary ] && summary=$2; shift; done
n=$(wc -l < "$FAKE_RUNS")
echo run >> "$FAKE_RUNS"
overruns=$(sed -n "$((n + 1))p" "$FAKE_OVERRUNS")
det=$( [ "$overruns" -gt 0 ] && echo false || echo true)
printf '{"overruns": %s, "deterministic": %s, "counters": {"policy_late": 0}, "sim_truth": {"fell_while_active": %s}}' \\
    "$overruns" "$det" "$( [ "$overruns" -gt 0 ] && echo true || echo false)" > "$summary"
"""


class Trial(unittest.TestCase):
    def setUp(self):
        self.tmp = tempfile.TemporaryDirectory()
        self.d = self.tmp.name
        self.bin = os.path.join(self.d, "pushstep")
        with open(self.bin, "w") as fh:
            fh.write(FAKE_PUSHSTEP)
        os.chmod(self.bin, 0o755)
        os.environ["FAKE_RUNS"] = os.path.join(self.d, "runs")
        os.environ["FAKE_OVERRUNS"] = os.path.join(self.d, "overruns")
        open(os.environ["FAKE_RUNS"], "w").close()

    def tearDown(self):
        self.tmp.cleanup()

    def trial(self, overruns):
        with open(os.environ["FAKE_OVERRUNS"], "w") as fh:
            fh.write("".join("%d\n" % n for n in overruns))
        open(os.environ["FAKE_RUNS"], "w").close()
        rc, _, err = cli("trial", "stand,0,0.3,0.1,0", "--out", self.d, "--bin", self.bin)
        self.assertEqual(rc, 0, err)
        with open(os.environ["FAKE_RUNS"]) as fh:
            n_runs = len(fh.readlines())
        with open(os.path.join(self.d, "stand_d000_v0.30_t0.1_k00.json")) as fh:
            return json.load(fh), n_runs, err

    def test_an_undisturbed_run_is_run_once(self):
        res, n_runs, err = self.trial([0, 0, 0])
        self.assertEqual((n_runs, res["fell"], "disturbed" in res), (1, False, False))
        self.assertEqual(err, "")

    def test_a_disturbed_run_is_run_again(self):
        res, n_runs, err = self.trial([2, 0, 0])
        self.assertEqual((n_runs, res["fell"], "disturbed" in res), (2, False, False))
        self.assertIn("run 1 disturbed by this machine's load (overruns 2, policy late 0): again",
                      err)

    def test_disturbed_every_time_is_kept_and_marked(self):
        res, n_runs, err = self.trial([1, 1, 1, 0])
        self.assertEqual((n_runs, res["fell"], res.get("disturbed")), (push.RUNS_MAX, True, True))
        self.assertIn("run 3 disturbed", err)
        self.assertIn("kept, marked disturbed", err)


def main():
    res = unittest.TextTestRunner(stream=sys.stdout, verbosity=2).run(
        unittest.defaultTestLoader.loadTestsFromModule(sys.modules[__name__]))
    bad = len(res.failures) + len(res.errors)
    print("[  PASSED  ] %d test(s)." % (res.testsRun - bad))
    if bad:
        print("[  FAILED  ] %d test(s), listed below:" % bad)
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
