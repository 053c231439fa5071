"""Wall time of the slide term of tracked 2-D boxes (``fast/slide_kernels.py``, issue 31 part 3): this tree's
kernel against another tree's (e.g. main's), alternately in one run.

Usage::

    PYTHONPATH=src .venv/bin/python bench/bench_slide.py [--against /work/main/src] [--rounds 6] \\
        [--calls 3000] [--objects 100] [--sizes 1,8,64,100,200,1000] [--out FILE]

Inputs: the service bench's camera (``bench_service.CAMERA``, a pinhole) and the same camera with a distorting
lens, ``--objects`` tracked contacts (the bottom-centre ground points of ``bench_service.make_detections``' boxes,
class car, speeds 0-25 m/s in every direction, one in ten standing).  Each round runs one worker process per
tree (``--worker``, with that tree's ``src`` first on ``PYTHONPATH``; the other tree's numba cache goes to
``--against-cache``, its tree is only read), trees alternating, so that a change of the machine's load reaches both
alike.  A worker times the compiled entry (``slide_kernels.MOMENTS_KERNELS``, as ``ContactSlide.covariance``
calls it), ``ContactSlide.covariance`` and ``ContactSlide.apply`` (the tracker's per-frame call) on a
``TrackOutput``, the median of ``--calls`` calls after a warm-up (compilation not timed), and saves its outputs;
the run reports the medians over rounds, the ratio against / this tree, and the largest difference of the two
trees' outputs relative to each object's largest entry.  ``--sizes``: then, in one worker of each tree, each
camera's kernel median at each of these frame sizes (the first contacts of the same inputs; a tenth of the calls
for the lens beyond 200 objects when it is the slow kernel; ``--rounds 0`` for these alone).  Nothing is asserted.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from functools import partial
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]


def _inputs(objects: int, seed: int = 0):
    """The bench camera (pinhole and distorting), ``(xy (n, 2), v (n, 2), classes)`` of ``objects`` contacts."""
    sys.path.insert(0, str(ROOT / "bench"))
    from bench_service import CAMERA, make_detections

    from footprint_uq import PanTiltCamera
    from footprint_uq import params as P

    pin = PanTiltCamera(**CAMERA)
    lens = PanTiltCamera(**CAMERA)
    lens.params = np.array(pin.params, dtype=np.float64)
    lens.params[P.PARAM_NAMES.index("k1")], lens.params[P.PARAM_NAMES.index("k2")] = -0.08, 0.01
    d = make_detections(objects, seed)
    uv = np.array([[0.5 * (b["u_min_px"] + b["u_max_px"]), b["v_max_px"]] for b in d])
    xy = pin.backproject(uv).xy_world_m
    rng = np.random.default_rng(seed + 1)
    course, speed = rng.uniform(-np.pi, np.pi, objects), rng.uniform(0.0, 25.0, objects)
    speed[::10] = 0.0
    v = speed[:, None] * np.column_stack([np.cos(course), np.sin(course)])
    return {"pinhole": pin, "distorting lens": lens}, xy, v, ["car"] * objects


def _median_us(fn, calls: int) -> float:
    fn()
    ts = np.empty(calls)
    for k in range(calls):
        t0 = time.perf_counter()
        fn()
        ts[k] = time.perf_counter() - t0
    return 1e6 * float(np.median(ts))


def worker(objects: int, calls: int, out_npz: str) -> dict:
    """One tree's figures (the tree on ``sys.path``): ``{camera: {kernel_us, covariance_us}}``; outputs saved."""
    from footprint_uq.fast import slide_kernels
    from footprint_uq.products.contact import class_size_priors
    from footprint_uq.tracking import TrackOutput
    from footprint_uq.tracking import contact_slide as CS

    cams, xy, v, classes = _inputs(objects)
    mean, sig = class_size_priors(classes, objects)
    res, saved = {}, {}
    for name, cam in cams.items():
        prm, R, dom, has_dist = CS.kernel_camera(cam)
        kern = slide_kernels.MOMENTS_KERNELS[has_dist]
        m, M = np.empty((objects, 2)), np.empty((objects, 2, 2))
        out = TrackOutput.untracked(objects)
        out.track_id[:] = np.arange(objects)
        out.xy_m[:], out.v_mps[:] = xy, v
        slide = CS.ContactSlide(cam)
        res[name] = {"kernel_us": _median_us(partial(kern, prm, R, dom, xy, v, mean, sig, CS._NODES, m, M), calls),
                     "covariance_us": _median_us(partial(slide.covariance, out, classes), calls),
                     "apply_us": _median_us(partial(slide.apply, out, classes), calls)}
        saved[name + "/mean"], saved[name + "/second"] = m.copy(), M.copy()
    np.savez(out_npz, **saved)
    return res


def sizes_worker(sizes: list[int], calls: int) -> dict:
    """Per camera (pinhole, distorting lens), the moments kernel's median (us) at each frame size (the tree on
    ``sys.path``)."""
    from footprint_uq.fast import slide_kernels
    from footprint_uq.products.contact import class_size_priors
    from footprint_uq.tracking import contact_slide as CS

    cams, xy_all, v_all, _ = _inputs(max(sizes))
    res: dict = {}
    for name, cam in cams.items():
        prm, R, dom, has_dist = CS.kernel_camera(cam)
        kern = slide_kernels.MOMENTS_KERNELS[has_dist]
        res[name] = {}
        for n in sizes:
            xy, v = xy_all[:n].copy(), v_all[:n].copy()
            mean, sig = class_size_priors(["car"] * n, n)
            m, M = np.empty((n, 2)), np.empty((n, 2, 2))
            res[name][str(n)] = _median_us(partial(kern, prm, R, dom, xy, v, mean, sig, CS._NODES, m, M),
                                           calls if not has_dist or n <= 200 else max(calls // 10, 20))
    return res


def _max_rel(a: np.ndarray, b: np.ndarray) -> float:
    a, b = a.reshape(len(a), -1), b.reshape(len(b), -1)
    if not np.array_equal(np.isnan(a), np.isnan(b)):
        return float("inf")
    scale = np.nanmax(np.abs(b), axis=1, initial=0.0)[:, None]
    return float(np.nanmax(np.abs(a - b) / np.where(scale > 0, scale, 1.0), initial=0.0))


def _run_worker(src: Path, a, tmp: Path, tag: str, rnd: int, extra: tuple = ()) -> tuple[dict, Path]:
    env = dict(os.environ, PYTHONPATH=str(src))
    if src.resolve() != (ROOT / "src").resolve() and str(a.against_cache) != "none":
        env["NUMBA_CACHE_DIR"] = str(a.against_cache)   # (the other tree is only read)
    npz = tmp / f"{tag}-{rnd}.npz"
    p = subprocess.run([sys.executable, __file__, "--worker", "--objects", str(a.objects), "--calls",
                        str(a.calls), "--npz", str(npz), *extra], env=env, capture_output=True, text=True,
                       check=True)
    return json.loads(p.stdout.strip().splitlines()[-1]), npz


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--against", type=Path, help="another tree's src folder (e.g. /work/main/src)")
    ap.add_argument("--against-cache", type=Path, default=Path(tempfile.gettempdir()) / "bench_slide_numba_cache",
                    help="the numba cache folder of the --against tree (kept between runs: compiled once); 'none': "
                         "the tree's own (a writable copy of another tree, its caches with it)")
    ap.add_argument("--rounds", type=int, default=6)
    ap.add_argument("--calls", type=int, default=3000)
    ap.add_argument("--objects", type=int, default=100)
    ap.add_argument("--sizes", help="comma-separated frame sizes: the pinhole kernel's median at each (per tree)")
    ap.add_argument("--out", type=Path)
    ap.add_argument("--worker", action="store_true", help=argparse.SUPPRESS)
    ap.add_argument("--npz", help=argparse.SUPPRESS)
    a = ap.parse_args(argv)
    sizes = [int(k) for k in a.sizes.split(",")] if a.sizes else []
    if a.worker:
        print(json.dumps(sizes_worker(sizes, a.calls) if sizes else worker(a.objects, a.calls, a.npz)))
        return 0
    trees = {"this": ROOT / "src"} | ({"against": a.against} if a.against else {})
    load0 = os.getloadavg()[0]
    runs: dict = {t: [] for t in trees}
    with tempfile.TemporaryDirectory() as d:
        tmp = Path(d)
        for rnd in range(a.rounds):
            for tag in (list(trees) if rnd % 2 == 0 else list(trees)[::-1]):
                r, npz = _run_worker(trees[tag], a, tmp, tag, rnd)
                runs[tag].append(r)
                print(f"round {rnd} {tag:7s} " + "  ".join(f"{c}: kernel {x['kernel_us']:.1f} us, covariance "
                                                          f"{x['covariance_us']:.1f} us, apply {x['apply_us']:.1f} us"
                                                          for c, x in r.items()), flush=True)
        res = {"objects": a.objects, "calls": a.calls, "rounds": a.rounds, "trees": {t: str(p) for t, p in
                                                                                      trees.items()}}
        for t in trees if sizes else ():
            res[f"{t}_kernel_us_by_size"] = _run_worker(trees[t], a, tmp, t, -1, ("--sizes", a.sizes))[0]
            print(t, "kernel us by frame size", json.dumps(res[f"{t}_kernel_us_by_size"]), flush=True)
        last = {t: np.load(tmp / f"{t}-{a.rounds - 1}.npz") for t in trees} if a.rounds else {}
        for cam in runs["this"][0] if a.rounds else ():
            row = {}
            for t in trees:
                for f in ("kernel_us", "covariance_us", "apply_us"):
                    row[f"{t}_{f}"] = float(np.median([r[cam][f] for r in runs[t]]))
            if "against" in trees:
                row["kernel_ratio_against_over_this"] = row["against_kernel_us"] / row["this_kernel_us"]
                row["covariance_ratio_against_over_this"] = row["against_covariance_us"] / row["this_covariance_us"]
                row["apply_ratio_against_over_this"] = row["against_apply_us"] / row["this_apply_us"]
                row["max_rel_diff"] = max(_max_rel(last["this"][f"{cam}/{k}"], last["against"][f"{cam}/{k}"])
                                          for k in ("mean", "second"))
            res[cam] = row
            print(cam, json.dumps(row), flush=True)
    res["load_avg"] = [load0, os.getloadavg()[0]]
    if a.out:
        sys.path.insert(0, str(ROOT / "src"))
        from footprint_uq.io.atomic import atomic_write_text

        atomic_write_text(a.out, json.dumps(res, indent=2) + "\n", parents=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
