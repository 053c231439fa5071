"""The motion fit's seeded campaigns (issue 36; docs/motion-fit.md): does the fitted manoeuvre noise hold the truth
in its 95 % interval, and do the fitted trackers' 95 % velocity / heading regions cover 95 %?

For each true density (calm 0, 0.5, 2.5, 5 m^2/s^3): ``--campaigns`` seeded campaigns (one camera, one draw of its
calibration error, ``--objects`` road users for ``--duration`` s at 30 Hz; :mod:`footprint_uq.tracking.
motion_campaigns`), all fitted in one streamed pass, then tracked again with each campaign's fitted model and with
the tracker's default (the prior) for comparison.  Writes JSON and Markdown; nothing is asserted here (the small
seeded version: ``tests/test_motion_fit.py::test_campaigns_interval_and_coverage_after_the_fit``).

    PYTHONPATH=src .venv/bin/python bench/motion_fit_campaigns.py [--campaigns 200] [--objects 10] \
        [--json bench/results/motion-fit-campaigns.json] [--md bench/results/motion-fit-campaigns.md]
"""

from __future__ import annotations

import argparse
import json
import time

import numpy as np

from footprint_uq.tracking.motion_campaigns import run_campaigns
from footprint_uq.tracking.motion_fit import MotionGrid
from footprint_uq.uncertainty.budget import load_budget

Q_TRUE = (0.0, 0.5, 2.5, 5.0)


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--campaigns", type=int, default=200)
    ap.add_argument("--objects", type=int, default=10)
    ap.add_argument("--duration", type=float, default=4.0)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--modes", choices=["auto", "one"], default="auto")
    ap.add_argument("--budget", default="basler1@deg", help="the cameras' budget (preset or file)")
    ap.add_argument("--budget-scale", type=float, default=1.0,
                    help="its sigmas times this (a small calibration error: the consider model's linear regime)")
    ap.add_argument("--json", default=None)
    ap.add_argument("--md", default=None)
    a = ap.parse_args(argv)
    grid = MotionGrid() if a.modes == "auto" else MotionGrid(imm_q_m2ps3=np.zeros(0))
    budget = load_budget(a.budget) if a.budget_scale == 1.0 else load_budget(a.budget).scaled(a.budget_scale)
    rows = []
    for q in Q_TRUE:
        t0 = time.perf_counter()
        r = run_campaigns(q, n_campaigns=a.campaigns, n_objects=a.objects, duration_s=a.duration, seed=a.seed,
                          grid=grid, budget=budget)
        row = {"q_true_m2ps3": q, "budget": a.budget, "budget_scale": a.budget_scale, "campaigns": a.campaigns,
               "objects": a.objects, "duration_s": a.duration,
               "identified": float(r.identified.mean()), "truth_in_interval": float(r.within.mean()),
               "q_hat_median": float(np.median(r.q_hat)), "q_hat_p05": float(np.percentile(r.q_hat, 5)),
               "q_hat_p95": float(np.percentile(r.q_hat, 95)),
               "interval_rel_width_median": float(np.median((np.where(np.isfinite(r.ci_hi), r.ci_hi, np.nan)
                                                             - r.ci_lo) / np.maximum(r.q_hat, 1e-12))),
               "fitted_coverage_velocity": r.coverage_velocity, "fitted_coverage_heading": r.coverage_heading,
               "prior_coverage_velocity": r.prior_coverage_velocity, "prior_coverage_heading": r.prior_coverage_heading,
               "n_velocity": r.n_velocity, "n_heading": r.n_heading, "elapsed_s": time.perf_counter() - t0}
        rows.append(row)
        print(json.dumps(row), flush=True)
    if a.json:
        with open(a.json, "w") as f:
            json.dump({"modes": a.modes, "seed": a.seed, "rows": rows}, f, indent=1)
    if a.md:
        lines = ["| q true (m^2/s^3) | truth in 95 % interval | median q fitted [5 %, 95 %] | velocity 95 % coverage: "
                 "fitted / prior | heading 95 % coverage: fitted / prior |", "|---|---|---|---|---|"]
        for r in rows:
            lines.append(f"| {r['q_true_m2ps3']:g} | {100 * r['truth_in_interval']:.1f} % | {r['q_hat_median']:.3g} "
                         f"[{r['q_hat_p05']:.3g}, {r['q_hat_p95']:.3g}] | {100 * r['fitted_coverage_velocity']:.1f} / "
                         f"{100 * r['prior_coverage_velocity']:.1f} % | {100 * r['fitted_coverage_heading']:.1f} / "
                         f"{100 * r['prior_coverage_heading']:.1f} % |")
        with open(a.md, "w") as f:
            f.write(f"{a.campaigns} campaigns x {a.objects} objects x {a.duration:g} s at 30 Hz per row, budget "
                    f"{a.budget} x {a.budget_scale:g}, seed {a.seed}, modes {a.modes}, the joint (exact) likelihood "
                    "(bench/motion_fit_campaigns.py)"
                    "\n\n" + "\n".join(lines) + "\n")


if __name__ == "__main__":
    main()
