"""Peak memory of the streaming batch at two input sizes (1x and 10x): it must not grow with the file.

Each size runs in a fresh subprocess (``footprint_uq.batch.process.process_file``, Parquet ->
Parquet) whose address space is capped with ``RLIMIT_AS`` (``--limit-mb``, default 2048 MB); the
child reports its own peak resident set size (``VmHWM`` of ``/proc/self/status``; ``ru_maxrss``
would include the parent's peak, which Linux carries across fork and exec).
The 10x input's data (detections + footprints, decoded in memory: about 2.4 GB for 10 million
3D boxes) is larger than the cap and about five times the peak resident memory, so finishing at all
shows the streaming; the two peaks show that memory depends on ``--chunk-rows``, not on the file
size.  The 1x input should span several chunks (>= 4) so that the pipeline is full in both runs.

Run ``.venv/bin/python bench/bench_memory.py [--rows 1000000] [--factor 10]``; :func:`measure`
returns the figures, :func:`run` the rows of ``bench/run.py``'s table.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

import pyarrow.parquet as pq

from footprint_uq.io.atomic import atomic_write_text

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_batch import BUDGET, CAMERA, make_detections  # noqa: E402

_CHILD = r"""
import json, resource, sys, time
limit = int(sys.argv[4]) * 2**20
if limit > 0:
    resource.setrlimit(resource.RLIMIT_AS, (limit, limit))
from footprint_uq import PanTiltCamera
from footprint_uq.batch.process import process_file
cam = PanTiltCamera(**json.loads(sys.argv[5]))
t0 = time.perf_counter()
s = process_file(cam, sys.argv[6], sys.argv[1], sys.argv[2], chunk_rows=int(sys.argv[3]), progress=False,
                 summary=False)
dt = time.perf_counter() - t0
try:  # VmHWM: peak RSS of this process image (ru_maxrss keeps the parent's peak across fork + exec)
    hwm = [line for line in open("/proc/self/status") if line.startswith("VmHWM:")][0]
    peak = int(hwm.split()[1]) / 1024.0
except (OSError, IndexError):
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
print(json.dumps({"rows_in": s.rows_in, "rows_out": s.rows_out, "rows_error": s.rows_error, "elapsed_s": dt,
                  "peak_rss_mb": peak}))
"""


# fewer malloc arenas and BLAS threads: less reserved (not used) address space under RLIMIT_AS
_CHILD_ENV = {"PYTHONWARNINGS": "ignore", "MALLOC_ARENA_MAX": "2", "OPENBLAS_NUM_THREADS": "1"}


def _write_input(path: Path, rows: int, block: int = 500_000) -> tuple[int, float]:
    """Write ``rows`` 3D-box detections block by block; return (bytes on disk, decoded MB)."""
    writer = None
    decoded = 0
    done = 0
    i = 0
    while done < rows:
        n = min(block, rows - done)
        t = make_detections(n, "3d", seed=i)
        decoded += t.nbytes
        if writer is None:
            writer = pq.ParquetWriter(path, t.schema)
        writer.write_table(t, row_group_size=131_072)
        done += n
        i += 1
    writer.close()
    return path.stat().st_size, decoded / 1e6


def measure(rows: int = 1_000_000, factor: int = 10, chunk_rows: int = 131_072, limit_mb: int = 2048,
            workdir: str | None = None) -> dict:
    """Peak RSS (MB) of the batch on ``rows`` and ``factor * rows`` detections."""
    res = {"chunk_rows": chunk_rows, "limit_mb": limit_mb, "sizes": []}
    with tempfile.TemporaryDirectory(dir=workdir) as tmp:
        for mult in (1, factor):
            n = rows * mult
            src = Path(tmp) / f"det_{mult}x.parquet"
            dst = Path(tmp) / f"out_{mult}x.parquet"
            size, decoded_in = _write_input(src, n)
            p = subprocess.run([sys.executable, "-c", _CHILD, str(src), str(dst), str(chunk_rows), str(limit_mb),
                                json.dumps(CAMERA), BUDGET], capture_output=True, text=True,
                               env={**os.environ, **_CHILD_ENV})
            if p.returncode != 0:
                raise RuntimeError(f"{mult}x run failed (limit {limit_mb} MB): {p.stderr.strip()[-400:]}")
            child = json.loads(p.stdout.strip().splitlines()[-1])
            md = pq.read_metadata(dst)
            out_rows = md.num_rows
            out_mb = sum(md.row_group(i).total_byte_size for i in range(md.num_row_groups)) / 1e6
            res["sizes"].append({"factor": mult, "rows": n, "input_file_mb": size / 1e6,
                                 "input_decoded_mb": decoded_in,
                                 "output_file_mb": dst.stat().st_size / 1e6, "output_uncompressed_mb": out_mb,
                                 "output_rows": out_rows, **child})
            src.unlink()
            dst.unlink()
    a, b = res["sizes"]
    res["peak_rss_ratio"] = b["peak_rss_mb"] / a["peak_rss_mb"]
    return res


def run(quick: bool = False) -> list[dict]:
    """Rows for ``bench/run.py`` (section ``memory``): 1x and 10x inputs."""
    res = measure(rows=500_000 if quick else 1_000_000, factor=10)
    out = []
    for s in res["sizes"]:
        out.append({"case": f"streaming batch, {s['factor']}x input ({s['rows']:,} rows, 3D boxes)",
                    "median_ms": 1e3 * s["elapsed_s"], "runs": 1,
                    "target": "peak RSS flat in the input size", "met": res["peak_rss_ratio"] < 1.2,
                    "notes": f"peak RSS {s['peak_rss_mb']:.0f} MB (address space capped at {res['limit_mb']} MB); "
                             f"data {s['input_decoded_mb']:.0f} MB in + {s['output_uncompressed_mb']:.0f} MB out "
                             f"(decoded); chunk_rows {res['chunk_rows']:,}; 10x/1x peak ratio "
                             f"{res['peak_rss_ratio']:.2f}",
                    **s})
    return out


def report(res: dict) -> str:
    lines = [f"streaming batch peak memory (chunk_rows {res['chunk_rows']:,}, address space capped at "
             f"{res['limit_mb']} MB)",
             "| input | rows | input file | input decoded | output uncompressed | peak RSS | time |",
             "|---|---|---|---|---|---|---|"]
    for s in res["sizes"]:
        lines.append(f"| {s['factor']}x | {s['rows']:,} | {s['input_file_mb']:.0f} MB | "
                     f"{s['input_decoded_mb']:.0f} MB | {s['output_uncompressed_mb']:.0f} MB | "
                     f"{s['peak_rss_mb']:.0f} MB | {s['elapsed_s']:.1f} s |")
    lines.append(f"peak RSS {res['sizes'][1]['factor']}x / 1x = {res['peak_rss_ratio']:.2f}")
    return "\n".join(lines)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rows", type=int, default=1_000_000)
    ap.add_argument("--factor", type=int, default=10)
    ap.add_argument("--chunk-rows", type=int, default=131_072)
    ap.add_argument("--limit-mb", type=int, default=2048)
    ap.add_argument("--json", default=None)
    a = ap.parse_args(argv)
    res = measure(a.rows, a.factor, a.chunk_rows, a.limit_mb)
    print(report(res))
    if a.json:
        atomic_write_text(a.json, json.dumps(res, indent=2) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
