"""Fleet batch throughput: in-process vs a 2-worker local Dask cluster, same dataset, same run.

A generated multi-camera dataset (hive-partitioned ``camera_id=/date=``, 3D boxes) and a
camera registry are processed by :func:`footprint_uq.batch.fleet.process_fleet` in this process
and on a local ``dask.distributed`` cluster (worker processes, one thread each; the cluster is
started before the timing).  Both write partitioned Parquet; footprints per second are
end to end (read, compute, write), medians of ``repeats``.

Run ``.venv/bin/python bench/bench_dask.py [--rows-per-file N] [--workers 2]``; :func:`measure`
returns the figures, :func:`run` the rows of ``bench/run.py``'s table.  Needs the ``dask`` extra.
"""

from __future__ import annotations

import argparse
import json
import shutil
import statistics
import sys
import tempfile
import time
from pathlib import Path

import pyarrow.parquet as pq

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_batch import BUDGET, CAMERA, make_detections  # noqa: E402

from footprint_uq.io.atomic import atomic_write_text


def make_dataset(root: Path, cameras: int, files_per_camera: int, rows_per_file: int) -> tuple[Path, Path, int]:
    """(dataset folder, registry file, total rows); every camera is the bench camera (same geometry)."""
    from footprint_uq import PanTiltCamera
    from footprint_uq.io import save_camera

    data = root / "detections"
    reg = root / "registry"
    reg.mkdir(parents=True)
    save_camera(PanTiltCamera(**CAMERA), reg / "bench.yaml")
    lines = ["camera_id,camera,budget"]
    total = 0
    for c in range(cameras):
        cid = f"cam{c:03d}"
        lines.append(f"{cid},bench.yaml,{BUDGET}")
        for f in range(files_per_camera):
            p = data / f"camera_id={cid}" / f"date=2024-05-{f + 1:02d}"
            p.mkdir(parents=True)
            pq.write_table(make_detections(rows_per_file, "3d", seed=100 * c + f), p / "part-0.parquet",
                           row_group_size=131_072)
            total += rows_per_file
    (reg / "cameras.csv").write_text("\n".join(lines) + "\n")
    return data, reg / "cameras.csv", total


def measure(cameras: int = 4, files_per_camera: int = 2, rows_per_file: int = 400_000, workers: int = 2,
            repeats: int = 2, workdir: str | None = None) -> dict:
    from footprint_uq.batch import fleet

    distributed = fleet.require_dask()
    res = {"cameras": cameras, "files": cameras * files_per_camera, "workers": workers, "repeats": repeats}
    with tempfile.TemporaryDirectory(dir=workdir) as tmp:
        data, reg, total = make_dataset(Path(tmp), cameras, files_per_camera, rows_per_file)
        res["rows"] = total
        registry = fleet.load_registry(reg)
        out = Path(tmp) / "out"

        def once(client=None) -> float:
            shutil.rmtree(out, ignore_errors=True)
            t0 = time.perf_counter()
            s = fleet.process_fleet(registry, data, out, client=client, progress=False)
            dt = time.perf_counter() - t0
            assert s.rows_out == total and s.consistent
            return dt

        fleet.process_fleet(registry, data, out, progress=False)  # warm-up (numba cache)
        t_in = statistics.median(once() for _ in range(repeats))
        cluster = distributed.LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                                           dashboard_address=":0")
        try:
            with distributed.Client(cluster) as client:
                client.run(lambda: __import__("footprint_uq.batch.fleet"))
                once(client)  # warm-up of the workers
                t_dask = statistics.median(once(client) for _ in range(repeats))
        finally:
            cluster.close()
    res.update(in_process_footprints_per_s=total / t_in, in_process_s=t_in,
               dask_footprints_per_s=total / t_dask, dask_s=t_dask, dask_speedup=t_in / t_dask)
    return res


def run(quick: bool = False) -> list[dict]:
    """Rows for ``bench/run.py`` (section ``dask``): in-process and local 2-worker cluster."""
    res = measure(rows_per_file=100_000 if quick else 400_000, repeats=1 if quick else 2)
    base = {"runs": res["repeats"]}
    return [
        {**base, "case": f"fleet in-process, {res['rows']:,} rows, {res['files']} files",
         "median_ms": 1e3 * res["in_process_s"],
         "notes": f"{res['in_process_footprints_per_s'] / 1e6:.2f} M footprints/s"},
        {**base, "case": f"fleet on a local Dask cluster, {res['workers']} workers",
         "median_ms": 1e3 * res["dask_s"],
         "notes": f"{res['dask_footprints_per_s'] / 1e6:.2f} M footprints/s, {res['dask_speedup']:.2f}x in-process",
         **{k: v for k, v in res.items() if k != "repeats"}},
    ]


def report(res: dict) -> str:
    return "\n".join([
        f"fleet batch, {res['rows']:,} detections in {res['files']} files of {res['cameras']} cameras "
        f"(3D boxes, Parquet -> partitioned Parquet), median of {res['repeats']}",
        "| path | footprints/s | time | ratio to in-process |", "|---|---|---|---|",
        f"| in-process | {res['in_process_footprints_per_s'] / 1e6:.2f} M/s | {res['in_process_s']:.2f} s | 1.00 |",
        f"| Dask local cluster, {res['workers']} workers | {res['dask_footprints_per_s'] / 1e6:.2f} M/s | "
        f"{res['dask_s']:.2f} s | {res['dask_speedup']:.2f} |"])


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cameras", type=int, default=4)
    ap.add_argument("--files-per-camera", type=int, default=2)
    ap.add_argument("--rows-per-file", type=int, default=400_000)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--repeats", type=int, default=2)
    ap.add_argument("--json", default=None)
    a = ap.parse_args(argv)
    res = measure(a.cameras, a.files_per_camera, a.rows_per_file, a.workers, a.repeats)
    print(report(res))
    if a.json:
        atomic_write_text(a.json, json.dumps(res, indent=2) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
