"""Bounded fuzzing of the detection readers with atheris (issue 11): no crash, no row lost.

Runs ``tests/fuzz_readers.py`` in a subprocess for ``FOOTPRINT_UQ_FUZZ_SECONDS`` seconds (default
60, the CI budget) or 200,000 inputs, whichever comes first, with a fixed libFuzzer seed
(``FOOTPRINT_UQ_FUZZ_SEED``, default 11) from a seed corpus of valid and broken files.  A crash
leaves its input as ``crash-*`` in the test's temporary folder and the test prints its path.
"""

from __future__ import annotations

import io
import os
import resource
import subprocess
import sys
from pathlib import Path

import pytest

pytest.importorskip("atheris")

HARNESS = Path(__file__).with_name("fuzz_readers.py")
SRC = Path(__file__).resolve().parents[1] / "src"
HEADER = b"frame,object_id,u_min_px,v_min_px,u_max_px,v_max_px\n"


def _corpus(d: Path) -> None:
    import pyarrow as pa
    import pyarrow.parquet as pq

    d.mkdir()
    csv = HEADER + b"1,a,900,500,980,560\n2,\"b\",1,2,3,4\n"
    seeds = {
        "csv": b"\x00" + csv, "csv_quote": b"\x00" + csv + b'3,"c,1,2,3,4\n', "csv_crlf": b"\x00" + csv.replace(
            b"\n", b"\r\n"), "csv_bom": b"\x00\xef\xbb\xbf" + csv,
        "jsonl": b"\x01" + b'{"frame": 1, "u_min_px": 900, "v_min_px": 500, "u_max_px": 980, "v_max_px": 560}\n'
                           b'{"frame": 1e23}\n\n[1]\n', "jsonl_null": b"\x01null\n{}\n",
    }
    buf = io.BytesIO()
    pq.write_table(pa.table({"frame": [1, 2], "u_min_px": [900.0, 1.0], "v_min_px": [500.0, 2.0],
                             "u_max_px": [980.0, 3.0], "v_max_px": [560.0, 4.0]}), buf)
    seeds["parquet"] = b"\x02" + buf.getvalue()
    for name, data in seeds.items():
        (d / name).write_bytes(data)


def test_fuzz_readers(tmp_path):
    seconds = int(os.environ.get("FOOTPRINT_UQ_FUZZ_SECONDS", "60"))
    seed = int(os.environ.get("FOOTPRINT_UQ_FUZZ_SEED", "11"))
    corpus = tmp_path / "corpus"
    _corpus(corpus)
    env = {**os.environ, "PYTHONPATH": str(SRC) + os.pathsep + os.environ.get("PYTHONPATH", "")}
    # libFuzzer's RSS limit reads the process's peak RSS, which Linux carries over from this (vfork-ing) worker
    # through exec: a worker that ran a memory-heavy test before (4.9 GB) made the harness "out of memory" at its
    # first input. The harness gets 4 GB on top of what it inherits.
    inherited_mb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss // 1024
    args = [sys.executable, str(HARNESS), str(corpus), f"-seed={seed}", "-runs=200000",
            f"-max_total_time={seconds}", "-max_len=4096", "-timeout=20", f"-rss_limit_mb={inherited_mb + 4096}"]
    r = subprocess.run(args, cwd=tmp_path, env=env, capture_output=True, text=True, timeout=seconds + 240)
    crashes = sorted(tmp_path.glob("crash-*")) + sorted(tmp_path.glob("timeout-*"))
    assert r.returncode == 0 and not crashes, (f"seed {seed}: {crashes}\n" + r.stderr[-4000:])
    assert "Done" in r.stderr, r.stderr[-2000:]
