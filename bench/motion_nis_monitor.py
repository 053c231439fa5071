"""The on-line NIS check of serve --tracks (issue 36, part 2; docs/motion-fit.md): does it flag a change of traffic
(the manoeuvre noise x4 halfway through a run) within its window, and stay quiet in unchanged runs?

``--runs`` seeded runs of steady traffic (:func:`footprint_uq.tracking.motion_campaigns.traffic_frames`: one camera
and one calibration draw per run, ``--objects`` road users at a time at 30 Hz, each seen for 4 s) tracked with the
one-mode model at the traffic's density, the check evaluated once a second as the health record does.  Writes
JSON; nothing is asserted here (the small seeded version: ``tests/test_motion_fit.py::test_nis_monitor_*``).

    PYTHONPATH=src .venv/bin/python bench/motion_nis_monitor.py [--runs 100] [--json bench/results/motion-nis.json]
"""

from __future__ import annotations

import argparse
import json
import time

import numpy as np

from footprint_uq.tracking.motion_campaigns import monitor_runs


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=100)
    ap.add_argument("--objects", type=int, default=20)
    ap.add_argument("--duration", type=float, default=60.0)
    ap.add_argument("--window", type=float, default=30.0)
    ap.add_argument("--q", type=float, nargs="+", default=[0.5, 2.5])
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--json", default=None)
    a = ap.parse_args(argv)
    half = a.duration / 2
    rows = []
    for q in a.q:
        for label, q_after in (("unchanged", q), ("x4 at half", 4 * q)):
            t0 = time.perf_counter()
            r = monitor_runs(q, q_after, change_s=half, n_runs=a.runs, n_objects=a.objects, duration_s=a.duration,
                             window_s=a.window, seed=a.seed)
            flagged = np.isfinite(r.first_flag_s)
            row = {"q_m2ps3": q, "case": label, "runs": a.runs, "window_s": a.window, "duration_s": a.duration,
                   "flagged": float(flagged.mean()),
                   "flagged_within_window_after_change": float((flagged & (r.first_flag_s >= half)
                                                                & (r.first_flag_s <= half + a.window)).mean()),
                   "delay_after_change_s_median": (float(np.median(r.first_flag_s[flagged] - half))
                                                   if flagged.any() else None),
                   "last_nis_ratio_median": float(np.nanmedian(r.last_ratio)), "elapsed_s": time.perf_counter() - t0}
            rows.append(row)
            print(json.dumps(row), flush=True)
    if a.json:
        with open(a.json, "w") as f:
            json.dump({"seed": a.seed, "objects": a.objects, "rows": rows}, f, indent=1)


if __name__ == "__main__":
    main()
