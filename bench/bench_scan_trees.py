"""The frame scanner and the untracked compact frame of two source trees, A/B, alternating in one session.

    PYTHONPATH=src .venv/bin/python bench/bench_scan_trees.py --ref-src /path/to/other/src [--rounds 3]
        [--repeats 300] [--scan-repeats 3000] [--out FILE]

Each round runs, in a fresh process per tree (this checkout's ``src`` first, then ``--ref-src``):

* ``scan_frame_us`` / ``scan_frame_cpu_us``: ``service.frame_scan.scan_frame`` of ``bench_scan.py``'s frame
  (100 2-D boxes, ~10.4 kB), median wall and thread-CPU time per call over ``--scan-repeats`` calls in blocks of
  100 (the CPU figure is immune to waiting for a core on a shared machine);
* ``bench_frame.measure`` of the untracked compact frame (``frame_bytes_us``, ``boxes2d_us`` and their ratio,
  interleaved in one loop, ``--repeats`` frames).

Per tree the medians over the rounds; nothing is asserted.  The reference tree is only read (its numba caches:
give a copy of it if they may be stale).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent


def one_tree(repeats: int, scan_repeats: int) -> dict:
    """The figures of the tree this process imports (run in a child process)."""
    from bench_frame import measure
    from bench_scan import frame_payload

    from footprint_uq.service.frame_scan import scan_frame

    text = frame_payload(100)
    for _ in range(200):
        scan_frame(text)
    wall, cpu = [], []
    for _ in range(max(scan_repeats // 100, 1)):
        t0, c0 = time.perf_counter(), time.thread_time()
        for _ in range(100):
            scan_frame(text)
        wall.append((time.perf_counter() - t0) / 100)
        cpu.append((time.thread_time() - c0) / 100)
    got = measure(False, "compact", 100, repeats)
    return {"scan_frame_us": round(1e6 * float(np.median(wall)), 3),
            "scan_frame_cpu_us": round(1e6 * float(np.median(cpu)), 3),
            **{k: got[k] for k in ("frame_bytes_us", "boxes2d_us", "frame_bytes_over_boxes2d")}}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--ref-src", type=Path, default=None, help="the other tree's src folder (required)")
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--repeats", type=int, default=300)
    ap.add_argument("--scan-repeats", type=int, default=3000)
    ap.add_argument("--out", type=Path, default=None)
    ap.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.child:
        print(json.dumps(one_tree(args.repeats, args.scan_repeats)))
        return 0
    if args.ref_src is None:
        ap.error("--ref-src is required")
    trees = {"this": ROOT / "src", "ref": args.ref_src.resolve()}
    runs: dict = {k: [] for k in trees}
    load0 = os.getloadavg()[0]
    for r in range(args.rounds):
        for tag, src in trees.items():
            env = dict(os.environ, PYTHONPATH=f"{src}{os.pathsep}{ROOT / 'bench'}")
            out = subprocess.run([sys.executable, __file__, "--child", "--repeats", str(args.repeats),
                                  "--scan-repeats", str(args.scan_repeats)], env=env, check=True,
                                 capture_output=True, text=True).stdout
            runs[tag].append(json.loads(out.strip().splitlines()[-1]))
            print(f"round {r} {tag:4s} " + "  ".join(f"{k} {v}" for k, v in runs[tag][-1].items()), flush=True)
    res = {"what": "bench/bench_scan_trees.py: scan_frame of the 100-box frame and the untracked compact frame "
                   f"(bench_frame.measure, {args.repeats} repeats) of this tree and {args.ref_src}, a fresh "
                   f"process each, {args.rounds} rounds alternating; medians over the rounds",
           "date": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()), "cores": os.cpu_count(),
           "load_average_1min_start": load0, "load_average_1min_end": os.getloadavg()[0], "rounds": runs,
           "median": {tag: {k: round(float(np.median([g[k] for g in got])), 3) for k in got[0]}
                      for tag, got in runs.items()}}
    for tag, m in res["median"].items():
        print(f"median {tag:4s} " + "  ".join(f"{k} {v}" for k, v in m.items()))
    if args.out:
        args.out.write_text(json.dumps(res, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
