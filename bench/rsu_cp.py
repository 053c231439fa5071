"""The CP basic service of one roadside unit (service/cp_service.py, docs/rsu-fusion.md "The CP basic service").

Three parts, all seeded, all in one process:

* ``load``: ``--cameras`` (8) cameras at ``--rate`` (30 Hz) that each see the same ``--objects`` (100) road users
  (the fusion's worst case: every object has 8 contributions), for ``--seconds`` (20 s) of traffic, CPMs at
  ``T_GenCpm`` 0.1 s.  The cameras' tracks are given (truth + a per-camera bias + noise; 60 % of the objects drive
  at 5-15 m/s, 30 % are parked, 10 % are persons walking at 1.4 m/s): the trackers' own cost is not in these
  figures.  Measured: CPU seconds per second of traffic (``time.process_time``: ingest, poll, all of it), the CPU
  time of one ``ingest`` (a camera frame) and of one ``poll`` that made an event (p50 / p99; CPU, not wall time:
  the machine is shared, and wall time would count other processes), CPM segment sizes (bytes), segments per
  event and objects sent per event, and the time from a frame's ingest to its CPM bytes: ``(event time - frame
  time)`` (the wait for the next generation event, traffic clock) + the frame's ingest CPU time + the event's
  poll CPU time (p50 / p99; a real-time loop on a core of its own that keeps up).  Radio access is not in it.
* ``identity``: the 3-camera intersection through the service (:mod:`footprint_uq.service.cp_intersection`),
  ``--frames`` (1,000) unit frames at 10 Hz: duplicates, missing vehicles, mixed objects at every event.
* ``coverage``: ``--runs`` independent runs of ``--run-frames`` frames: how often an event's fused 95 % ellipse
  (predicted to referenceTime) holds the truth, and its sampling sd over runs (a seeded bootstrap of the runs).

    PYTHONPATH=src .venv/bin/python bench/rsu_cp.py [--seconds 20] [--runs 200] [--run-frames 150]
        [--parts load,identity,coverage] [--json bench/results/rsu_cp.json]

Nothing is asserted here (the small seeded versions: tests/test_cp_service.py).
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import time

import numpy as np

from footprint_uq.service.cp_intersection import T0_UNIX_S, run_intersection
from footprint_uq.service.cp_service import CpBasicService, CpCamera
from footprint_uq.tracking.rsu_synthetic import RsuSimResult
from footprint_uq.tracking.table import TrackOutput


def _pct(a, qs=(50, 99)) -> dict:
    a = np.asarray(a, dtype=float)
    return {f"p{q}": float(np.percentile(a, q)) for q in qs} if a.size else {}


def _scene(n: int, rng):
    """Start positions, velocities and classes of the n road users (docstring)."""
    kind = rng.random(n)
    xy0 = np.column_stack([rng.uniform(-80, 80, n), rng.uniform(-80, 80, n)])
    heading = rng.uniform(0, 2 * np.pi, n)
    speed = np.where(kind < 0.6, rng.uniform(5, 15, n), np.where(kind < 0.9, 0.0, 1.4))
    v = speed[:, None] * np.column_stack([np.cos(heading), np.sin(heading)])
    classes = ["car" if k < 0.9 else "person" for k in kind]
    return xy0, v, classes


def load(n_cameras: int = 8, rate_hz: float = 30.0, n_objects: int = 100, seconds: float = 20.0,
         seed: int = 0) -> dict:
    """The ``load`` part (module doc)."""
    rng = np.random.default_rng(seed)
    cams = [CpCamera(f"cam{j}", j + 1, None, clock_offset_sigma_s=0.002) for j in range(n_cameras)]
    svc = CpBasicService(cams, station_id=77, origin_lat_deg=48.1, origin_lon_deg=11.5)
    xy0, v, classes = _scene(n_objects, rng)
    bias = rng.normal(0, 0.15, (n_cameras, 2))  # within the stated 0.3 m sigma
    cov = np.broadcast_to(0.09 * np.eye(2), (n_objects, 2, 2)).copy()
    cov_v = np.broadcast_to(0.3 * np.eye(2), (n_objects, 2, 2)).copy()
    ingest_s, poll_s, frame_lat, seg_bytes, seg_count, sent = [], [], [], [], [], []
    pending: list = []  # (frame time, its ingest wall s) waiting for an event
    n_frames = int(round(seconds * rate_hz))
    phase = rng.uniform(0, 1.0 / rate_hz, n_cameras)  # the cameras are not synchronised
    schedule = sorted((k / rate_hz + phase[j], j) for k in range(n_frames) for j in range(n_cameras))
    cpu0 = time.process_time()
    for t_rel, j in schedule:
        t = T0_UNIX_S + t_rel
        xy = xy0 + v * t_rel + bias[j] + rng.normal(0, 0.1, (n_objects, 2))
        tracks = TrackOutput(np.arange(n_objects), np.zeros(n_objects, bool),
                             np.full(n_objects, int(t_rel * rate_hz) + 1), np.full(n_objects, t_rel), xy, cov,
                             v + rng.normal(0, 0.2, (n_objects, 2)), cov_v)
        w0 = time.process_time()
        svc.ingest(cams[j].camera_id, t, tracks, class_id=classes, linear_ok=np.ones(n_objects, bool),
                   detection_confidence=np.full(n_objects, 0.9))
        w1 = time.process_time()
        ev = svc.poll(t)
        w2 = time.process_time()
        ingest_s.append(w1 - w0)
        pending.append((t, w1 - w0))
        if ev is None:
            continue
        poll_s.append(w2 - w1)
        if ev.segments:
            seg_bytes += [len(s) for s in ev.segments]
            seg_count.append(len(ev.segments))
            sent.append(ev.record["counts"]["sent"])
            frame_lat += [(ev.time_s - tf) + wi + (w2 - w1) for tf, wi in pending]
        pending = []
    cpu = time.process_time() - cpu0
    return {"cameras": n_cameras, "rate_hz": rate_hz, "objects": n_objects, "seconds": seconds,
            "camera_frames": len(schedule), "events": svc.counts()["events"], "cpu_s_per_s": cpu / seconds,
            "ingest_ms": {k: 1e3 * x for k, x in _pct(ingest_s).items()},
            "poll_ms": {k: 1e3 * x for k, x in _pct(poll_s).items()},
            "segment_bytes": {**_pct(seg_bytes, (0, 50, 99, 100)), "mean": float(np.mean(seg_bytes))},
            "segments_per_event": {str(k): int(c) for k, c in enumerate(np.bincount(seg_count)) if c},
            "objects_sent_per_event": _pct(sent, (0, 50, 99, 100)),
            "frame_to_cpm_ms": {k: 1e3 * x for k, x in _pct(frame_lat).items()},
            "fused_objects": len(svc.fusion), "counts": svc.counts()}


def _row(r: RsuSimResult, seconds: float) -> dict:
    d = dataclasses.asdict(r)
    d.update(coverage=r.coverage, coverage_multi=r.coverage_multi, coverage_camera=r.coverage_camera,
             seconds=round(seconds, 1))
    return d


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cameras", type=int, default=8)
    ap.add_argument("--rate", type=float, default=30.0)
    ap.add_argument("--objects", type=int, default=100)
    ap.add_argument("--seconds", type=float, default=20.0)
    ap.add_argument("--frames", type=int, default=1000)
    ap.add_argument("--runs", type=int, default=200)
    ap.add_argument("--run-frames", type=int, default=150)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--parts", default="load,identity,coverage", help="comma-separated parts to run")
    ap.add_argument("--json", default="bench/results/rsu_cp.json")
    a = ap.parse_args(argv)
    parts = set(a.parts.split(","))
    out: dict = {}
    if "load" in parts:
        load(2, 10.0, 10, 1.0)  # compile / warm the kernels before timing
        out["load"] = load(a.cameras, a.rate, a.objects, a.seconds, a.seed)
        print(f"load: {json.dumps({k: v for k, v in out['load'].items() if k != 'counts'})}", flush=True)
    if parts & {"identity", "coverage"}:
        _intersection(a, parts, out)
    if a.json:  # the parts run replace theirs in the file, the others are kept
        try:
            with open(a.json) as fh:
                old = json.load(fh)
        except (OSError, ValueError):
            old = {}
        with open(a.json, "w") as fh:
            json.dump({**old, **out}, fh, indent=1)
    return out


def _intersection(a, parts: set, out: dict) -> None:
    if "identity" not in parts:
        return _coverage(a, out)
    t0 = time.perf_counter()
    r = run_intersection(a.frames, seed=a.seed)
    f = r.fused
    out["identity"] = {**_row(f, time.perf_counter() - t0), "events": r.events, "events_with_cpm": r.events_with_cpm,
                       "segment_bytes": _pct(r.segment_bytes, (0, 50, 99, 100)), "counts": r.counts,
                       "ghosts": int(sum(r.ghosts)), "duplicates_by_position": int(sum(r.duplicates))}
    print(f"identity: {a.frames} frames, {f.n_truth_frames} (event, vehicle) pairs: duplicates {f.n_duplicates}, "
          f"missing {f.n_missing}, mixed {f.n_mixed}, larger {f.n_larger}, ghosts {sum(r.ghosts)}, duplicates by "
          f"position {sum(r.duplicates)}, events {r.events} "
          f"({r.events_with_cpm} with a CPM)", flush=True)
    if "coverage" in parts:
        _coverage(a, out)


def _coverage(a, out: dict) -> None:
    t0 = time.perf_counter()
    total = RsuSimResult()
    per_run = []
    ghosts = dups = events = 0
    for k in range(a.runs):
        run = run_intersection(a.run_frames, seed=1000 + a.seed + k)
        r = run.fused
        total.add(r)
        per_run.append((r.n_cover_hits, r.n_cover))
        ghosts, dups, events = ghosts + sum(run.ghosts), dups + sum(run.duplicates), events + run.events
    # the coverage's sampling sd over runs (it varies with the calibration draws): a seeded bootstrap of the runs
    h, n = np.array(per_run, dtype=float).T
    rng = np.random.default_rng(0)
    boot = [h[i].sum() / n[i].sum() for i in (rng.integers(0, len(h), len(h)) for _ in range(2000))]
    out["coverage"] = {"runs": a.runs, "run_frames": a.run_frames, "coverage_bootstrap_sd": float(np.std(boot)),
                       **_row(total, time.perf_counter() - t0), "events": events, "ghosts": ghosts,
                       "duplicates_by_position": dups}
    print(f"coverage: fused {total.coverage:.4f} +- {np.std(boot):.4f} (n {total.n_cover}), 2+ cameras "
          f"{total.coverage_multi:.4f} "
          f"(n {total.n_multi}), cameras alone {total.coverage_camera:.4f}, larger {total.n_larger}, duplicates "
          f"{total.n_duplicates} of {total.n_truth_frames}, mixed {total.n_mixed}; ghosts {ghosts}, duplicates by "
          f"position {dups} in {events} events", flush=True)


if __name__ == "__main__":
    main()
