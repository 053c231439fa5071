"""The service frame's two text kernels against their reference, in one process: issue 31 part 1 (wave 8c).

    PYTHONPATH=src .venv/bin/python bench/bench_scan.py [--repeats 3000] [--ref COMMIT] [--out FILE]

The reference is the same modules at ``--ref`` (default: the commit before wave 8c's rewrite), taken from git
(``git show``) into a cache directory beside this checkout's numba caches and imported under other names, so that
the old kernels and the new are timed interleaved in the same loop on the same inputs:

* ``scan``: ``service/frame_scan._scan`` (the kernel alone) and ``scan_frame`` (the kernel + its Python) of the
  bench frame (``bench_frame.py``'s: 100 2-D boxes, ~10 kB of JSON, ~500 numbers);
* ``compact``: ``service/jsonrows.compact_objects_json`` untracked (5 float columns) and tracked (10 columns,
  track ids, message ids) on 100 rows of seeded floats of the record's magnitudes (position tens of metres,
  covariances below 1, velocities, NaN where no velocity), and within it the kernel ``_compact_rows`` alone and
  ``orjson.dumps`` of the float columns.

``--frame``: also the whole service frame (``bench_frame.py``'s ``measure``: ``Service.process_frame_json`` of the
payload's bytes against ``FrameProcessor.boxes2d`` alone, untracked and tracked, compact record), once with the new
kernels and once with the reference's put in their place (``service.core``'s ``scan_frame`` and
``compact_objects_json``), alternating in ``--rounds`` rounds; per case the medians of the rounds.

Before timing, every output of the new kernels is compared with the reference's (bit for bit; exit status 1 if
one differs).  Medians over the repeats; ``*_ratio``: new / reference within this run.  Nothing is asserted about
time.
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import orjson
from bench_service import make_detections

from footprint_uq.io.atomic import atomic_write_text
from footprint_uq.service import core, frame_scan, jsonrows

ROOT = Path(__file__).resolve().parent.parent
REF = "10ea4e0d"  # main before wave 8c (the kernels as they were)
_NUMPY = orjson.OPT_SERIALIZE_NUMPY


def reference_modules(commit: str):
    """``frame_scan`` and ``jsonrows`` as they were at ``commit``, imported from a copy under bench/.ref-<commit>
    (created once; numba caches its kernels there)."""
    where = ROOT / "bench" / f".ref-{commit}"
    where.mkdir(exist_ok=True)
    mods = []
    for name in ("frame_scan", "jsonrows"):
        path = where / f"ref_{name}.py"
        if not path.exists():
            text = subprocess.run(["git", "-C", str(ROOT), "show", f"{commit}:src/footprint_uq/service/{name}.py"],
                                  check=True, capture_output=True).stdout
            # (relative imports of the package, as the copy is no part of it: its modules' absolute names)
            text = text.replace(b"from ..", b"from footprint_uq.").replace(b"from .", b"from footprint_uq.service.")
            path.write_bytes(text)
        spec = importlib.util.spec_from_file_location(f"ref_{name}", path)
        mod = importlib.util.module_from_spec(spec)
        sys.modules[spec.name] = mod  # (numba's cached kernels name their module: found again on a later run)
        spec.loader.exec_module(mod)
        mods.append(mod)
    return mods


def frame_payload(objects: int) -> bytes:
    """bench_frame.py's frame text."""
    body = json.dumps(make_detections(objects, 0), separators=(",", ":")).encode()
    return b'{"camera_id":"cam0","frame":0,"timestamp_s":%.6f,"detections":%s}' % (1.7e9 + 1 / 30, body)


def compact_inputs(n: int, tracked: bool) -> tuple:
    """Seeded arguments of compact_objects_json: 100 rows of floats of the record's magnitudes."""
    rng = np.random.default_rng(7)
    v = np.empty((10 if tracked else 5, n))
    v[0], v[1] = rng.uniform(-60, 60, n), rng.uniform(5, 90, n)
    v[2:5] = rng.uniform(0, 0.5, (3, n))
    if tracked:
        v[5:7] = rng.normal(0, 5, (2, n))
        v[7:10] = rng.uniform(0, 2, (3, n))
        v[5:10, ::7] = np.nan  # (no velocity yet: null)
    ids = np.arange(n, dtype=np.int64) * 7
    mid = np.arange(n, dtype=np.int64)
    mid[::9] = -1
    tid = np.arange(n, dtype=np.int64) + 1000
    tid[::5] = -1
    return (ids, np.zeros(n, np.int64), [b'"car"'], np.zeros(n, np.int64), [b',"status":"ok"'], v, mid,
            tid if tracked else None)


def kernel_args(mod, args: tuple) -> tuple:
    """The arguments compact_objects_json passes to ``_compact_rows`` (as the module computes them: since wave 10b
    its ``_compact_args``)."""
    if hasattr(mod, "_compact_args"):
        return mod._compact_args(*args)
    ids, ci, ct, si, stx, v, mid, tid = args
    ftext = np.frombuffer(orjson.dumps(np.ascontiguousarray(v), option=_NUMPY), np.uint8)
    cb, ca = mod._text_table(ct)
    sb, sa = mod._text_table(stx)
    return (ftext, ids, ci, cb, ca, si, sb, sa, mid, True, ids if tid is None else tid, tid is not None,
            mod._COMPACT_LIT, mod._COMPACT_AT, 100000)


#: what a ScannedFrame says, compared between the trees
_SCANNED = ("camera_id", "frame", "timestamp_s", "boxes", "pixel_cov_px2", "object_ids", "classes", "class_confidence",
            "int_ids", "values_checked")


def same_outputs(ref_fs, ref_jr, text: bytes, compact: dict) -> list[str]:
    """The stages whose new output differs from the reference's (bit for bit)."""
    bad = []
    a, b = frame_scan.scan_frame(text), ref_fs.scan_frame(text)
    # (by name: since 2026-11-29, wave 11 a, the ids and classes lists are made when asked for, not tuple fields)
    if a is None or b is None or any(
            not np.array_equal(np.asarray(x, dtype=object if isinstance(x, list) else None),
                               np.asarray(y, dtype=object if isinstance(y, list) else None))
            for x, y in ((getattr(a, k), getattr(b, k)) for k in _SCANNED)) or a.boxes.tobytes() != b.boxes.tobytes():
        bad.append("scan_frame")
    for name, args in compact.items():
        if bytes(jsonrows.compact_objects_json(*args)) != bytes(ref_jr.compact_objects_json(*args)):
            bad.append(name)
    return bad


def frame_figures(ref_fs, ref_jr, objects: int, repeats: int, rounds: int) -> dict:
    """bench_frame.measure (compact record, untracked and tracked) with the new kernels and with the reference's,
    alternating; per case and kernels the median over the rounds of each figure."""
    from bench_frame import measure

    kernels = {"new": (frame_scan.scan_frame, jsonrows.compact_objects_json),
               "ref": (ref_fs.scan_frame, ref_jr.compact_objects_json)}
    keep = ("frame_bytes_us", "boxes2d_us", "frame_bytes_over_boxes2d", "frame_bytes_minus_step_us",
            "frame_bytes_minus_step_over_boxes2d")
    runs: dict = {}
    try:
        for _ in range(rounds):
            for tracked in (False, True):
                for tag, (scan, compact) in kernels.items():
                    core.scan_frame, core.compact_objects_json = scan, compact
                    got = measure(tracked, "compact", objects, repeats)
                    runs.setdefault(f"{'tracked' if tracked else 'untracked'}_{tag}", []).append(got)
    finally:
        core.scan_frame, core.compact_objects_json = kernels["new"]
    out = {}
    for case, got in runs.items():
        out[case] = {k: round(float(np.median([g[k] for g in got])), 3) for k in keep if k in got[0]}
        print(f"frame {case:14s} " + "  ".join(f"{k} {v}" for k, v in out[case].items()), flush=True)
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=3000)
    ap.add_argument("--objects", type=int, default=100)
    ap.add_argument("--ref", default=REF, help="the reference commit (default: %(default)s)")
    ap.add_argument("--out", type=Path, default=None, help="write the figures as JSON here")
    ap.add_argument("--frame", action="store_true", help="also the whole frame, new kernels vs the reference's")
    ap.add_argument("--frame-repeats", type=int, default=300)
    ap.add_argument("--rounds", type=int, default=3)
    args = ap.parse_args(argv)
    ref_fs, ref_jr = reference_modules(args.ref)
    text = frame_payload(args.objects)
    buf = np.frombuffer(text, np.uint8)
    compact = {c: compact_inputs(args.objects, c == "tracked") for c in ("untracked", "tracked")}
    bad = same_outputs(ref_fs, ref_jr, text, compact)
    if bad:
        print("outputs differ from the reference:", ", ".join(bad), file=sys.stderr)
        return 1
    stages = {}
    for tag, fs, jr in (("new", frame_scan, jsonrows), ("ref", ref_fs, ref_jr)):
        kargs = (buf, fs._POW10, fs._FK, fs._FK_AT, fs._DK, fs._DK_AT)
        stages[f"scan_kernel_{tag}"] = (fs._scan, kargs)
        stages[f"scan_frame_{tag}"] = (fs.scan_frame, (text,))
        for c, a in compact.items():
            stages[f"compact_{c}_{tag}"] = (jr.compact_objects_json, a)
            stages[f"compact_rows_kernel_{c}_{tag}"] = (jr._compact_rows, kernel_args(jr, a))
    for c, a in compact.items():
        stages[f"orjson_dumps_floats_{c}"] = (lambda v: orjson.dumps(np.ascontiguousarray(v), option=_NUMPY), (a[5],))
    times = {k: [] for k in stages}
    for f, a in stages.values():  # (warm: compiled or loaded from the cache)
        f(*a)
    wall = time.perf_counter
    load0 = os.getloadavg()[0]
    for _ in range(args.repeats):
        for k, (f, a) in stages.items():
            t0 = wall()
            f(*a)
            times[k].append(wall() - t0)
    res = {f"{k}_us": round(1e6 * float(np.median(v)), 3) for k, v in times.items()}
    for k in stages:
        if k.endswith("_new"):
            res[f"{k[:-4]}_ratio"] = round(res[f"{k}_us"] / res[f"{k[:-4]}_ref_us"], 3)
    out = {"what": f"bench/bench_scan.py: the frame scanner and the compact writer vs their code at {args.ref}, "
                   f"{args.objects} objects, {args.repeats} interleaved repeats, medians (us)",
           "date": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()), "cores": os.cpu_count(),
           "python": sys.version.split()[0], "load_average_1min_start": load0,
           "load_average_1min_end": os.getloadavg()[0], "outputs_identical": True, "figures": res}
    for k in stages:
        if k.endswith("_new"):
            b = k[:-4]
            print(f"{b:30s} new {res[f'{k}_us']:7.2f} us  ref {res[f'{b}_ref_us']:7.2f} us  "
                  f"ratio {res[f'{b}_ratio']:.3f}")
    for c in compact:
        print(f"orjson_dumps_floats_{c:10s} {res[f'orjson_dumps_floats_{c}_us']:7.2f} us")
    if args.frame:
        out["frame"] = frame_figures(ref_fs, ref_jr, args.objects, args.frame_repeats, args.rounds)
        out["frame_what"] = (f"bench_frame.measure, compact record, {args.frame_repeats} repeats x {args.rounds} "
                             "rounds alternating new / reference kernels; medians of the rounds")
        out["load_average_1min_end"] = os.getloadavg()[0]
    if args.out:
        atomic_write_text(args.out, json.dumps(out, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
