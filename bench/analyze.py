#!/usr/bin/env python3
"""Analysis side of `make bench` (bench/run.sh). Standard library only.

Parses wake-up latency histograms in the text format of `cyclictest -h N`
(pushstep's wakeup.hist is the same format), merges the blocks of a run,
computes percentiles the same way for both tools, and writes
bench/results/*.json, summary.md and gnuplot data files.

  analyze.py --self-test                 check the parser and the percentiles
  analyze.py stats FILE...               merged figures of histogram files (JSON)
  analyze.py report RUNDIR OUTDIR        RUNDIR/blocks.tsv + conditions.env -> OUTDIR

The cyclictest -h text format (rt-tests 2.x, one thread):
  [# /dev/cpu_dma_latency set to 0us]      optional, cyclictest only
  # Histogram
  000000 000123                            bucket i: latency in [i, i+1) us
  ...                                      (N lines, i = 0..N-1)
  # Total: 000004987                       samples inside the histogram
  # Min Latencies: 00011                   whole us (truncated)
  # Avg Latencies: 00019
  # Max Latencies: 00540                   exact max, also when >= N
  # Histogram Overflows: 00013             samples >= N us
  # Histogram Overflow at cycle number:
  # Thread 0: 01867 02668 [# 00011 others]
"""
import json
import math
import os
import platform
import re
import sys
import time

QUANTILES = (("p50", 0.50), ("p90", 0.90), ("p99", 0.99), ("p999", 0.999))
TARGET_P99_RATIO = 1.10  # issue: wake-up p99 within 10 % of cyclictest's
TARGET_MAX_RATIO = 1.25  # issue: wake-up max within 25 %
TARGET_TICK_P999_SHARE = 0.05  # issue: plain tick p99.9 under 5 % of the period


# ---- histograms ------------------------------------------------------------


def parse_hist(text):
    """One thread's histogram from cyclictest -h text. Returns a dict:
    counts (list, index = us), overflows, min_us, max_us, avg_us (as printed)."""
    counts, fields = [], {}
    for line in text.splitlines():
        line = line.strip()
        if not line:
            continue
        if line.startswith("#"):
            m = re.match(r"#\s*(Total|Min Latencies|Avg Latencies|Max Latencies|"
                         r"Histogram Overflows):\s*(\d+)", line)
            if m:
                fields[m.group(1)] = int(m.group(2))
            continue
        cols = line.split()
        if len(cols) < 2 or not cols[0].isdigit():
            raise ValueError("not a histogram line: %r" % line)
        idx = int(cols[0])
        if idx != len(counts):
            raise ValueError("bucket %d out of order (expected %d)" % (idx, len(counts)))
        counts.append(int(cols[1]))  # first thread column only
    if not counts:
        raise ValueError("no histogram lines")
    total = fields.get("Total")
    if total is not None and total != sum(counts):
        raise ValueError("Total %d != sum of buckets %d" % (total, sum(counts)))
    return {
        "counts": counts,
        "overflows": fields.get("Histogram Overflows", 0),
        "min_us": fields.get("Min Latencies"),
        "max_us": fields.get("Max Latencies"),
        "avg_us_printed": fields.get("Avg Latencies"),
    }


def read_hist(path):
    with open(path) as f:
        return parse_hist(f.read())


def merge(hists):
    """Sum of the blocks: counts and overflows add, min/max are extremes."""
    size = max(len(h["counts"]) for h in hists)
    counts = [0] * size
    for h in hists:
        for i, c in enumerate(h["counts"]):
            counts[i] += c
    mins = [h["min_us"] for h in hists if h["min_us"] is not None]
    maxs = [h["max_us"] for h in hists if h["max_us"] is not None]
    return {
        "counts": counts,
        "overflows": sum(h["overflows"] for h in hists),
        "min_us": min(mins) if mins else None,
        "max_us": max(maxs) if maxs else None,
        "avg_us_printed": None,
    }


def figures(h):
    """Percentiles by nearest rank (the smallest bucket whose cumulative count
    reaches ceil(q * n)), in whole us, the same for every tool. A rank that
    falls among the overflows is reported as None with overflow: true."""
    counts, n_in = h["counts"], sum(h["counts"])
    n = n_in + h["overflows"]
    out = {"n": n, "hist_us": len(counts), "overflows": h["overflows"],
           "min_us": h["min_us"], "max_us": h["max_us"]}
    if n == 0:
        return out
    if h["min_us"] is None:  # no footer: take extremes from the buckets
        out["min_us"] = next(i for i, c in enumerate(counts) if c)
    if h["max_us"] is None and h["overflows"] == 0:
        out["max_us"] = max(i for i, c in enumerate(counts) if c)
    # Mean of the truncated values, as cyclictest's own Avg; None if overflows.
    out["avg_us"] = (round(sum(i * c for i, c in enumerate(counts)) / n, 2)
                     if h["overflows"] == 0 else None)
    for name, q in QUANTILES:
        rank = max(1, math.ceil(q * n))
        acc, val = 0, None
        for i, c in enumerate(counts):
            acc += c
            if acc >= rank:
                val = i
                break
        out[name + "_us"] = val
        if val is None:
            out[name + "_overflow"] = True
    return out


def ratio(a, b):
    if a is None or b is None or b == 0:
        return None
    return round(a / b, 3)


# ---- self-test -------------------------------------------------------------

SAMPLE = """# /dev/cpu_dma_latency set to 0us
# Histogram
000000 000000
000001 000000
000002 000010
000003 000070
000004 000015
000005 000004
# Total: 000000099
# Min Latencies: 00002
# Avg Latencies: 00003
# Max Latencies: 00012
# Histogram Overflows: 00001
# Histogram Overflow at cycle number:
# Thread 0: 00042

"""


def self_test():
    h = parse_hist(SAMPLE)
    f = figures(h)
    checks = [
        (f["n"], 100), (f["overflows"], 1), (f["min_us"], 2), (f["max_us"], 12),
        (f["p50_us"], 3),     # rank 50: 10 + 70 >= 50 at bucket 3
        (f["p90_us"], 4),     # rank 90: 80 < 90 <= 95 at bucket 4
        (f["p99_us"], 5),     # rank 99: 95 < 99 <= 99 at bucket 5
        (f["p999_us"], None),  # rank 100: the overflow sample
        (f.get("p999_overflow"), True),
    ]
    m = figures(merge([h, parse_hist(SAMPLE.replace("00012", "00020"))]))
    checks += [(m["n"], 200), (m["max_us"], 20), (m["p50_us"], 3), (m["p99_us"], 5)]
    # pushstep's writer: no dma line, no blank line at the end, wider table.
    ps = "# Histogram\n" + "".join("%06d %06d\n" % (i, 5 if i in (7, 9) else 0)
                                   for i in range(1000))
    ps += ("# Total: 000000010\n# Min Latencies: 00007\n# Avg Latencies: 00008\n"
           "# Max Latencies: 00009\n# Histogram Overflows: 00000\n"
           "# Histogram Overflow at cycle number:\n# Thread 0:\n")
    p = figures(parse_hist(ps))
    checks += [(p["n"], 10), (p["hist_us"], 1000), (p["p50_us"], 7), (p["p99_us"], 9),
               (p["avg_us"], 8.0), (ratio(9, 12), 0.75)]
    for bad in ("# Histogram\n000001 000003\n",  # out of order
                "# Histogram\n000000 000003\n# Total: 000000004\n"):  # wrong total
        try:
            parse_hist(bad)
            checks.append(("no error for %r" % bad, "ValueError"))
        except ValueError:
            pass
    failed = [(got, want) for got, want in checks if got != want]
    for got, want in failed:
        print("self-test: got %r, want %r" % (got, want), file=sys.stderr)
    print("self-test: %d checks, %d failed" % (len(checks), len(failed)))
    return 1 if failed else 0


# ---- report ----------------------------------------------------------------


def read_env(path):
    env = {}
    if os.path.exists(path):
        with open(path) as f:
            for line in f:
                if "=" in line:
                    k, v = line.rstrip("\n").split("=", 1)
                    env[k] = v
    return env


def read_blocks(path):
    """blocks.tsv: section, tool, block, path, wall_s, command."""
    rows = []
    with open(path) as f:
        for line in f:
            cols = line.rstrip("\n").split("\t")
            if len(cols) >= 6 and not line.startswith("#"):
                rows.append({"section": cols[0], "tool": cols[1], "block": int(cols[2]),
                             "path": cols[3], "wall_s": float(cols[4]), "command": cols[5]})
    return rows


def hist_path(row):
    return os.path.join(row["path"], "wakeup.hist") if row["tool"] == "pushstep" else row["path"]


def load_profile(row):
    with open(os.path.join(row["path"], "profile.json")) as f:
        return json.load(f)


def machine(env):
    def first(path, pattern=None):
        try:
            with open(path) as f:
                for line in f:
                    if pattern is None:
                        return line.strip()
                    if line.startswith(pattern):
                        return line.split(":", 1)[1].strip()
        except OSError:
            return None
        return None
    return {
        "kernel": platform.release(),
        "kernel_version": platform.version(),
        "arch": platform.machine(),
        "cpu_model": first("/proc/cpuinfo", "model name") or first("/proc/cpuinfo", "Model"),
        "nproc": os.cpu_count(),
        "governor": first("/sys/devices/system/cpu/cpu%s/cpufreq/scaling_governor"
                          % env.get("cpu", "0")),
        "cpuidle_driver": first("/sys/devices/system/cpu/cpuidle/current_driver"),
        "preempt_rt": os.path.exists("/sys/kernel/realtime"),
        "cmdline": first("/proc/cmdline"),
        "sched_rt_runtime_us": first("/proc/sys/kernel/sched_rt_runtime_us"),
    }


def latency_section(rows, section, out_dir, env):
    """Both tools' merged figures for one section, the ratios, the blocks."""
    res = {"section": section, "tools": {}, "blocks": []}
    for tool in ("pushstep", "cyclictest"):
        mine = [r for r in rows if r["section"] == section and r["tool"] == tool]
        if not mine:
            continue
        hists = [read_hist(hist_path(r)) for r in mine]
        merged = merge(hists)
        res["tools"][tool] = figures(merged)
        res["tools"][tool]["n_blocks"] = len(mine)
        res["tools"][tool]["command"] = mine[0]["command"]
        p99s = [figures(h)["p99_us"] for h in hists]
        p99s = [v for v in p99s if v is not None]
        if p99s:  # block-to-block spread: how far apart two runs of one tool fall
            res["tools"][tool]["p99_us_block_range"] = [min(p99s), max(p99s)]
        for r, h in zip(mine, hists):
            f = figures(h)
            res["blocks"].append({"tool": tool, "block": r["block"], "n": f["n"],
                                  "p50_us": f["p50_us"], "p99_us": f["p99_us"],
                                  "max_us": f["max_us"], "wall_s": r["wall_s"]})
        with open(os.path.join(out_dir, "%s_%s.dat" % (section, tool)), "w") as f:
            f.write("# us count (merged %d blocks)\n" % len(mine))
            for i, c in enumerate(merged["counts"]):
                f.write("%d %d\n" % (i, c))
    res["blocks"].sort(key=lambda b: (b["block"], b["tool"]))
    ps, ct = res["tools"].get("pushstep"), res["tools"].get("cyclictest")
    if ps and ct:
        res["ratio"] = {k: ratio(ps[k + "_us"], ct[k + "_us"])
                        for k in ("p50", "p99", "p999", "max")}
        res["target"] = {"p99_ratio_max": TARGET_P99_RATIO, "max_ratio_max": TARGET_MAX_RATIO}
        res["is_p99_within_target"] = (res["ratio"]["p99"] is not None
                                       and res["ratio"]["p99"] <= TARGET_P99_RATIO)
        res["is_max_within_target"] = (res["ratio"]["max"] is not None
                                       and res["ratio"]["max"] <= TARGET_MAX_RATIO)
    res["conditions"] = {k: env.get(k) for k in (
        "rt", "priority", "cpu", "main_cpu", "interval_us", "hist_us", "block_s",
        "n_pairs", "order", "dma_latency_held") if env.get(k) is not None}
    if section != "latency":  # stress_<kind>: same load command for both tools
        res["conditions"].update(stress=section.replace("stress_", ""),
                                 stress_cmd=env.get("stress_cmd"),
                                 block_s=env.get("stress_block_s"),
                                 n_pairs=env.get("stress_n_pairs"))
    # pushstep's own log-linear estimate of the same samples, as a cross-check.
    profs = [load_profile(r) for r in rows if r["section"] == section and r["tool"] == "pushstep"]
    if profs:
        res["pushstep_self_reported_wake_per_block"] = [
            {k: p["latency"]["wake"].get(k) for k in ("n", "p50_us", "p99_us", "max_us")}
            for p in profs]
        res["pushstep_profile"] = profs[0].get("profile")
    return res


def tick_section(profs):
    period_us = profs[0]["profile"]["period_us"]
    res = {"period_us": period_us, "n_blocks": len(profs),
           "aggregate": "worst block for each percentile (percentiles of separate runs"
                        " cannot be merged exactly)", "stages": {}}
    for stage in ("tick_plain", "tick_policy", "tick"):
        per = [p["latency"].get(stage) for p in profs]
        per = [s for s in per if s and s.get("n")]
        if not per:
            continue
        worst = {k: max(s[k] for s in per) for k in ("p50_us", "p99_us", "p999_us", "max_us")}
        res["stages"][stage] = {
            "n": sum(s["n"] for s in per),
            **{k: round(v, 3) for k, v in worst.items()},
            **{k.replace("_us", "_share"): round(v / period_us, 5) for k, v in worst.items()},
            "per_block": [{k: s[k] for k in ("n", "p50_us", "p99_us", "p999_us", "max_us")}
                          for s in per],
        }
    plain = res["stages"].get("tick_plain")
    if plain:
        res["target_p999_share"] = TARGET_TICK_P999_SHARE
        res["is_plain_p999_within_target"] = plain["p999_share"] < TARGET_TICK_P999_SHARE
    return res


def bus_section(profs):
    res = {"n_blocks": len(profs), "buses": []}
    for i, b in enumerate(profs[0].get("buses", [])):
        obs = [p["buses"][i]["observed_load"] for p in profs if len(p.get("buses", [])) > i]
        late = sum(p["buses"][i].get("late_frames", 0) for p in profs if len(p["buses"]) > i)
        res["buses"].append({
            "name": b["name"], "capacity_bit_s": b["bitrate"],
            "planned_peak_tick_load": b["planned_peak_tick_load"],
            "planned_avg_load": b["planned_avg_load"],
            "observed_load_min": round(min(obs), 4), "observed_load_max": round(max(obs), 4),
            "observed_bit_s_max": round(max(obs) * b["bitrate"]),
            "observed_over_planned_avg": ratio(max(obs), b["planned_avg_load"]),
            "late_frames": late,
        })
    return res


def alloc_section(profs, rows):
    per = [{"section": r["section"], "block": r["block"], "ticks": p["ticks"],
            **{k: p["after_init"].get(k) for k in ("mallocs", "frees", "page_faults",
                                                   "allocations_counted")}}
           for r, p in profs]
    tot = {k: sum(b[k] or 0 for b in per) for k in ("ticks", "mallocs", "frees", "page_faults")}
    return {"runs": len(per), **tot, "is_zero": tot["mallocs"] == 0 and tot["frees"] == 0
            and tot["page_faults"] == 0,
            "is_counted_everywhere": all(b["allocations_counted"] for b in per),
            "per_run": per}


def fmt(v, unit=""):
    if v is None:
        return "n/a"
    if isinstance(v, float):
        return "%.3g%s" % (v, unit)
    return "%s%s" % (v, unit)


def pct(v):
    return "n/a" if v is None else "%.2f %%" % (100.0 * v)


def summary_md(env, mach, lat, tick, bus, alloc):
    L = ["# pushstep bench results", ""]
    L.append("Date: %s; bench wall time %s s. Written by `make bench` (bench/run.sh, "
             "bench/analyze.py); docs/latency.md explains every figure."
             % (env.get("date", time.strftime("%Y-%m-%d %H:%M:%S %z")), env.get("wall_s", "?")))
    L += ["", "## Machine", "", "| | |", "|---|---|"]
    L.append("| kernel | %s (%s), PREEMPT_RT: %s |" % (mach["kernel"], mach["kernel_version"],
                                                      "yes" if mach["preempt_rt"] else "no"))
    L.append("| CPU | %s, %s CPUs (%s) |" % (mach["cpu_model"], mach["nproc"], mach["arch"]))
    L.append("| governor (loop CPU) | %s |" % (mach["governor"] or "not readable"))
    L.append("| cpuidle driver | %s |" % (mach["cpuidle_driver"] or "none"))
    L.append("| RT privileges | %s |" % env.get("rt_detail", env.get("rt")))
    L.append("| /dev/cpu_dma_latency held at 0 for both tools | %s |"
             % env.get("dma_latency_held", "?"))
    L.append("| sched_rt_runtime_us | %s |" % mach["sched_rt_runtime_us"])
    L.append("| kernel command line | `%s` |" % mach["cmdline"])
    for name, sec in lat:
        ps, ct = sec["tools"].get("pushstep"), sec["tools"].get("cyclictest")
        c = sec["conditions"]
        L += ["", "## Wake-up latency%s, pushstep beside cyclictest" %
              ("" if name == "latency" else " under stress-ng --" + c.get("stress", "")), ""]
        L.append("%s pairs of %s s blocks, order %s, interval %s us, priority %s, CPU %s; "
                 "merged 1-us histograms (%s buckets), nearest-rank percentiles, whole us."
                 % (c.get("n_pairs"), c.get("block_s"), c.get("order"), c.get("interval_us"),
                    c.get("priority") if env.get("rt") == "yes" else "none (SCHED_OTHER)",
                    c.get("cpu"), c.get("hist_us")))
        if not ct:
            L.append("cyclictest did not run (it needs RT privileges): no ratios.")
        if c.get("stress_cmd"):
            L.append("Load for both tools: `%s`." % c["stress_cmd"])
        L += ["", "| figure | pushstep | cyclictest | pushstep / cyclictest | target |",
              "|---|---|---|---|---|"]
        tgt = {"p99": "<= %.2f" % TARGET_P99_RATIO, "max": "<= %.2f" % TARGET_MAX_RATIO}
        for k, label in (("n", "samples"), ("min", "min"), ("avg", "avg"), ("p50", "p50"),
                         ("p90", "p90"), ("p99", "p99"), ("p999", "p99.9"), ("max", "max")):
            key = k if k == "n" else k + "_us"
            unit = "" if k == "n" else " us"
            rr = ratio((ps or {}).get(key), (ct or {}).get(key))
            L.append("| %s | %s | %s | %s | %s |" % (label, fmt((ps or {}).get(key), unit),
                                                     fmt((ct or {}).get(key), unit), fmt(rr),
                                                     tgt.get(k, "")))
        if ps and ct and ps.get("p99_us_block_range") and ct.get("p99_us_block_range"):
            L.append("| p99 of single blocks | %d..%d us | %d..%d us | | |"
                     % tuple(ps["p99_us_block_range"] + ct["p99_us_block_range"]))
        if ps and ct:
            L.append("| overflows (>= %s us) | %s | %s | | |" % (ps["hist_us"], ps["overflows"],
                                                                ct["overflows"]))
        L += ["", "Per block (p99 / max, us): " + "; ".join(
            "%d %s %s/%s" % (b["block"], b["tool"][0], fmt(b["p99_us"]), fmt(b["max_us"]))
            for b in sec["blocks"]) + " (p = pushstep, c = cyclictest)."]
    if tick:
        L += ["", "## Tick compute time (read to write) as a share of the %s us period"
              % tick["period_us"], "",
              "Worst of %d blocks for each percentile (no load)." % tick["n_blocks"], "",
              "| stage | n | p50 | p99 | p99.9 | max | p99.9 / period | target |",
              "|---|---|---|---|---|---|---|---|"]
        for st, s in tick["stages"].items():
            L.append("| %s | %d | %.1f us (%s) | %.1f us (%s) | %.1f us (%s) | %.1f us (%s) | %s | %s |"
                     % (st, s["n"], s["p50_us"], pct(s["p50_share"]), s["p99_us"],
                        pct(s["p99_share"]), s["p999_us"], pct(s["p999_share"]), s["max_us"],
                        pct(s["max_share"]), pct(s["p999_share"]),
                        "< 5 %" if st == "tick_plain" else ""))
    if bus:
        L += ["", "## CAN bus load beside the wire's capacity", "",
              "| bus | capacity | planned peak tick | planned avg | observed (min..max of "
              "%d runs) | observed / planned avg | late frames |" % bus["n_blocks"],
              "|---|---|---|---|---|---|---|"]
        for b in bus["buses"]:
            L.append("| %s | %d kbit/s | %s | %s | %s..%s (%d kbit/s) | %s | %d |" % (
                b["name"], b["capacity_bit_s"] // 1000, pct(b["planned_peak_tick_load"]),
                pct(b["planned_avg_load"]), pct(b["observed_load_min"]),
                pct(b["observed_load_max"]), b["observed_bit_s_max"] // 1000,
                fmt(b["observed_over_planned_avg"]), b["late_frames"]))
    if alloc:
        L += ["", "## Allocations and page faults on the loop thread after init", "",
              "| runs | ticks | mallocs | frees | page faults | peer (must be) |",
              "|---|---|---|---|---|---|",
              "| %d | %d | %d | %d | %d | 0 / 0 / 0: %s |" % (
                  alloc["runs"], alloc["ticks"], alloc["mallocs"], alloc["frees"],
                  alloc["page_faults"], "met" if alloc["is_zero"] else "NOT met")]
        if not alloc["is_counted_everywhere"]:
            L.append("\nSome runs could not count allocations (see alloc.json).")
    L += ["", "## Commands", ""]
    for line in env.get("commands", "").split(" ;; "):
        if line:
            L.append("    " + line)
    L.append("")
    return "\n".join(L)


def report(run_dir, out_dir):
    env = read_env(os.path.join(run_dir, "conditions.env"))
    rows = read_blocks(os.path.join(run_dir, "blocks.tsv"))
    os.makedirs(out_dir, exist_ok=True)
    mach = machine(env)
    lat = []
    for section in sorted({r["section"] for r in rows}, key=lambda s: (s != "latency", s)):
        sec = latency_section(rows, section, out_dir, env)
        sec["machine"] = mach
        name = "latency.json" if section == "latency" else "latency_%s.json" % section
        with open(os.path.join(out_dir, name), "w") as f:
            json.dump(sec, f, indent=2)
        lat.append((section, sec))
    ps_rows = [r for r in rows if r["tool"] == "pushstep"]
    profs = [(r, load_profile(r)) for r in ps_rows]
    quiet = [p for r, p in profs if r["section"] == "latency"] or [p for _, p in profs]
    tick = tick_section(quiet) if quiet else None
    bus = bus_section(quiet) if quiet else None
    alloc = alloc_section(profs, ps_rows) if profs else None
    for name, obj in (("tick.json", tick), ("bus.json", bus), ("alloc.json", alloc)):
        if obj is not None:
            with open(os.path.join(out_dir, name), "w") as f:
                json.dump(obj, f, indent=2)
    md = summary_md(env, mach, lat, tick, bus, alloc)
    with open(os.path.join(out_dir, "summary.md"), "w") as f:
        f.write(md)
    print(md)
    # Without RT privileges cyclictest cannot run: pushstep's figures alone are
    # still a result (summary.md says why the peer column is empty).
    ok = all(sec["tools"].get("pushstep") for _, sec in lat)
    return 0 if ok and tick and alloc else 1


def main(argv):
    if len(argv) >= 2 and argv[1] == "--self-test":
        return self_test()
    if len(argv) >= 3 and argv[1] == "stats":
        print(json.dumps(figures(merge([read_hist(p) for p in argv[2:]])), indent=2))
        return 0
    if len(argv) == 4 and argv[1] == "report":
        return report(argv[2], argv[3])
    print(__doc__, file=sys.stderr)
    return 2


if __name__ == "__main__":
    sys.exit(main(sys.argv))
