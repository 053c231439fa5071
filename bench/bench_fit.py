"""Wall time and peak memory of the budget fit on many pairs (issue 20): 50 cameras, 10^5 and 10^6 pairs.

Usage::

    .venv/bin/python bench/bench_fit.py [--sizes 100000,1000000] [--cameras 50] [--out bench/results]

Each size runs in a fresh process (peak RSS of that process, ``ru_maxrss``): a synthetic campaign
(``footprint_uq.validation.campaigns``, the calibration error drawn once per camera) is built, then
``fit_budget`` with pan, tilt, height and the per-object term free is timed (the campaign's construction is
not).  Writes ``DIR/bench_fit.json`` and prints a table.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def one(n: int, cameras: int) -> dict:
    sys.path.insert(0, str(ROOT / "src"))
    from footprint_uq.validation.campaigns import synthetic_campaign
    from footprint_uq.validation.fit import fit_budget

    c = synthetic_campaign({"pan_deg": 0.1, "tilt_deg": 0.05, "height_m": 0.2}, cameras, n // cameras,
                           object_sigma_m=0.3, seed=1)
    rss0 = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    t0 = time.perf_counter()
    fit = fit_budget(c.residual_m, c.dxy_dp, c.cov_object_m2, c.group,
                     free=["pan_deg", "tilt_deg", "height_m", "object_m"])
    dt = time.perf_counter() - t0
    return {"pairs": int(c.residual_m.shape[0]), "cameras": cameras, "fit_s": dt, "converged": fit.converged,
            "peak_rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
            "rss_before_fit_mb": rss0 / 1024, "inputs_mb": (c.dxy_dp.nbytes + c.residual_m.nbytes
                                                             + c.cov_object_m2.nbytes) / 2**20,
            "sigmas": {k: t.sigma for k, t in fit.terms.items()}, "load_avg": os.getloadavg()[0]}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", default="100000,1000000")
    ap.add_argument("--cameras", type=int, default=50)
    ap.add_argument("--out", type=Path, default=ROOT / "bench" / "results")
    ap.add_argument("--one", type=int, default=None, help=argparse.SUPPRESS)
    a = ap.parse_args(argv)
    if a.one is not None:
        print(json.dumps(one(a.one, a.cameras)))
        return 0
    rows = []
    for n in (int(s) for s in a.sizes.split(",")):
        p = subprocess.run([sys.executable, __file__, "--one", str(n), "--cameras", str(a.cameras)],
                           capture_output=True, text=True, check=True)
        rows.append(json.loads(p.stdout.strip().splitlines()[-1]))
        r = rows[-1]
        print(f"{r['pairs']:>9d} pairs, {r['cameras']} cameras: fit {r['fit_s']:.1f} s, peak RSS "
              f"{r['peak_rss_mb']:.0f} MB (inputs {r['inputs_mb']:.0f} MB), converged {r['converged']}, "
              f"load {r['load_avg']:.1f}")
    a.out.mkdir(parents=True, exist_ok=True)
    (a.out / "bench_fit.json").write_text(json.dumps(rows, indent=2) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
