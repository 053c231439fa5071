"""The motion fit's bank alone: the joint (exact) likelihood's members vs the tracker's Schmidt members on the same
seeded frames (docs/motion-fit.md, sections 2a and 4).  Same process, interleaved runs, median; the ratio is the
figure (absolute times follow the machine's load).

    PYTHONPATH=src .venv/bin/python bench/motion_fit_bank_cost.py [--campaigns 20] [--runs 3] [--json out.json]
"""

from __future__ import annotations

import argparse
import json
import time

import numpy as np

from footprint_uq.tracking.motion_campaigns import campaign_frames
from footprint_uq.tracking.motion_fit import MotionBank, MotionGrid
from footprint_uq.tracking.synthetic import default_camera
from footprint_uq.tracking.table import SharedJacobianAt, TrackerConfig, TrackTable
from footprint_uq.uncertainty.budget import load_budget


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--campaigns", type=int, default=20)
    ap.add_argument("--objects", type=int, default=10)
    ap.add_argument("--runs", type=int, default=3)
    ap.add_argument("--json", default=None)
    a = ap.parse_args(argv)
    camera, budget = default_camera(), load_budget("basler1@deg")
    at = SharedJacobianAt(camera, budget)
    grid = MotionGrid()
    frames = list(campaign_frames(0.5, a.campaigns, a.objects, duration_s=4.0, rate_hz=30.0, seed=0, camera=camera))
    assoc = TrackTable(TrackerConfig(), rank=at.rank, shared_at=at)
    outs = [assoc.step(f[0], f[1], f[3], f[4], f[5]) for f in frames]
    times: dict = {"joint": [], "tracker": []}
    for _ in range(a.runs):
        for lik in ("joint", "tracker"):
            bank = MotionBank.from_grid(grid, rank=at.rank, shared_at=at, likelihood=lik)
            bank.observe(*(frames[0][0], outs[0], frames[0][2], *frames[0][3:6]))  # (loads the compiled code)
            t0 = time.perf_counter()
            for f, out in zip(frames[1:], outs[1:], strict=True):
                bank.observe(f[0], out, f[2], f[3], f[4], f[5])
            times[lik].append(time.perf_counter() - t0)
    med = {k: float(np.median(v)) for k, v in times.items()}
    n_upd = (len(frames) - 1) * a.campaigns * a.objects
    row = {"members": int(grid.members()[0].shape[0]), "updates": n_upd, "joint_s": med["joint"],
           "tracker_s": med["tracker"], "ratio_joint_to_tracker": med["joint"] / med["tracker"],
           "joint_us_per_update": 1e6 * med["joint"] / n_upd, "runs": a.runs}
    print(json.dumps(row))
    if a.json:
        with open(a.json, "w") as f:
            json.dump(row, f, indent=1)


if __name__ == "__main__":
    main()
