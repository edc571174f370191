#!/usr/bin/env python3
"""Calibrates the twin on real machines' logs and tabulates it against the
baselines (standard library only).

  scripts/real_logs_study.py RUNS_DIR OUT_DIR [--twin build/bin/twin] [--cross RUN] [--jobs N]

For every run folder in RUNS_DIR: `twin calibrate RUN -o OUT_DIR/RUN` (fitted
on the first 60 % of the rows, judged on the rest), then the held-out NRMS of
each torque channel for the twin, the rigid-body regression and the zero
model, per run and pooled (root of the row-weighted mean square), and the
90 % interval of the twin's NRMS minus the regression's over 1 s blocks of
the rows (report.json's twin_minus_regression). With
--cross RUN: calibrated on RUN alone and validated on every other run (whole
runs, never fitted on), the same table. --jobs N calibrates N runs at once.
Prints markdown tables; each calibration's lag and wall time go to stderr
(with --jobs above 1 the runs share the cores, so their times do too).
"""
import argparse
import concurrent.futures
import json
import math
import os
import subprocess
import sys
import time


def calibrate(twin, runs, out, validate=()):
    cmd = [twin, "calibrate", *runs, "-o", out, "--no-plots"]
    if validate:
        cmd += ["--validate", *validate]
    start = time.monotonic()
    p = subprocess.run(cmd, capture_output=True, text=True)
    wall_s = time.monotonic() - start
    if p.returncode != 0:
        raise SystemExit(f"twin calibrate failed on {runs}: {p.stderr.strip().splitlines()[-1:]}")
    with open(os.path.join(out, "report.json")) as f:
        return json.load(f), wall_s


def table(rows, keys):
    print("| run | channel | rows | twin | rigid-body regression | zero | twin beats regression | "
          "twin - regression, 90 % interval |")
    print("|---|---|---|---|---|---|---|---|")
    pooled = {}
    for name, entry in rows:
        n = entry["rows_compared"]
        for k in keys:
            tw = entry["error_calibrated"].get(k)
            rg = entry["baseline"]["rigid_body_regression"].get(k)
            zr = entry["baseline"]["zero"].get(k)
            if tw is None or rg is None:
                print(f"| {name} | {k} | {n} | {tw} | {rg} | {zr} | not computed | |")
                continue
            d = entry.get("twin_minus_regression", {}).get(k)
            iv = f"{d['interval_90'][0]:+.3f} to {d['interval_90'][1]:+.3f}" if d else "not computed"
            # Where the twin loses the run, the second of rows it loses most in.
            loss = d.get("largest_loss") if d and tw >= rg else None
            if loss:
                iv += f"; loses most {loss['from_s']:.1f} to {loss['to_s']:.1f} s"
            print(f"| {name} | {k} | {n} | {tw:.4g} | {rg:.4g} | {zr:.4g} | {'yes' if tw < rg else 'no'} | {iv} |")
            p = pooled.setdefault(k, [0.0, 0.0, 0])
            p[0] += tw * tw * n
            p[1] += rg * rg * n
            p[2] += n
    for k, (t2, r2, n) in pooled.items():
        t, r = math.sqrt(t2 / n), math.sqrt(r2 / n)
        print(f"| pooled | {k} | {n} | {t:.4g} | {r:.4g} | 1 | {'yes' if t < r else 'no'} | |")


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("runs_dir")
    ap.add_argument("out_dir")
    ap.add_argument("--twin", default="build/bin/twin")
    ap.add_argument("--cross", default=None)
    ap.add_argument("--channels", default="x_i_A,y_i_A")
    ap.add_argument("--jobs", type=int, default=1)
    a = ap.parse_args()
    keys = a.channels.split(",")
    runs = sorted(d for d in os.listdir(a.runs_dir) if os.path.isdir(os.path.join(a.runs_dir, d)))
    os.makedirs(a.out_dir, exist_ok=True)
    if a.cross:
        others = [os.path.join(a.runs_dir, r) for r in runs if r != a.cross]
        rep, wall_s = calibrate(a.twin, [os.path.join(a.runs_dir, a.cross)], os.path.join(a.out_dir, "cross_" + a.cross),
                                others)
        print(f"{a.cross}: calibrated and validated in {wall_s:.0f} s", file=sys.stderr)
        print(f"Calibrated on {a.cross}, validated on the {len(others)} other runs (whole runs):\n")
        table([(os.path.basename(v["run"]), v) for v in rep["validation_runs"]], keys)
        return
    rows = []
    with concurrent.futures.ThreadPoolExecutor(max_workers=max(1, a.jobs)) as pool:
        reports = pool.map(lambda r: calibrate(a.twin, [os.path.join(a.runs_dir, r)], os.path.join(a.out_dir, r)), runs)
    for r, (rep, wall_s) in zip(runs, reports):
        rows.append((r, rep["fit_runs"][0]))
        lag = {ax: p.get("lag_s") for ax, p in rep["parameters_identified"].items()}
        print(f"{r}: lag " + ", ".join(f"{ax} {1e3 * v:.1f} ms" for ax, v in lag.items() if v) +
              f"; calibrated in {wall_s:.0f} s", file=sys.stderr)
    print("Held-out rows of each run (fitted on its first 60 %):\n")
    table(rows, keys)


if __name__ == "__main__":
    main()
