"""Ghosts and duplicates in the CP service's object list: bench/bench_cp_serve.py's 8 cameras x 100 road users in
one process (bench/cp_serve_profile.py's path: ``Service`` with ``--tracks`` and the CP service), every generation
event's objects scored against the road users at the event's referenceTime.

    PYTHONPATH=src .venv/bin/python bench/cp_ghosts.py [--seconds 10] [--fusion-from REV] [--json PATH]

Per event (:func:`footprint_uq.tracking.rsu_synthetic.score_positions`): a *ghost* is a reported object farther than
3 m from every road user; a *duplicate* is a road user nearest to 2 or more reported objects within 3 m (each object
counted for its nearest road user).  ``--fusion-from REV``: the same frames also through ``RsuFusion`` of git revision
REV (before / after in one run).
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
from pathlib import Path

import numpy as np
import orjson
from bench_cp_serve import RATE_HZ, frame_bodies, road_users, site, write_site
from cp_serve_profile import build, old_fusion, payloads_of, run_once

HERE = Path(__file__).resolve().parent


def score(records: list, t0: float) -> dict:
    """Ghosts and duplicates per event of ``records`` (the events' JSON records) against the road users."""
    from footprint_uq.tracking.rsu_synthetic import score_positions

    xy_at, _ = road_users()
    ghosts, dups, n_obj = [], [], []
    for rec in records:
        xy = np.array([o["xy_m"] for o in rec["objects"]], np.float64).reshape(-1, 2)
        g, d = score_positions(xy, xy_at(rec["time_s"] - t0)[0])
        ghosts.append(g)
        dups.append(d)
        n_obj.append(len(xy))
    g, d, n = np.array(ghosts), np.array(dups), np.array(n_obj)
    return {"events": len(records), "objects_per_event_p50": float(np.median(n)) if n.size else 0.0,
            "objects_per_event_max": int(n.max()) if n.size else 0,
            "ghosts_per_event_mean": round(float(g.mean()), 3), "ghosts_per_event_max": int(g.max()),
            "ghost_share": round(float(g.sum() / max(n.sum(), 1)), 4),
            "duplicates_per_event_mean": round(float(d.mean()), 3), "duplicates_per_event_max": int(d.max()),
            "events_with_ghosts": int((g > 0).sum()), "events_with_duplicates": int((d > 0).sum())}


def run(reg: Path, bodies: list, t0: float) -> dict:
    svc, out, sink = build(reg, True, keep=True)
    run_once(svc, out, payloads_of(bodies, t0))
    records = [orjson.loads(data) for sub, data in sink.kept if sub.endswith("events")]
    return score(records, t0)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seconds", type=float, default=10.0)
    ap.add_argument("--fusion-from", default=None, metavar="REV")
    ap.add_argument("--json", type=Path, default=None)
    args = ap.parse_args(argv)
    import footprint_uq.service.cp_service as cps_mod

    bodies = frame_bodies(site(), int(round(args.seconds * RATE_HZ)))
    fusions = {"now": cps_mod.RsuFusion}
    if args.fusion_from:
        fusions[args.fusion_from] = old_fusion(args.fusion_from)
    res = {"seconds": args.seconds}
    with tempfile.TemporaryDirectory() as d:
        reg = write_site(Path(d), site())
        for key, cls in fusions.items():
            cps_mod.RsuFusion = cls
            res[key] = run(reg, bodies, 1.75e9)
        cps_mod.RsuFusion = fusions["now"]
    text = json.dumps(res, indent=1)
    if args.json is not None:
        from footprint_uq.io.atomic import atomic_write_text

        atomic_write_text(args.json, text + "\n")
    print(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
