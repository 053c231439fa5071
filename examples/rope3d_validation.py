"""Validate the uncertainty on one real labelled frame: the published Rope3D frame, three budgets.

    python examples/rope3d_validation.py [--out DIR]

The frame (tests/data/rope3d-demo: a Rope3D roadside camera, 1920x1080, 48 labels with a 2-D box and a
3-D box, 4 of them without a 3-D annotation) is read with its calibration (P2, denorm); each 2-D box's
bottom-centre is back-projected (``--contact bottom-centre``) and compared with the labelled bottom centre
of its 3-D box.  Printed: the table of docs/validation.md (coverage of the 50/90/95/99 % ellipses, mean
NEES, effective number of objects, verdict) and the coverage by range band; written: the figure
``validation_rope3d.png`` (docs/figures/validation-rope3d.png).  Then the same with the contact model
(``--contact footprint-centre``), and the budget fitted to these residuals (paper-style base with the free
per-object terms ``object_m`` and ``object_ground_m``: docs/budget-fit.md) judged leave-one-object-out.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from _common import output_dir
from matplotlib.figure import Figure

from footprint_uq.uncertainty.budget import ErrorBudget
from footprint_uq.validation.fit import cross_validate, fit_budget
from footprint_uq.validation.job import validate
from footprint_uq.validation.pairs import collect_pairs
from footprint_uq.validation.readers import read_kitti_folder

out = output_dir(__doc__.splitlines()[0], "rope3d_validation")
FRAME = Path(__file__).resolve().parents[1] / "tests" / "data" / "rope3d-demo"

BUDGETS = {
    "basler1": ErrorBudget.preset("basler1"),
    "basler1@deg": ErrorBudget.preset("basler1@deg"),
    # the issue's "budget of the paper's kind": angles 0.05 deg, ground 0.05 m / 0.1 deg, 1 px
    "paper-style": ErrorBudget(pan_deg=0.05, tilt_deg=0.05, roll_deg=0.05, ground_height_m=0.05,
                               ground_slope_deg=0.1, imaging_px=(1.0, 1.0), name="paper-style"),
}

results = {}
for name, budget in BUDGETS.items():
    res = validate(read_kitti_folder(FRAME), budget, objects_out=out / f"objects_{name}.csv", fsync=False)
    results[name] = res
# the contact model of issue 20 (class size priors + viewing geometry: the footprint centre, not the bottom edge)
contact = {name: validate(read_kitti_folder(FRAME), BUDGETS[name], contact="footprint-centre", fsync=False)
           for name in ("basler1@deg", "paper-style")}

first = next(iter(results.values())).summary
print(f"pairs {first['n_pairs']}, rows {first['rows']}; |error| median {first['error']['median_m']:.3f} m, "
      f"95th percentile {first['error']['p95_m']:.2f} m, max {first['error']['max_m']:.2f} m")
print(f"{'budget':<12} {'cov50':>6} {'cov90':>6} {'cov95':>6} {'cov99':>6} {'NEES':>6} {'n_eff':>6} "
      f"{'95% semi-major':>15}  verdict")
for name, res in results.items():
    s = res.summary
    cov = [c["empirical"] for c in s["coverage"]]
    semi = 2.4477 * np.median(res.accumulator.sample["sigma_major_m"])
    print(f"{name:<12} " + " ".join(f"{100 * c:5.1f}%" for c in cov)
          + f" {s['nees_test']['nees_mean']:6.2f} {s['nees_test']['n_eff']:6.2f} {semi:13.2f} m  {s['verdict']}")
print("footprint-centre contact:")
for name, res in contact.items():
    s = res.summary
    cov = [c["empirical"] for c in s["coverage"]]
    semi = 2.4477 * np.median(res.accumulator.sample["sigma_major_m"])
    print(f"{name:<12} " + " ".join(f"{100 * c:5.1f}%" for c in cov)
          + f" {s['nees_test']['nees_mean']:6.2f} {s['nees_test']['n_eff']:6.2f} {semi:13.2f} m  {s['verdict']}"
          + f"  (median |error| {s['error']['median_m']:.3f} m)")
# the budget fitted to these residuals (paper-style base, free per-object terms), judged leave-one-object-out
pairs = collect_pairs(read_kitti_folder(FRAME), BUDGETS["paper-style"], contact="footprint-centre")
u = pairs.subset(pairs.usable)
free = ("object_m", "object_ground_m")
fit = fit_budget(u.residual_m, u.dxy_dp, u.cov_object_m2, u.group, free=free, base_budget=BUDGETS["paper-style"])
cv = cross_validate(u.residual_m, u.dxy_dp, u.cov_object_m2, u.group, free=free, by="object",
                    base_budget=BUDGETS["paper-style"])
print("fitted (LOO)  " + " ".join(f"{100 * c:5.1f}%" for c in cv.coverage)
      + f"  object_m {fit.terms['object_m'].sigma:.3f} m, object_ground_m {fit.terms['object_ground_m'].sigma:.3f} m")
print("by range (basler1@deg; last column: footprint-centre contact):")
fc = {r["range"]: r for r in contact["basler1@deg"].summary["by_range"]}
for r in results["basler1@deg"].summary["by_range"]:
    print(f"  {r['range']:<10} n={r['n']:<3d} cov95 {100 * r['coverage_95']:5.1f}%  mean NEES {r['nees_mean']:.2f}"
          f"  | {100 * fc[r['range']]['coverage_95']:5.1f}%")

fig = Figure(figsize=(10.5, 4.2))
ax, bx = fig.subplots(1, 2)
ax.plot([0, 1], [0, 1], "k--", lw=0.8, label="ideal")
for (name, res), col in zip(results.items(), ("#1b9e77", "#d95f02", "#7570b3"), strict=True):
    cc = res.summary["calibration_curve"]
    ax.plot(cc["nominal"], cc["empirical"], color=col, lw=1.8, label=name)
    ax.fill_between(cc["nominal"], cc["low"], cc["high"], color=col, alpha=0.12, lw=0)
ax.set_xlabel("nominal coverage of the ellipse")
ax.set_ylabel("fraction of labelled bottom centres inside")
ax.set_title("Rope3D frame, 44 objects, bottom-centre contact", fontsize=10)
ax.set_xlim(0, 1)
ax.set_ylim(0, 1.02)
ax.grid(alpha=0.3)
ax.legend(fontsize=8, loc="lower right")
rows = results["basler1@deg"].summary["by_range"]
x = np.arange(len(rows))
cov = np.array([r["coverage_95"] for r in rows])
lo = np.array([r["interval_95"][0] for r in rows])
hi = np.array([r["interval_95"][1] for r in rows])
bx.bar(x, cov, color="#fdb863")
bx.errorbar(x, cov, yerr=[np.clip(cov - lo, 0, None), np.clip(hi - cov, 0, None)], fmt="none", color="k", capsize=3)
bx.axhline(0.95, color="k", ls="--", lw=0.8)
bx.set_xticks(x, [f"{r['range']}\n(n={r['n']})" for r in rows], fontsize=8)
bx.set_ylabel("coverage of the 95 % ellipse (basler1@deg)")
bx.set_ylim(0, 1.05)
bx.set_title("By range: the contact error dominates up close", fontsize=10)
fig.tight_layout()
fig.savefig(out / "validation_rope3d.png", dpi=110)
print(f"wrote {out / 'validation_rope3d.png'}")
