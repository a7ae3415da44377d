#!/usr/bin/env python3
"""Push-recovery benchmark: chest pushes on the simulated robot, in the real
runtime (build/pushstep --lockstep: CAN frames, quantisation, servo layer).

One trial = one scenario file (start, harness release, one push on the torso
at a randomised time) run to push + 5 s; success = no fall (the plant's
ground truth: a robot body other than the feet touched the floor while the
controller was in charge). The push is given as delta-v = impulse / robot
mass, in a direction (0 deg = forward, +x; 90 deg = to the robot's left)
over a duration: force = delta_v * mass / duration.

Subcommands (so that GNU parallel, a Slurm array or parallel --sshlogin can
run the trials; nothing here schedules them):
  jobs  [grid options]          print one trial spec per line (--first-trial K
                                leaves out trials 0..K-1: a grid grown later)
  trial SPEC --out DIR          run one trial, write DIR/<id>.json (run again, up
                                to 3 runs, while this machine's load disturbs it)
  merge SRC... --out FILE.json  merge per-trial results (directories of trial
                                files, or earlier merged FILE.json) into one table
  table FILE.json               print the readable summary (markdown)

A trial spec is "controller,direction_deg,dv_m_s,duration_s,trial_idx".
Timing is drawn from a seed made of the spec, so a trial is reproducible.
"""
import argparse
import glob
import json
import math
import os
import random
import subprocess
import sys
import tempfile

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
MASS_KG = 37.7  # robots/ps1.yaml kinematics.mass_kg (= the model's mass)
SETTLE_S = 3.0  # harness released at 2.0 s; pushes from 3.0 s
AFTER_S = 5.0   # success: no fall for this long after the push starts
WEIGHTS = os.environ.get("PUSH_WEIGHTS",
                         os.path.join(ROOT, "policy", "weights", "ps1_stage1.safetensors"))


def spec_id(spec):
    c, d, v, t, k = spec
    return "%s_d%03d_v%.2f_t%.1f_k%02d" % (c, int(round(d)), v, t, k)


def parse_spec(text):
    c, d, v, t, k = text.strip().split(",")
    return (c, float(d), float(v), float(t), int(k))


def grid(controllers, n_dir, dvs, durations, trials, first_trial=0):
    """Trial-major: every cell's trial k before any cell's trial k + 1, so a
    grid cut short still has the same number of trials in every cell."""
    for k in range(first_trial, trials):
        for c in controllers:
            for i in range(n_dir):
                d = 360.0 * i / n_dir
                for v in dvs:
                    for t in durations:
                        yield (c, d, v, t, k)


def scenario_text(spec):
    c, d, v, t, k = spec
    rng = random.Random(spec_id(spec))
    t_push = SETTLE_S + rng.uniform(0.0, 1.0)
    f = v * MASS_KG / t
    fx, fy = f * math.cos(math.radians(d)), f * math.sin(math.radians(d))
    return t_push, f, (
        "name: push\nduration_s: %.3f\nseed: %d\nevents:\n"
        "  - {t_s: 0.2, kind: start}\n  - {t_s: 2.0, kind: harness_release}\n"
        "pushes:\n  - {t_s: %.3f, duration_s: %.3f, body: torso, force_n: [%.3f, %.3f, 0]}\n"
        % (t_push + AFTER_S, 1 + rng.randrange(1 << 30), t_push, t, fx, fy))


RUNS_MAX = 3  # runs of a trial while this machine's load disturbs them


def is_disturbed(summary):
    """The runtime says whether a lockstep run was a function of its spec
    alone: it judges a late policy step and an overrunning tick on the loop
    thread's CPU time (rt/ps_loop.h), which a loaded machine inflates, and a
    late step hands the slot to the fallback."""
    return summary.get("deterministic") is not True


def run_once(spec, binary, text):
    """One run of the trial's scenario; its summary, or None (said why)."""
    with tempfile.TemporaryDirectory() as tmp:
        scen = os.path.join(tmp, "s.yaml")
        summ = os.path.join(tmp, "s.json")
        with open(scen, "w") as fh:
            fh.write(text)
        cmd = [binary, "--lockstep", "--quiet", "--scenario", scen, "--summary", summ]
        if spec[0] != "default":
            cmd += ["--policy", spec[0]]
        if spec[0] == "mlp":
            cmd += ["--weights", WEIGHTS]
        p = subprocess.run(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
        if p.returncode != 0 or not os.path.exists(summ):
            sys.stderr.write("trial %s failed (%d):\n%s\n" % (spec_id(spec), p.returncode,
                                                              p.stdout[-2000:]))
            return None
        with open(summ) as fh:
            return json.load(fh)


def run_trial(spec, out_dir, binary):
    """Runs the trial (again while the load disturbs it, up to RUNS_MAX runs;
    a trial disturbed every time is kept with "disturbed": true) and writes
    out_dir/<id>.json."""
    t_push, f, text = scenario_text(spec)
    os.makedirs(out_dir, exist_ok=True)
    for n_run in range(1, RUNS_MAX + 1):
        s = run_once(spec, binary, text)
        if s is None:
            return 1
        disturbed = is_disturbed(s)
        if not disturbed:
            break
        sys.stderr.write("trial %s: run %d disturbed by this machine's load (overruns %d, "
                         "policy late %d)%s\n" % (
                             spec_id(spec), n_run, s.get("overruns", 0),
                             s.get("counters", {}).get("policy_late", 0),
                             ": again" if n_run < RUNS_MAX else ": kept, marked disturbed"))
    truth = s.get("sim_truth", {})
    res = {
        "id": spec_id(spec), "controller": spec[0], "direction_deg": spec[1],
        "dv_m_s": spec[2], "duration_s": spec[3], "trial": spec[4],
        "t_push_s": t_push, "force_n": f, "impulse_n_s": f * spec[3],
        "fell": bool(truth.get("fell_while_active", True)),
        "first_fall_t_s": truth.get("first_fall_t_s"),
    }
    for key in ("heading_dev_deg", "foot_slide_m", "kinetic_energy_j"):
        if key in truth:
            res[key] = truth[key]
    pol = s.get("policy", {})
    if "fallback_steps" in pol:  # the trained policy: how long its fallback was in charge
        res["policy_steps"] = pol["steps"]
        res["fallback_steps"] = pol["fallback_steps"]
        res["fallback_takeovers"] = pol["fallback_takeovers"]
        res["first_takeover_t_s"] = pol.get("first_takeover_t_s")
    if disturbed:
        res["disturbed"] = True
    with open(os.path.join(out_dir, spec_id(spec) + ".json"), "w") as fh:
        json.dump(res, fh)
    return 0


def load_json(path):
    try:
        with open(path) as fh:
            return json.load(fh)
    except ValueError as e:
        raise ValueError("%s: not JSON (%s)" % (path, e))


def read_trials(sources):
    """Trial records from directories of trial files and from merged files,
    one per trial id. A trial is reproducible, so the same id twice must
    carry the same result in every field both records have (a record of an
    older push.py may lack the newer fields; the fuller record is kept); a
    difference means two builds or two policy files were mixed, and is
    refused. Only a record marked "disturbed" (the load disturbed every run)
    may differ: the other record stands."""
    by_id = {}
    for src in sources:
        if os.path.isdir(src):
            files = sorted(glob.glob(os.path.join(src, "*.json")))
            rows = [load_json(p) for p in files]
        else:
            doc = load_json(src)
            if not isinstance(doc, dict) or not isinstance(doc.get("trials"), list):
                raise ValueError("%s: not a merged push file (no list \"trials\")" % src)
            rows = doc["trials"]
        for r in rows:
            if not isinstance(r, dict) or "id" not in r:
                raise ValueError("%s: a trial record without an id" % src)
            old = by_id.setdefault(r["id"], r)
            if bool(old.get("disturbed")) != bool(r.get("disturbed")):
                if old.get("disturbed"):
                    by_id[r["id"]] = r
                continue
            if any(old[k] != r[k] for k in old.keys() & r.keys()):
                raise ValueError("trial %s differs between sources (%s): results of "
                                 "different builds or policy files" % (r["id"], src))
            if len(r) > len(old):
                by_id[r["id"]] = r
    return [by_id[k] for k in sorted(by_id)]


def merge(sources, out):
    rows = read_trials(sources)
    cells = {}
    for r in rows:
        key = (r["controller"], r["direction_deg"], r["dv_m_s"], r["duration_s"])
        cells.setdefault(key, []).append(r)
    table = []
    for key in sorted(cells):
        rs = cells[key]
        ok = [r for r in rs if not r["fell"]]
        table.append({"controller": key[0], "direction_deg": key[1], "dv_m_s": key[2],
                      "duration_s": key[3], "n": len(rs), "n_success": len(ok),
                      "success_rate": len(ok) / len(rs), "force_n": rs[0]["force_n"]})
    doc = {"mass_kg": MASS_KG, "after_s": AFTER_S, "trials": rows, "cells": table,
           "dv50": dv50(table)}
    with open(out, "w") as fh:
        json.dump(doc, fh, indent=1)
    return doc


def dv50(cells):
    """Per controller, duration and direction: the delta-v where the success
    rate crosses 50 %, linearly interpolated between grid points (the largest
    grid point if it never drops below, 0 if the smallest already fails)."""
    out = {}
    by = {}
    for c in cells:
        by.setdefault((c["controller"], c["duration_s"], c["direction_deg"]), []).append(c)
    for (ctl, dur, d), cs in sorted(by.items()):
        cs.sort(key=lambda c: c["dv_m_s"])
        val = cs[-1]["dv_m_s"]
        prev = None
        for c in cs:
            if c["success_rate"] < 0.5:
                if prev is None:
                    val = 0.0
                else:
                    r0, r1 = prev["success_rate"], c["success_rate"]
                    v0, v1 = prev["dv_m_s"], c["dv_m_s"]
                    val = v0 + (r0 - 0.5) / (r0 - r1) * (v1 - v0)
                break
            prev = c
        out.setdefault(ctl, {}).setdefault("%.1f" % dur, {})["%g" % d] = val
    return out


def table_md(doc):
    lines = []
    ctls = sorted({c["controller"] for c in doc["cells"]})
    durs = sorted({c["duration_s"] for c in doc["cells"]})
    dvs = sorted({c["dv_m_s"] for c in doc["cells"]})
    dirs = sorted({c["direction_deg"] for c in doc["cells"]})
    for dur in durs:
        lines.append("\n### %.1f s push: success rate (no fall for %g s)\n" % (dur, AFTER_S))
        lines.append("| controller | " + " | ".join("dv %.2f m/s (%.0f N)" % (
            v, v * MASS_KG / dur) for v in dvs) + " |")
        lines.append("|---" * (len(dvs) + 1) + "|")
        for ctl in ctls:
            row = []
            for v in dvs:
                cs = [c for c in doc["cells"] if c["controller"] == ctl and
                      c["duration_s"] == dur and c["dv_m_s"] == v]
                n = sum(c["n"] for c in cs)
                k = sum(c["n_success"] for c in cs)
                row.append("%d/%d" % (k, n) if n else "-")
            lines.append("| %s | %s |" % (ctl, " | ".join(row)))
        lines.append("\nPer direction (success / trials at each dv), %.1f s:\n" % dur)
        lines.append("| controller | direction | " + " | ".join("%.2f" % v for v in dvs) +
                     " | dv50 |")
        lines.append("|---" * (len(dvs) + 3) + "|")
        for ctl in ctls:
            for d in dirs:
                row = []
                for v in dvs:
                    cs = [c for c in doc["cells"] if c["controller"] == ctl and
                          c["duration_s"] == dur and c["dv_m_s"] == v and
                          c["direction_deg"] == d]
                    row.append("%d/%d" % (cs[0]["n_success"], cs[0]["n"]) if cs else "-")
                d50 = doc["dv50"].get(ctl, {}).get("%.1f" % dur, {}).get("%g" % d)
                lines.append("| %s | %g | %s | %s |" % (ctl, d, " | ".join(row),
                                                         "%.2f" % d50 if d50 is not None else "-"))
    return "\n".join(lines) + "\n" + per_controller_md(doc)


def mean_of(rows, key, scale=1.0):
    vals = [r[key] * scale for r in rows if r.get(key) is not None]
    return "%.1f" % (sum(vals) / len(vals)) if vals else "-"


def fallback_of(rows):
    """The trained policy's fallback over these trials: in how many it took
    over, why, in how many of those it first took over before the robot fell
    (or in a trial without a fall), and its share of the policy steps (trials
    recorded by an older push.py carry none of this and are left out)."""
    rows = [r for r in rows if "fallback_steps" in r]
    if not rows:
        return "-"
    took = [r for r in rows if r["fallback_steps"] > 0]
    early = [r for r in took if r.get("first_takeover_t_s") is not None and
             (not r["fell"] or r["first_takeover_t_s"] < r["first_fall_t_s"])]
    why = {}
    for r in rows:
        for k, n in r["fallback_takeovers"].items():
            why[k] = why.get(k, 0) + n
    steps = sum(r["policy_steps"] for r in rows)
    share = 100.0 * sum(r["fallback_steps"] for r in rows) / steps if steps else 0.0
    reasons = ", ".join("%s %d" % (k, n) for k, n in sorted(why.items()) if n)
    return "in %d of %d trials (%s), %d of them before a fall or without one, " \
        "%.1f %% of steps" % (len(took), len(rows), reasons or "never", len(early), share)


def per_controller_md(doc):
    """The issue's per-trial measures, averaged over each controller's trials."""
    lines = ["\n### Per trial, averaged over each controller's trials\n",
             "| controller | push | trials | no fall | heading change (deg) | feet sliding (cm) "
             "| peak kinetic energy (J) | fallback took over |", "|---" * 8 + "|"]
    ctls = sorted({r["controller"] for r in doc["trials"]})
    durs = sorted({r["duration_s"] for r in doc["trials"]})
    for ctl in ctls:
        for dur in durs + [None]:
            rows = [r for r in doc["trials"] if r["controller"] == ctl and
                    (dur is None or r["duration_s"] == dur)]
            if not rows:
                continue
            lines.append("| %s | %s | %d | %d | %s | %s | %s | %s |" % (
                ctl, "all" if dur is None else "%.1f s" % dur, len(rows),
                sum(not r["fell"] for r in rows), mean_of(rows, "heading_dev_deg"),
                mean_of(rows, "foot_slide_m", 100.0), mean_of(rows, "kinetic_energy_j"),
                fallback_of(rows)))
    disturbed = [r["id"] for r in doc["trials"] if r.get("disturbed")]
    if disturbed:
        lines.append("\n%d trial(s) disturbed by the machine's load in every run (late policy "
                     "steps or overruns on CPU time; their result depends on the load): %s" % (
                         len(disturbed), ", ".join(disturbed)))
    return "\n".join(lines) + "\n"


def plot(doc, out_png, duration):
    """Polar plot of dv50 per direction, one curve per controller (gnuplot)."""
    import shutil
    if shutil.which("gnuplot") is None:
        return False
    data = []
    d50 = doc["dv50"]
    ctls = sorted(d50)
    for ctl in ctls:
        pts = d50[ctl].get("%.1f" % duration, {})
        rows = sorted((float(k), v) for k, v in pts.items())
        rows.append(rows[0]) if rows else None  # close the curve
        path = out_png + "." + ctl + ".dat"
        with open(path, "w") as fh:
            for d, v in rows:
                fh.write("%g %g\n" % (d * math.pi / 180.0, v))
        data.append((ctl, path))
    plots = ", ".join("'%s' using 1:2 with linespoints title '%s'" % (p, c) for c, p in data)
    script = ("set terminal png size 700,700; set output '%s'; set polar; set size square;"
              "set title 'dv50 (m/s) per push direction, %.1f s pushes (0 deg = forward)';"
              "set grid polar; unset border; unset xtics; unset ytics; set rrange [0:0.9];"
              "plot %s" % (out_png, duration, plots))
    ok = subprocess.run(["gnuplot", "-e", script]).returncode == 0
    for _, p in data:
        os.remove(p)
    return ok


def main():
    ap = argparse.ArgumentParser(description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = ap.add_subparsers(dest="cmd", required=True)
    j = sub.add_parser("jobs")
    j.add_argument("--controllers", default="stand")
    j.add_argument("--directions", type=int, default=16)
    j.add_argument("--dv", default="0.15,0.30,0.45,0.60,0.80")
    j.add_argument("--durations", default="0.1,0.3")
    j.add_argument("--trials", type=int, default=20)
    j.add_argument("--first-trial", type=int, default=0)
    t = sub.add_parser("trial")
    t.add_argument("spec")
    t.add_argument("--out", required=True)
    t.add_argument("--bin", default=os.path.join(ROOT, "build", "pushstep"))
    m = sub.add_parser("merge")
    m.add_argument("sources", nargs="+", help="directories of trial files, merged .json files")
    m.add_argument("--out", required=True)
    tb = sub.add_parser("table")
    tb.add_argument("file")
    pl = sub.add_parser("plot")
    pl.add_argument("file")
    pl.add_argument("--out", required=True, help="PNG; one per push duration: NAME_0.1s.png")
    a = ap.parse_args()
    if a.cmd == "jobs":
        for spec in grid(a.controllers.split(","), a.directions,
                         [float(x) for x in a.dv.split(",")],
                         [float(x) for x in a.durations.split(",")], a.trials,
                         a.first_trial):
            print("%s,%g,%g,%g,%d" % spec)
        return 0
    if a.cmd == "trial":
        return run_trial(parse_spec(a.spec), a.out, a.bin)
    if a.cmd == "merge":
        try:
            doc = merge(a.sources, a.out)
        except (OSError, ValueError) as e:
            sys.stderr.write("push.py merge: %s\n" % e)
            return 2
        sys.stdout.write(table_md(doc))
        return 0
    if a.cmd == "table":
        sys.stdout.write(table_md(json.load(open(a.file))))
        return 0
    if a.cmd == "plot":
        doc = json.load(open(a.file))
        for dur in sorted({c["duration_s"] for c in doc["cells"]}):
            plot(doc, a.out.replace(".png", "_%.1fs.png" % dur), dur)
        return 0
    return 2


if __name__ == "__main__":
    sys.exit(main())
