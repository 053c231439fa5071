"""A service frame's walk through the package's layers: which modules one ``Service.process_frame_json`` call
runs, in order, and how often it climbs back up a layer (a return from a lower layer to a higher one).

Standalone (not a section of ``run.py``; it measures structure, not time)::

    PYTHONPATH=src .venv/bin/python bench/frame_walk.py [--tracks] [--objects 100] [--record full|compact]

The walk is taken with ``sys.setprofile`` on the third frame of a warmed service (100 2-D boxes with a pixel
covariance): every Python-level call and return inside ``footprint_uq`` (the compiled kernels' own code is not
Python and does not appear), consecutive repeats of one module merged.  Layers from the floor up, as
docs/architecture.md orders them: ``fast`` and the leaves (0), ``cameras`` (1), ``uncertainty`` and ``io`` (2),
``products`` (3), ``tracking`` (4), ``service`` (5).
"""

from __future__ import annotations

import argparse
import collections
import sys

import numpy as np
import orjson

from footprint_uq import PanTiltCamera
from footprint_uq.service import Service

RANK = {"fast": 0, "params": 0, "status": 0, "v2x_codes": 0, "_checks": 0, "errors": 0, "_notices": 0,
        "_numba_cache": 0, "cameras": 1, "uncertainty": 2, "io": 2, "products": 3, "tracking": 4, "service": 5}


def _frame(rng, i: int, n: int) -> bytes:
    u, v = rng.uniform(100, 1700, n), rng.uniform(500, 1070, n)
    return orjson.dumps({"frame": i, "timestamp_s": 1714564800.0 + i / 30, "detections": [
        {"object_id": k, "class": "car", "u_min_px": float(a), "v_min_px": float(b - 80), "u_max_px": float(a + 90),
         "v_max_px": float(b), "cov_uu_px2": 4.0, "cov_uv_px2": 0.0, "cov_vv_px2": 4.0}
        for k, (a, b) in enumerate(zip(u, v, strict=True))]})


def _module(frame) -> str | None:
    name = frame.f_globals.get("__name__", "")
    if not name.startswith("footprint_uq."):
        return None
    return name.split(".", 1)[1]


def walk(svc: Service, data: bytes) -> list[str]:
    """The modules one ``process_frame_json(data)`` runs, in order (consecutive repeats merged)."""
    out: list[str] = []

    def prof(frame, event, arg):
        if event not in ("call", "return"):
            return
        g = frame if event == "call" else frame.f_back  # a return goes back to the caller's module
        while g is not None and _module(g) is None:
            g = g.f_back
        if g is not None and (not out or out[-1] != _module(g)):
            out.append(_module(g))

    sys.setprofile(prof)
    try:
        svc.process_frame_json(data)
    finally:
        sys.setprofile(None)
    return out


def climbs(modules: list[str]) -> list[tuple[str, str]]:
    """The steps of a walk from a lower layer to a higher one."""
    def rank(m):
        return RANK.get(m.split(".")[0], 9)
    return [(a, b) for a, b in zip(modules, modules[1:], strict=False) if rank(b) > rank(a)]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--tracks", action="store_true", help="a tracked service (positions + motion)")
    ap.add_argument("--objects", type=int, default=100)
    ap.add_argument("--record", choices=("full", "compact"), default="full", help="the record's layout")
    a = ap.parse_args(argv)
    cam = PanTiltCamera(focal_px=1400, image_size_px=(1920, 1080), height_m=8.0, pan_deg=30.0, tilt_deg=20.0)
    svc = Service(cam, "basler1", tracks=a.tracks, record=a.record)
    rng = np.random.default_rng(0)
    for i in range(2):
        svc.process_frame_json(_frame(rng, i, a.objects))
    mods = walk(svc, _frame(rng, 2, a.objects))
    up = climbs(mods)
    print("walk:", " > ".join(mods))
    print(f"climbs back up: {len(up)}")
    for lo, hi in up:
        print(f"  {lo} -> {hi}")
    print("module visits:", ", ".join(f"{m} {n}" for m, n in collections.Counter(mods).most_common()))
    return 0


if __name__ == "__main__":
    sys.exit(main())
