"""Benchmark of the site planner: time to a plan and met area against a naive layout, in the same run.

The site is the worked example of docs/planning.md (:func:`footprint_uq.planning.intersection.intersection_site_dict`):
the case study's four-way intersection, two 3.5 m lanes per direction, 100 m x 100 m end to end, sampled at
0.5 m (lanes: 95 % semi-major <= 1.75 m; the junction box: <= 1.0 m, weight 2), a 15 m building at one
corner, 12 candidate poles (4 existing corner poles, 8 new ones along the arms), 3 camera types (full HD with
a wide distorted or a normal lens, full-HD telephoto, 4K), pans every 30 deg, tilts 12/20/30 deg, two heights
per pole: 3456 candidate configurations; K = 4 cameras.

Per run: :func:`footprint_uq.planning.optimise.plan` (the default method ``best``, screening every 2nd sample
in both directions, refinement of at most 120 evaluations at full resolution), timed end to end; and the naive layout
(:func:`footprint_uq.planning.intersection.naive_layout`: one camera per arm on the arm's nearer pole, at
the top of its range, boresight on the centre) evaluated on the same samples.  Prints a table and writes
``bench/results/plan.json`` (``--out``).  Goal: a plan in under a minute on the 2-core machine.

    .venv/bin/python bench/bench_plan.py [--runs 3] [--quick] [--out bench/results/plan.json]
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import time
from pathlib import Path

import numpy as np

from footprint_uq.io.atomic import atomic_write_text
from footprint_uq.planning.coverage import evaluate_information
from footprint_uq.planning.intersection import intersection_site_dict, naive_layout
from footprint_uq.planning.optimise import layout_information, plan
from footprint_uq.planning.site import site_from_dict


def run(runs: int = 3, quick: bool = False) -> dict:
    d = intersection_site_dict(resolution_m=1.0 if quick else 0.5)
    if quick:
        d["search"].update({"pan_step_deg": 60.0, "heights_per_mount": 1})
    site = site_from_dict(d)
    load0 = os.getloadavg()
    times, results = [], []
    for _ in range(runs):
        t0 = time.perf_counter()
        res = plan(site, screen_step=2, max_refine_evals=120, seed=0)
        times.append(time.perf_counter() - t0)
        results.append(res)
    res = results[-1]
    t0 = time.perf_counter()
    naive = evaluate_information(site, res.samples, layout_information(site, res.samples, naive_layout(site)))
    t_naive = time.perf_counter() - t0
    return {
        "site": site.name, "samples": len(res.samples), "resolution_m": site.resolution_m,
        "candidates": res.n_candidates, "mounts": len(site.mounts), "camera_types": len(site.cameras),
        "k": len(res.configs), "runs": runs,
        "time_to_plan_s_median": float(np.median(times)), "time_to_plan_s_min": float(np.min(times)),
        "time_to_plan_s_all": times, "stages_s_last_run": res.seconds,
        "goal_s": 60.0, "goal_met": bool(np.median(times) < 60.0),
        "fraction_met_plan": res.evaluation.fraction, "fraction_met_naive": naive.fraction,
        "fraction_met_plan_discrete_only": res.discrete_value / float(res.evaluation.value / res.evaluation.fraction),
        "zones_plan": [z.row() for z in res.evaluation.zones], "zones_naive": [z.row() for z in naive.zones],
        "layout": [c.__dict__ for c in res.configs], "naive_evaluation_s": t_naive,
        "method": res.method, "grid_bound": res.bound, "starts": res.starts,
        "same_layout_every_run": all(r.configs == res.configs for r in results),
        "loadavg_start": load0, "loadavg_end": os.getloadavg(), "cpus": os.cpu_count(),
        "python": platform.python_version(),
    }


def _table(r: dict) -> str:
    lines = [f"site: {r['site']}, {r['samples']} samples at {r['resolution_m']} m, {r['mounts']} poles, "
             f"{r['camera_types']} camera types, {r['candidates']} candidates, K = {r['k']}",
             f"time to a plan: median {r['time_to_plan_s_median']:.1f} s (min {r['time_to_plan_s_min']:.1f} s, "
             f"{r['runs']} runs; goal < {r['goal_s']:.0f} s: {'met' if r['goal_met'] else 'NOT met'}); "
             f"last run: " + ", ".join(f"{k} {v:.1f} s" for k, v in r["stages_s_last_run"].items()),
             f"weighted met area: plan {100 * r['fraction_met_plan']:.1f} % (discrete stage alone "
             f"{100 * r['fraction_met_plan_discrete_only']:.1f} %), naive layout {100 * r['fraction_met_naive']:.1f} %",
             f"load average {r['loadavg_start'][0]:.1f} -> {r['loadavg_end'][0]:.1f} on {r['cpus']} cpus"]
    for zp, zn in zip(r["zones_plan"], r["zones_naive"], strict=True):
        lines.append(f"  {zp['zone']} (<= {zp['requirement_m']:g} m): plan {100 * zp['fraction_met']:.1f} %, "
                     f"naive {100 * zn['fraction_met']:.1f} %")
    lines += ["layout:"] + [f"  {c['mount']}: {c['camera_type']}/{c['lens']} h {c['height_m']:.2f} m, "
                            f"pan {c['pan_deg']:.1f}, tilt {c['tilt_deg']:.1f}" for c in r["layout"]]
    return "\n".join(lines)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=3)
    ap.add_argument("--quick", action="store_true", help="1 m samples, a coarser grid, one run (smoke test)")
    ap.add_argument("--out", default=str(Path(__file__).parent / "results" / "plan.json"))
    a = ap.parse_args()
    r = run(1 if a.quick else a.runs, a.quick)
    print(_table(r))
    out = Path(a.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    atomic_write_text(out, json.dumps(r, indent=2) + "\n")
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
