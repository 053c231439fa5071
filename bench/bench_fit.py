"""Wall time and peak memory of the budget fit on many pairs (issue 20): 50 cameras, 10^5 and 10^6 pairs.

Usage::

    .venv/bin/python bench/bench_fit.py [--sizes 100000,1000000] [--cameras 50] [--out bench/results] [--dense]

Each size runs in a fresh process (its own peak RSS, ``VmHWM``).  The synthetic campaign
(``footprint_uq.validation.campaigns.synthetic_campaign_chunks``, the calibration error drawn once per
camera; 2000 objects a chunk) is streamed into the fit's compact records (``fit.compact_inputs``: only the
Jacobian columns that carry variance), then ``fit_compact`` with pan, tilt, height and the per-object term
free is timed, then the cross-validated coverage (leave-one-object-out, 10 folds, and leave-one-camera-out;
on the reported subsample of ``CV_MAX_PAIRS`` pairs).  ``--dense`` times the former path instead (the whole
campaign in memory, ``fit_budget`` on the arrays).  Writes ``DIR/bench_fit.json`` and prints a table.

``--job``: the whole ``calibrate budget`` job instead
(:func:`footprint_uq.viz.budget_fit_run.run_budget_fit`: a Parquet pairs table of bench/bench_validate.py's
synthetic probe-vehicle campaign, 50 cameras with a registry, read in chunks -> bottom-centre contact ->
pairs -> compact records -> fit -> cross-validated coverage -> budget.yaml, fit.json), one fresh process per
size (its wall time and ``VmHWM``); writes ``DIR/bench_fit_job.json``.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from pathlib import Path

from footprint_uq.io.atomic import atomic_write_text

ROOT = Path(__file__).resolve().parents[1]


def _hwm_mb() -> float:
    line = next(x for x in open("/proc/self/status") if x.startswith("VmHWM:"))
    return int(line.split()[1]) / 1024


def one(n: int, cameras: int, dense: bool) -> dict:
    sys.path.insert(0, str(ROOT / "src"))
    from footprint_uq.validation import fit as F
    from footprint_uq.validation.campaigns import synthetic_campaign, synthetic_campaign_chunks

    truth = {"pan_deg": 0.1, "tilt_deg": 0.05, "height_m": 0.2}
    free = ["pan_deg", "tilt_deg", "height_m", "object_m"]
    rss0 = _hwm_mb()
    t0 = time.perf_counter()
    row: dict = {"path": "dense" if dense else "streamed"}
    if dense:
        c = synthetic_campaign(truth, cameras, n // cameras, object_sigma_m=0.3, seed=1)
        t1 = time.perf_counter()
        fit = F.fit_budget(c.residual_m, c.dxy_dp, c.cov_object_m2, c.group, free=free)
        n_pairs = int(c.residual_m.shape[0])
    else:
        chunks = (x[:4] for x in synthetic_campaign_chunks(truth, cameras, n // cameras, object_sigma_m=0.3, seed=1,
                                                            batch=2000))
        data = F.compact_inputs(chunks, free=free)
        t1 = time.perf_counter()
        fit = F.fit_compact(data, free=free)
        n_pairs = data.n
        row["records_mb"] = sum(a.nbytes for p in data.parts() for a in p[:5]) / 2**20
        row["records"] = type(data).__name__
    t2 = time.perf_counter()
    row["fit_s"] = t2 - t1
    row["peak_rss_fit_mb"] = _hwm_mb()
    if not dense:
        cv = [F.cross_validate_compact(data, free=free, by=by) for by in ("object", "group")]
        row["cv_s"] = time.perf_counter() - t2
        row["cv_n_sampled"] = cv[0].n_sampled
        row["cv_coverage_95"] = {c.by: float(c.coverage[2]) for c in cv}
    row.update(pairs=n_pairs, cameras=cameras, input_s=t1 - t0, converged=fit.converged,
               peak_rss_mb=_hwm_mb(), rss_before_mb=rss0, sigmas={k: t.sigma for k, t in fit.terms.items()},
               load_avg=os.getloadavg()[0])
    return row


_JOB = r"""
import json, sys, time
t0 = time.perf_counter()
from footprint_uq.uncertainty.budget import load_budget
from footprint_uq.viz.budget_fit_run import run_budget_fit
t1 = time.perf_counter()
summary, files = run_budget_fit(sys.argv[1], sys.argv[2], base_budget=load_budget(sys.argv[3]), registry=sys.argv[4],
                                fsync=False)
t2 = time.perf_counter()
hwm = [line for line in open("/proc/self/status") if line.startswith("VmHWM:")][0]
fit = summary["fit"]
print(json.dumps({"pairs": fit["n_objects"], "groups": fit["n_groups"], "elapsed_s": t2 - t1, "import_s": t1 - t0,
                  "peak_rss_mb": int(hwm.split()[1]) / 1024.0, "converged": fit["converged"],
                  "sigmas": {k: t["sigma"] for k, t in fit["terms"].items()},
                  "cross_validation": summary["cross_validation"]}))
"""


def job(sizes, cameras: int) -> list[dict]:
    """The ``calibrate budget`` job on pairs tables of each size (fresh process each)."""
    import tempfile

    sys.path.insert(0, str(ROOT / "bench"))
    from bench_validate import BUDGET, write_campaign

    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        budget_file = folder / "budget.json"
        budget_file.write_text(json.dumps(BUDGET.to_dict()))
        for n in sizes:
            path, reg = write_campaign(folder, n, cameras)
            p = subprocess.run([sys.executable, "-c", _JOB, str(path), str(folder / f"out_{n}"), str(budget_file),
                                str(reg)], capture_output=True, text=True, timeout=3600)
            if p.returncode != 0:
                raise RuntimeError(p.stderr[-3000:])
            r = json.loads(p.stdout.strip().splitlines()[-1])
            r.update(cameras=cameras, load_avg=os.getloadavg()[0])
            rows.append(r)
            cv = "; ".join(f"leave-one-{k}-out 95 %: {100 * c['coverage'][2]:.1f} % on {c['n_sampled']} pairs"
                           for k, c in r["cross_validation"].items())
            print(f"{r['pairs']:>9d} pairs, {cameras} cameras: calibrate budget {r['elapsed_s']:.1f} s, peak RSS "
                  f"{r['peak_rss_mb']:.0f} MB, converged {r['converged']}; {cv}; load {r['load_avg']:.1f}")
    return rows


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", default="100000,1000000")
    ap.add_argument("--cameras", type=int, default=50)
    ap.add_argument("--out", type=Path, default=ROOT / "bench" / "results")
    ap.add_argument("--dense", action="store_true", help="the former path: every array in memory, fit_budget")
    ap.add_argument("--job", action="store_true", help="the whole `calibrate budget` job on a pairs table")
    ap.add_argument("--one", type=int, default=None, help=argparse.SUPPRESS)
    a = ap.parse_args(argv)
    if a.one is not None:
        print(json.dumps(one(a.one, a.cameras, a.dense)))
        return 0
    if a.job:
        rows = job([int(s) for s in a.sizes.split(",")], a.cameras)
        a.out.mkdir(parents=True, exist_ok=True)
        atomic_write_text((a.out / "bench_fit_job.json"), json.dumps(rows, indent=2) + "\n")
        return 0
    rows = []
    for n in (int(s) for s in a.sizes.split(",")):
        p = subprocess.run([sys.executable, __file__, "--one", str(n), "--cameras", str(a.cameras)]
                           + (["--dense"] if a.dense else []), capture_output=True, text=True, check=True)
        rows.append(json.loads(p.stdout.strip().splitlines()[-1]))
        r = rows[-1]
        cv = f", cross-validation {r['cv_s']:.1f} s on {r['cv_n_sampled']} pairs" if "cv_s" in r else ""
        print(f"{r['pairs']:>9d} pairs, {r['cameras']} cameras ({r['path']}): input {r['input_s']:.1f} s, fit "
              f"{r['fit_s']:.1f} s{cv}, peak RSS {r['peak_rss_mb']:.0f} MB (at the fit's end "
              f"{r['peak_rss_fit_mb']:.0f} MB), converged {r['converged']}, load {r['load_avg']:.1f}")
    a.out.mkdir(parents=True, exist_ok=True)
    name = "bench_fit_dense.json" if a.dense else "bench_fit.json"
    atomic_write_text((a.out / name), json.dumps(rows, indent=2) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
