"""Atheris (libFuzzer) harness for the detection readers (issue 11); run by tests/test_fuzz.py.

    python tests/fuzz_readers.py CORPUS_DIR -runs=20000 -seed=1 -max_total_time=60

Each input's first byte picks the format (CSV, JSON Lines, Parquet); the rest is the file.
Allowed outcomes: the file is read, or refused with :class:`footprint_uq.errors.InputError`
(one line).  Anything else -- another exception, a row lost (CSV / JSON Lines: rows + malformed
rows != physical lines), a row number out of order -- is a crash that libFuzzer reports with the
input that caused it (saved as ``crash-*`` in the working folder).
"""

from __future__ import annotations

import atexit
import os
import shutil
import sys
import tempfile

import atheris

with atheris.instrument_imports(include=["footprint_uq.batch.readers"]):
    from footprint_uq.batch.readers import open_detections
    from footprint_uq.errors import InputError

EXT = (".csv", ".jsonl", ".parquet")
NUMERIC = ("u_min_px", "v_min_px", "u_max_px", "v_max_px")
_DIR = tempfile.mkdtemp(prefix="fuzz-readers-")
atexit.register(shutil.rmtree, _DIR, True)


def physical_lines(data: bytes, header: bool) -> int:
    n = data.count(b"\n") + (1 if data and not data.endswith(b"\n") else 0)
    return max(n - 1, 0) if header else n


def check(data: bytes) -> None:
    if not data:
        return
    ext = EXT[data[0] % 3]
    body = data[1:]
    path = os.path.join(_DIR, "in" + ext)
    with open(path, "wb") as f:
        f.write(body)
    try:
        r = open_detections(path, chunk_rows=7)
        cols = [c for c in NUMERIC if c in r.columns] or [r.columns[0]] if r.columns else list(NUMERIC[:1])
        r.select(tuple(cols))
        rows = []
        for ch in r:
            assert ch.rows.size == ch.table.num_rows, "rows and table disagree"
            rows += ch.rows.tolist() + [m[0] for m in ch.malformed]
    except InputError:
        return
    if ext == ".parquet":
        return
    n = physical_lines(body, header=ext == ".csv")
    assert sorted(rows) == list(range(n)), f"rows {len(rows)} != physical lines {n}"
    assert r.lines == n, f"reader counted {r.lines} lines, the file has {n}"


def main() -> None:
    atheris.Setup(sys.argv, check)
    atheris.Fuzz()


if __name__ == "__main__":
    main()
