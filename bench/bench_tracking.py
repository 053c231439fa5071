"""The tracker's cost per frame: 100 moving objects (3D boxes) at 30 Hz through positions and motion.

Issue 22's target: <= 300 us of processing per frame for the positions and the motion together.  Measured in one
run, interleaved frame by frame (medians over ``frames`` frames after a warm-up of 30 frames):

* ``positions`` -- :meth:`FrameProcessor.boxes3d` as the service runs it without tracks (the reference);
* ``positions_split`` -- the same with ``shared_jacobian=True`` (the centre's whitened calibration Jacobian);
* ``shared_at`` -- :class:`~footprint_uq.tracking.table.SharedJacobianAt` at the 100 predicted positions alone;
* ``track`` -- :func:`~footprint_uq.tracking.motion.track_motion`: :meth:`TrackTable.step` (deleter, ids, the
  per-frame covariance, predict, ``shared_at``, gate, update, outputs; the ids looked up in one compiled call --
  integer ids; since 2026-11-28 night, wave 9 f: before, a dictionary pass -- and compiled passes over the objects)
  and the motion fields of :func:`~footprint_uq.tracking.motion.object_motion` in the step's compiled call, the
  default two-mode IMM filter (``cov_m2=`` the estimate's whole covariance), the ids a list of ints (before
  2026-11-29, wave 12: ``step`` then ``object_motion``, two calls);
* ``track_int64`` -- ``track`` with the frame's ids handed as an int64 array (as the service's frame scanner
  has them, ``FrameDetections.int_ids``), not a list: the compiled look-up without the list's conversion
  (2026-11-28 night, wave 9 f; since 2026-11-29, wave 11, a list of ints is made such an array in the step);
  ``ratio_int64`` its ratio;
* ``track_two_calls`` -- ``track_int64`` as two calls, :meth:`TrackTable.step` then
  :func:`~footprint_uq.tracking.motion.object_motion` (what ``track_int64`` was before wave 12; the service's
  :class:`~footprint_uq.tracking.camera_tracker.CameraTracker` still takes them apart: the slide term of 2-D boxes
  and the NIS check come between); ``ratio_two_calls`` its ratio.  ``track``, ``track_int64`` and
  ``track_two_calls`` take turns (seeded draws) right after the positions, as the service runs its step, and
  each figure is the median over the frames where it ran there (a third of the frames each): a step after another
  table's step pays ~2-3 us less (its code and arrays warm), which flattered ``track_int64`` (always run fourth)
  before 2026-11-29 wave 11;
* ``track_cv`` -- the same with the single constant-velocity mode (``manoeuvre_accel_psd_m2ps3=None``: the tracker
  before the IMM), on the same frames;
* ``track_reference`` -- ``track`` with the update's compiled reference (:func:`~footprint_uq.tracking.kernels.
  frame_update`, the pass the table ran before :func:`~footprint_uq.tracking.imm_kernels.frame_pass`), same frames;
* ``total`` -- ``positions_split + track``: positions and motion of one frame; ``ratio`` = ``total / positions``
  (issue 31's target: <= 2);
* ``step_python`` -- the Python of :meth:`TrackTable.step` alone (checks, id lookup, new ids' rows, allocations,
  the dictionary's share of the deleter -- since 2026-11-29, wave 13, with the tracks' timeout the tracker's
  default, :data:`TIMEOUT_S` -- and, for a list looked up in the dictionary, its sweep's compiled call): ``step``
  minus its compiled calls (``frame_step``: the whole frame in one call; a list with new ids:
  ``frame_rows_shared`` and ``frame_pass`` around the Python claim), timed around them (issue 31's target: < 20
  us); ``_int64``: the same with the ids as an int64 array (before 2026-11-29, wave 11 c: ``frame_rows_shared``,
  the rows and ``B`` at the predicted positions, then ``frame_pass``; before 2026-11-28 night, wave 9: three calls,
  ``frame_rows``, ``shared_at``, ``frame_pass``).

:func:`monitor_cost` (a separate pass over the same frames, so as not to disturb the ratio's caches): ``monitor``,
the on-line NIS check (:class:`~footprint_uq.tracking.consistency.NisMonitor`, as ``serve --tracks`` runs it by
default: the tracker's own NIS summed per class), and ``monitor_bank``, the same check as it was before 2026-11-28
(a :class:`~footprint_uq.tracking.motion_fit.MotionBank` re-running the filter with ``B`` evaluated again, the
per-frame covariance ``cov - B B^T`` computed for it), after the same tracks' step.

Run ``.venv/bin/python bench/bench_tracking.py [--objects N] [--frames F] [--json]``; :func:`run` returns the
figures as a dict.  ``--runs 3 --out bench/results/tracking-cost.json`` writes that many runs (each with the load
average before and after it) to the results file.  Nothing is asserted.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import time
from pathlib import Path

import numpy as np

from footprint_uq import PanTiltCamera
from footprint_uq.products.footprints import FrameProcessor
from footprint_uq.tracking import SharedJacobianAt, TrackerConfig, TrackTable, object_motion, track_motion
from footprint_uq.tracking import table as table_module
from footprint_uq.tracking.classes import ClassTracks
from footprint_uq.tracking.consistency import NisMonitor
from footprint_uq.tracking.motion_fit import MotionBank, members_of

TARGET_US = 300.0
CAMERA = dict(focal_px=1400.0, image_size_px=(1920, 1080), height_m=8.0, pan_deg=30.0, tilt_deg=20.0)
BUDGET = "basler1@deg"
RATE_HZ = 30.0


def _frames(camera, n: int, count: int, seed: int = 0, life_s: float = 3.0):
    """``count`` frames of n car-sized boxes (N, 7) and their ids: each object drives 3-10 m/s for ``life_s`` from a
    point 20..45 m from the camera, then a new object (a new id) starts there (staggered: ~1 new object per frame
    at 30 Hz).  Exact boxes; the detector's pixel noise is declared to the processor (1 px^2), as a detector would."""
    rng = np.random.default_rng(seed)
    d = rng.uniform(20.0, 45.0, n)
    a = np.deg2rad(camera.pan_deg + rng.uniform(-20.0, 20.0, n))
    xy0 = np.column_stack([d * np.sin(a), d * np.cos(a)])
    course = rng.uniform(-np.pi, np.pi, n)
    v = rng.uniform(3.0, 10.0, n)[:, None] * np.column_stack([np.cos(course), np.sin(course)])
    size = np.column_stack([np.full(n, 0.8), rng.uniform(3.5, 5.0, n), rng.uniform(1.6, 2.0, n), np.full(n, 1.5)])
    phase = rng.uniform(0.0, life_s, n)
    for k in range(count):
        t = k / RATE_HZ
        age = np.mod(t + phase, life_s)
        ids = (np.arange(n) + n * np.floor((t + phase) / life_s).astype(np.int64)).tolist()
        yield t, ids, np.column_stack([xy0 + v * age[:, None], size, course])


#: the tracks' timeout: the tracker's default (TrackerConfig().timeout_s, 1 s: the service's), so the deleter sweeps
#: as it does in the service -- a scene whose objects come and go (~1 a frame here) has an expired track on about
#: two frames in three.  Before 2026-11-29, wave 13: 1e9 s (no track ever deleted: the sweep never ran, ~6.5 us a
#: frame it took then, and the table grew to ~1,130 rows); ``--timeout-s 1e9`` gives that setting again.
TIMEOUT_S = TrackerConfig().timeout_s


def _timeout(timeout_s: float | None) -> float:
    return TIMEOUT_S if timeout_s is None else float(timeout_s)


class _Timed:
    """A callable that adds the time of each call of ``fn`` to ``spent[0]`` (s)."""

    def __init__(self, fn, spent: list):
        self.fn, self.spent = fn, spent

    def __call__(self, *args):
        t0 = time.perf_counter()
        res = self.fn(*args)
        self.spent[0] += time.perf_counter() - t0
        return res


def step_python(n_objects: int = 100, frames: int = 300, timeout_s: float | None = None) -> dict:
    """Medians (us) of :meth:`TrackTable.step`'s own Python per frame and of its compiled calls, on the frames of
    :func:`run`, the ids as a list (``step``, ``step_python``) and as an int64 array (``step_int64``,
    ``step_python_int64``, a second table on the same frames): the module's ``frame_step`` / ``frame_rows_shared``
    / ``frame_pass`` wrapped by timers (since 2026-11-29, wave 11 c, a frame is one call of ``frame_step``, unless
    a list has new ids -- ``frame_rows_shared``, the claim in Python, ``frame_pass`` -- or there are more new ids
    than free rows -- ``frame_step`` stops after the rows, ``frame_pass`` follows the claim)."""
    cam = PanTiltCamera(**CAMERA)
    split = FrameProcessor(cam, BUDGET, joint_cov=False, linearity=False, v2x_policy="linear", shared_jacobian=True)
    names = ("frame_step", "frame_rows_shared", "frame_pass")
    spent = {k: [0.0] for k in names}
    at = SharedJacobianAt(cam, BUDGET)
    cfg = TrackerConfig(timeout_s=_timeout(timeout_s))
    tables = {kind: TrackTable(cfg, rank=at.rank, shared_at=at) for kind in ("", "_int64")}
    det = np.broadcast_to(np.eye(2), (n_objects, 2, 2))
    saved = tuple(getattr(table_module, k) for k in names)
    for f, k in zip(saved, names, strict=True):
        timed = _Timed(f, spent[k])
        timed.signatures = f.signatures
        setattr(table_module, k, timed)
    times: dict = {k + kind: [] for kind in tables for k in ("step", "step_python", *names)}
    try:
        for k, (t, ids, boxes) in enumerate(_frames(cam, n_objects, frames + 30)):
            est = split.boxes3d(boxes, pixel_cov_px2=det)
            for kind, table in tables.items():
                frame_ids = np.array(ids, np.int64) if kind else ids
                for v in spent.values():
                    v[0] = 0.0
                t0 = time.perf_counter()
                table.step(t, frame_ids, est.centre_xy_world_m, shared_m=est.centre_shared_m, cov_m2=est.centre_cov_m2)
                dt = time.perf_counter() - t0
                if k >= 30:
                    times["step" + kind].append(dt * 1e6)
                    times["step_python" + kind].append((dt - sum(v[0] for v in spent.values())) * 1e6)
                    for key, v in spent.items():
                        times[key + kind].append(v[0] * 1e6)
    finally:
        for f, k in zip(saved, names, strict=True):
            setattr(table_module, k, f)
    return {k: round(statistics.median(v), 1) for k, v in times.items()}


def monitor_cost(n_objects: int = 100, frames: int = 300, timeout_s: float | None = None) -> dict:
    """Medians (us) of the on-line NIS check per frame, now (``monitor``) and its path before (``monitor_bank``),
    after the same tracks' step on the frames of :func:`run`."""
    cam = PanTiltCamera(**CAMERA)
    split = FrameProcessor(cam, BUDGET, joint_cov=False, linearity=False, v2x_policy="linear", shared_jacobian=True)
    at = SharedJacobianAt(cam, BUDGET)
    tracks = ClassTracks(TrackerConfig(timeout_s=_timeout(timeout_s)), rank=at.rank, shared_at=at)
    mon = NisMonitor(tracks)
    bank = MotionBank(members_of(tracks.configs), rank=at.rank, shared_at=at, timeout_s=_timeout(timeout_s))
    det = np.broadcast_to(np.eye(2), (n_objects, 2, 2))
    classes = ["car"] * n_objects
    times: dict = {"monitor": [], "monitor_bank": []}
    for k, (t, ids, boxes) in enumerate(_frames(cam, n_objects, frames + 30)):
        est = split.boxes3d(boxes, pixel_cov_px2=det)
        B = est.centre_shared_m
        out = tracks.step(t, ids, classes, est.centre_xy_world_m, shared_m=B, cov_m2=est.centre_cov_m2)
        t0 = time.perf_counter()
        mon.observe(t, out, classes)
        t1 = time.perf_counter()
        bank.observe(t, out, classes, est.centre_xy_world_m, est.centre_cov_m2 - B @ np.swapaxes(B, -1, -2), B)
        t2 = time.perf_counter()
        if k >= 30:
            times["monitor"].append((t1 - t0) * 1e6)
            times["monitor_bank"].append((t2 - t1) * 1e6)
    return {k: round(statistics.median(v), 1) for k, v in times.items()}


#: the tracker's ways from the centres to the motion timed right after the positions, in turns (see the module doc)
VARIANTS = ("track", "track_int64", "track_two_calls")


def _track_variant(name: str, table: TrackTable, t: float, ids, xy, B, cov, yaw):
    """One frame's step and motion the way ``name`` says; returns the step's output."""
    if name == "track_two_calls":
        tracks = table.step(t, ids, xy, shared_m=B, cov_m2=cov)
        object_motion(tracks, yaw_rad=yaw)
        return tracks
    return track_motion(table, t, ids, xy, shared_m=B, cov_m2=cov, yaw_rad=yaw)[0]


def run(n_objects: int = 100, frames: int = 300, timeout_s: float | None = None) -> dict:
    cam = PanTiltCamera(**CAMERA)
    plain = FrameProcessor(cam, BUDGET, joint_cov=False, linearity=False, v2x_policy="linear")
    split = FrameProcessor(cam, BUDGET, joint_cov=False, linearity=False, v2x_policy="linear", shared_jacobian=True)
    at = SharedJacobianAt(cam, BUDGET)
    cfg = TrackerConfig(timeout_s=_timeout(timeout_s))
    table = TrackTable(cfg, rank=at.rank, shared_at=at)
    table_cv = TrackTable(TrackerConfig(timeout_s=cfg.timeout_s, manoeuvre_accel_psd_m2ps3=None), rank=at.rank,
                          shared_at=at)
    table_ref = TrackTable(cfg, rank=at.rank, shared_at=at)
    table_ref._reference_pass = True
    tables = {"track": table, **{v: TrackTable(cfg, rank=at.rank, shared_at=at)
                                 for v in VARIANTS[1:]}}
    det = np.broadcast_to(np.eye(2), (n_objects, 2, 2))
    restarts = 0
    keys = ("positions", "positions_split", "shared_at", "track", "track_cv", "track_reference", "total",
            "track_int64", "total_int64", "track_two_calls", "total_two_calls")
    times = {k: [] for k in keys}
    ratios: dict = {"ratio": [], "ratio_int64": [], "ratio_two_calls": []}
    # (which variant steps first, right after the positions: seeded draws, not the frame's parity, which the
    # objects' births could follow)
    order = np.random.default_rng(7).integers(0, 3, frames + 30)
    for k, (t, ids, boxes) in enumerate(_frames(cam, n_objects, frames + 30)):
        ids64 = np.array(ids, np.int64)  # (what the frame's scanner hands; not timed)
        yaw = boxes[:, 6]
        t0 = time.perf_counter()
        plain.boxes3d(boxes, pixel_cov_px2=det)
        t1 = time.perf_counter()
        est = split.boxes3d(boxes, pixel_cov_px2=det)
        t2 = time.perf_counter()
        xy, B, cov = est.centre_xy_world_m, est.centre_shared_m, est.centre_cov_m2
        # the list's table, the int64 ids' and the two calls' take turns right after the positions (as the service
        # runs its step): a step there pays ~2-3 us more than one after another table's step (code and arrays cold)
        first = VARIANTS[order[k]]
        spent = {}
        for name in (first, *(v for v in VARIANTS if v != first)):
            ta = time.perf_counter()
            res = _track_variant(name, tables[name], t, ids64 if name != "track" else ids, xy, B, cov, yaw)
            spent[name] = time.perf_counter() - ta
            if name == "track":
                out = res
        t3 = time.perf_counter()
        at(est.centre_xy_world_m)
        t4 = time.perf_counter()
        track_motion(table_cv, t, ids, xy, shared_m=B, cov_m2=cov, yaw_rad=yaw)
        t5 = time.perf_counter()
        track_motion(table_ref, t, ids, xy, shared_m=B, cov_m2=cov, yaw_rad=yaw)
        t6 = time.perf_counter()
        restarts += int(out.new_track.sum()) if k else 0
        if k >= 30:
            for key, dt in (("positions", t1 - t0), ("positions_split", t2 - t1), ("shared_at", t4 - t3),
                            ("track_cv", t5 - t4), ("track_reference", t6 - t5)):
                times[key].append(dt * 1e6)
            # (each variant's figures from the frames where its step came right after the positions)
            dt = spent[first]
            suffix = first[len("track"):]
            times[first].append(dt * 1e6)
            times["total" + suffix].append((t2 - t1 + dt) * 1e6)
            ratios["ratio" + suffix].append((t2 - t1 + dt) / (t1 - t0))
    res = {k: round(statistics.median(v), 1) for k, v in times.items()}
    res.update({k: round(statistics.median(v), 2) for k, v in ratios.items()})
    res["ratio_of_medians"] = round(res["total"] / res["positions"], 2)
    res.update(n_objects=n_objects, frames=frames, target_us=TARGET_US, tracked=int((out.n_updates > 1).sum()),
               new_tracks_after_first_frame=restarts)
    return res


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--objects", type=int, default=100)
    ap.add_argument("--frames", type=int, default=300)
    ap.add_argument("--json", action="store_true")
    ap.add_argument("--runs", type=int, default=1, help="runs written to --out")
    ap.add_argument("--timeout-s", type=float, default=TIMEOUT_S, help="the tracks' timeout (default: the tracker's)")
    ap.add_argument("--out", type=Path, help="write the runs (with the load averages) to this JSON file")
    a = ap.parse_args(argv)
    if a.out is not None:
        runs = []
        for _ in range(a.runs):
            load0 = os.getloadavg()[0]
            runs.append({**run(a.objects, a.frames, a.timeout_s),
                         "python": step_python(a.objects, a.frames, a.timeout_s),
                         "monitor": monitor_cost(a.objects, a.frames, a.timeout_s), "timeout_s": a.timeout_s,
                         "load_average_1min_start": round(load0, 2),
                         "load_average_1min_end": round(os.getloadavg()[0], 2)})
        doc = {"note": f"bench/bench_tracking.py --frames {a.frames} --runs {a.runs} --out {a.out}; track = IMM "
                       "(default) with imm_kernels.frame_pass, track_reference = the same with the compiled "
                       "reference pass (kernels.frame_update), track_cv = single constant-velocity mode, same "
                       "frames, interleaved; monitor = the on-line NIS check now / its path before 2026-11-28 (a "
                       "MotionBank re-running the filter), separate pass; "
                       "ratio = median over frames of total / positions; python = "
                       "TrackTable.step's own Python and its compiled calls (separate pass over the same frames); "
                       "figures are medians over the frames in us, on a shared 2-core VM unless said otherwise",
               "runs": runs}
        tmp = a.out.with_suffix(".tmp")
        tmp.write_text(json.dumps(doc, indent=1) + "\n")
        tmp.replace(a.out)
        for r in runs:
            print(f"total {r['total']:.1f} us (positions_split {r['positions_split']:.1f} + track {r['track']:.1f}); "
                  f"positions {r['positions']:.1f}; ratio {r['ratio']:.2f}; track_reference "
                  f"{r['track_reference']:.1f}; ids as int64: track {r['track_int64']:.1f}, "
                  f"ratio {r['ratio_int64']:.2f}; two calls: track {r['track_two_calls']:.1f}, "
                  f"ratio {r['ratio_two_calls']:.2f}; "
                  f"monitor {r['monitor']['monitor']:.1f} (before: "
                  f"{r['monitor']['monitor_bank']:.1f}); step Python {r['python']['step_python']:.1f} us; "
                  f"load {r['load_average_1min_start']:.2f}")
        return
    res = run(a.objects, a.frames, a.timeout_s)
    if a.json:
        print(json.dumps(res))
        return
    for k in ("positions", "positions_split", "shared_at", "track", "track_cv", "track_reference", "total",
              "track_int64", "track_two_calls"):
        print(f"{k:16s} {res[k]:8.1f} us per frame of {res['n_objects']} objects (median of {res['frames']})")
    print(f"target: total <= {TARGET_US:.0f} us -> {'met' if res['total'] <= TARGET_US else 'NOT met'}")
    print(f"ratio total / positions {res['ratio']:.2f} (issue 31: <= 2); int64 ids {res['ratio_int64']:.2f}; "
          f"int64 ids, step + object_motion {res['ratio_two_calls']:.2f}")
    for k, v in step_python(a.objects, a.frames).items():
        print(f"{k:16s} {v:8.1f} us (TrackTable.step and its parts)")
    for k, v in monitor_cost(a.objects, a.frames).items():
        print(f"{k:16s} {v:8.1f} us (the on-line NIS check; _bank: its path before)")


if __name__ == "__main__":
    main()
