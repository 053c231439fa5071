"""Ground-control-point solves in weak geometry (issue 21): does a result reported usable hold its 95 % regions?

For each regime of ``tests/gcp_campaigns.py`` (``regime_campaign``; seeded):

* **documented** -- 6-20 points over the image, 0.5-2 px clicks, known intrinsics;
* **corner** -- 4-5 points in one corner of the image, 5 px clicks, known intrinsics;
* **clustered** -- 6-8 points within +-150 px of one pixel, 5 px clicks, known intrinsics;
* **lens** -- the focal length solved, the true lens mildly distorted (k1 ~ U(-0.15, 0.05)): by default k1 is
  solved with its prior (``lens_k1_sigma`` 0.1); the row **lens, k1 = 0 assumed** (``lens_k1_sigma=0``) shows
  the k1 score test flagging what the old model got wrong.

Per regime: the share of results reported usable, and among them the true pose inside the 95 % region of the
solved parameters, and the test pixels (3 per campaign, anywhere in the image; and those the control points
support, ``GCPSolution.support``) whose true ground point lies inside the 95 % ellipse; every other result is
counted under its first reason.  Target: >= 93 % in every regime among usable results.

    PYTHONPATH=src:tests python bench/bench_gcp_regimes.py [N=300] [--rows 1,2] [--out bench/results/gcp_regimes.json]
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))

from footprint_uq.io.atomic import atomic_write_text
from gcp_campaigns import evaluate, table_row  # noqa: E402

ROWS = (("documented", "documented", {}), ("corner", "corner", {}), ("clustered", "clustered", {}),
        ("lens (k1 solved with its prior)", "lens", {}), ("lens, k1 = 0 assumed", "lens", {"lens_k1_sigma": 0.0}))


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("n", nargs="?", type=int, default=300, help="campaigns per regime")
    ap.add_argument("--seed", type=int, default=2026)
    ap.add_argument("--out", default=None, help="JSON file of the table")
    ap.add_argument("--rows", default=None, help="comma-separated row numbers (1-based) to run; default all")
    a = ap.parse_args(argv)
    out = {"n": a.n, "seed": a.seed, "rows": {}}
    print("| regime | usable | true pose in 95 % region | test pixels in 95 % ellipse (supported / all) | "
          "flagged or refused (first reason) |")
    print("|---|---|---|---|---|")
    pick = [int(i) - 1 for i in a.rows.split(",")] if a.rows else range(len(ROWS))
    for label, regime, opts in (ROWS[i] for i in pick):
        t = time.perf_counter()
        row = table_row(evaluate(regime, a.n, seed=a.seed, **opts))
        row["elapsed_s"] = round(time.perf_counter() - t, 1)
        out["rows"][label] = row
        reasons = ", ".join(f"{k} {v}" for k, v in sorted(row["reasons"].items(), key=lambda kv: -kv[1])) or "-"
        print(f"| {label} | {row['usable']}/{row['n']} | {100 * row['pose_in']:.1f} % | "
              f"{100 * row['pix_in_supported']:.1f} % ({row['pix_supported']}) / {100 * row['pix_in_all']:.1f} % | "
              f"{reasons} |", flush=True)
    if a.out:
        atomic_write_text(a.out, json.dumps(out, indent=2) + "\n")
    return out


if __name__ == "__main__":
    main()
