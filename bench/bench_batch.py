"""Batch throughput: footprints per second, Parquet -> Parquet, end to end (issue 3 target: >= 2 million/s).

Measured in one run on the same machine:

* ``batch`` -- :func:`footprint_uq.batch.process.process_file` on a generated Parquet file
  (read, validate, fused kernel, ellipses, V2X fields, write Parquet), median of ``repeats``;
* ``kernel`` -- the fused :class:`~footprint_uq.footprints.FrameProcessor` alone on the same
  boxes in memory (the compute floor of the batch);
* ``naive`` -- a per-object Python loop over the numpy reference
  (:func:`~footprint_uq.footprints.footprints_from_boxes3d` / ``_boxes2d`` one object at a time),
  timed on a subset and reported per object (labelled as extrapolated).

Run ``.venv/bin/python bench/bench_batch.py [--rows N] [--repeats R]``; :func:`measure`
returns the figures as a dict, :func:`run` the rows of ``bench/run.py``'s table.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from footprint_uq import PanTiltCamera
from footprint_uq.batch.process import process_file
from footprint_uq.footprints import FrameProcessor, footprints_from_boxes2d, footprints_from_boxes3d

TARGET_PER_S = 2_000_000
CAMERA = dict(focal_px=1400.0, image_size_px=(1920, 1080), height_m=8.0, pan_deg=30.0, tilt_deg=20.0)
BUDGET = "basler1"


def make_detections(n: int, box_type: str, seed: int = 0) -> pa.Table:
    """n detections in front of the bench camera (a few percent partly outside the image)."""
    rng = np.random.default_rng(seed)
    cam = PanTiltCamera(**CAMERA)
    d = rng.uniform(12.0, 70.0, n)
    a = np.deg2rad(CAMERA["pan_deg"] + rng.uniform(-28.0, 28.0, n))
    x, y = d * np.sin(a), d * np.cos(a)
    cols = {"frame": np.arange(n, dtype=np.int64) // 100, "timestamp_s": (np.arange(n) // 100) * 0.1,
            "object_id": np.arange(n, dtype=np.int64) % 100,
            "class": pa.array(np.where(rng.random(n) < 0.8, "car", "truck")).dictionary_encode()}
    if box_type == "3d":
        cols.update(x_m=x, y_m=y, z_m=np.full(n, 0.8), length_m=rng.uniform(3.5, 5.0, n),
                    width_m=rng.uniform(1.6, 2.0, n), height_m=rng.uniform(1.4, 1.8, n),
                    yaw_rad=rng.uniform(-np.pi, np.pi, n))
    else:
        uv = cam.project(np.stack([x, y, np.zeros(n)], 1)).uv_px
        w = rng.uniform(30.0, 90.0, n)
        h = rng.uniform(30.0, 90.0, n)
        cols.update(u_min_px=uv[:, 0] - w / 2, v_min_px=uv[:, 1] - h, u_max_px=uv[:, 0] + w / 2, v_max_px=uv[:, 1])
    return pa.table(cols)


def _naive_per_object(cam, boxes: np.ndarray, box_type: str) -> float:
    """Seconds per object of a Python loop over the numpy reference."""
    t0 = time.perf_counter()
    for i in range(boxes.shape[0]):
        if box_type == "3d":
            footprints_from_boxes3d(cam, BUDGET, boxes[i:i + 1])
        else:
            footprints_from_boxes2d(cam, BUDGET, boxes[i:i + 1])
    return (time.perf_counter() - t0) / boxes.shape[0]


def measure(rows: int = 2_000_000, repeats: int = 3, naive_rows: int = 2_000, box_types=("3d", "2d"),
            workdir: str | None = None) -> dict:
    """Measure and return ``{box_type: {...figures...}}`` (footprints per second, medians)."""
    cam = PanTiltCamera(**CAMERA)
    out: dict = {"rows": rows, "repeats": repeats, "cpus": os.cpu_count(), "target_per_s": TARGET_PER_S}
    with tempfile.TemporaryDirectory(dir=workdir) as tmp:
        for bt in box_types:
            table = make_detections(rows, bt)
            src = Path(tmp) / f"det_{bt}.parquet"
            pq.write_table(table, src, row_group_size=262_144)
            dst = Path(tmp) / f"out_{bt}.parquet"
            cols = (["x_m", "y_m", "z_m", "length_m", "width_m", "height_m", "yaw_rad"] if bt == "3d"
                    else ["u_min_px", "v_min_px", "u_max_px", "v_max_px"])
            boxes = np.stack([table.column(c).to_numpy() for c in cols], 1)
            # warm-up (numba compile / cache load) on a small file
            small = Path(tmp) / "warm.parquet"
            pq.write_table(table.slice(0, 1000), small)
            process_file(cam, BUDGET, small, Path(tmp) / "warm_out.parquet", progress=False, summary=False)
            times = []
            for _ in range(repeats):
                t0 = time.perf_counter()
                s = process_file(cam, BUDGET, src, dst, progress=False, summary=False)
                times.append(time.perf_counter() - t0)
                assert s.rows_out == rows
            proc = FrameProcessor(cam, BUDGET, joint_cov=False)
            ktimes = []
            for _ in range(repeats):
                t0 = time.perf_counter()
                proc.boxes3d(boxes) if bt == "3d" else proc.boxes2d(boxes)
                ktimes.append(time.perf_counter() - t0)
            naive_s = _naive_per_object(cam, boxes[:naive_rows], bt)
            t_b, t_k = statistics.median(times), statistics.median(ktimes)
            out[bt] = {
                "batch_footprints_per_s": rows / t_b,
                "batch_s": t_b,
                "kernel_only_footprints_per_s": rows / t_k,
                "naive_loop_footprints_per_s": 1.0 / naive_s,
                "naive_loop_note": f"per-object loop over the numpy reference, timed on {naive_rows} objects",
                "speedup_vs_naive": naive_s * rows / t_b,
                "meets_target": rows / t_b >= TARGET_PER_S,
                "rows_ok": int(s.rows_ok), "rows_partial": int(s.rows_partial), "rows_error": int(s.rows_error),
                "input_MB": src.stat().st_size / 1e6, "output_MB": dst.stat().st_size / 1e6,
            }
    return out


def run(quick: bool = False) -> list[dict]:
    """Rows for ``bench/run.py`` (section ``batch``): one per box family."""
    res = measure(rows=500_000 if quick else 2_000_000, repeats=2 if quick else 3, naive_rows=200 if quick else 1000)
    rows = []
    names = {"3d": "3D boxes (4 corners)", "2d": "2D boxes (bottom centre)"}
    for bt in ("3d", "2d"):
        r = res[bt]
        rows.append({"case": f"batch Parquet -> Parquet, {names[bt]}, {res['rows']:,} rows",
                     "median_ms": 1e3 * r["batch_s"], "runs": res["repeats"],
                     "speedup_vs_naive": r["speedup_vs_naive"], "target": ">= 2 M footprints/s",
                     "met": r["meets_target"],
                     "notes": f"{r['batch_footprints_per_s'] / 1e6:.2f} M footprints/s end to end; kernel alone "
                              f"{r['kernel_only_footprints_per_s'] / 1e6:.2f} M/s; naive per-object loop "
                              f"{r['naive_loop_footprints_per_s']:,.0f} /s ({r['naive_loop_note']})",
                     **r})
    return rows


def report(res: dict) -> str:
    lines = [f"batch Parquet -> Parquet, {res['rows']:,} detections, median of {res['repeats']} "
             f"({res['cpus']} CPUs; target {res['target_per_s'] / 1e6:.1f} M footprints/s)",
             "| boxes | batch end-to-end | kernel only | naive per-object loop (extrapolated) | batch / naive |",
             "|---|---|---|---|---|"]
    for bt in ("3d", "2d"):
        if bt in res:
            r = res[bt]
            lines.append(f"| {bt} | {r['batch_footprints_per_s'] / 1e6:.2f} M/s ({r['batch_s']:.2f} s) | "
                         f"{r['kernel_only_footprints_per_s'] / 1e6:.2f} M/s | "
                         f"{r['naive_loop_footprints_per_s']:,.0f} /s | {r['speedup_vs_naive']:,.0f}x |")
    return "\n".join(lines)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rows", type=int, default=2_000_000)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--naive-rows", type=int, default=2_000)
    ap.add_argument("--box-types", default="3d,2d")
    ap.add_argument("--json", default=None, help="also write the figures to this JSON file")
    a = ap.parse_args(argv)
    res = measure(a.rows, a.repeats, a.naive_rows, tuple(a.box_types.split(",")))
    print(report(res))
    if a.json:
        Path(a.json).write_text(json.dumps(res, indent=2) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
