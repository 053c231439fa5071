"""Recovery of a known budget by the fit (issues 20 and 35): seeded synthetic campaigns, the calibration error
drawn once per camera, the fit's 95 % intervals against the truth -- for the terms the fit calls identified.

Usage::

    .venv/bin/python bench/fit_recovery.py [--campaigns 200] [--cameras 8] [--objects 120] [--terms default,all]
                                           [--first-seed 0] [--out bench/results]
    .venv/bin/python bench/fit_recovery.py --combine A.json B.json ... [--out bench/results]

(``--first-seed``: campaigns ``first-seed .. first-seed + campaigns - 1``, for runs split over processes;
``--combine`` adds up the counts of such runs, configuration by configuration.)

Two configurations, each on ``--campaigns`` seeded campaigns (``synthetic_campaign``,
``footprint_uq.validation.campaigns``; per-object sigma 0.3 m, bias (0.2, -0.1) m):

* ``default``: the truth pan 0.1 deg, tilt 0.05 deg, height 0.2 m, the default free terms of ``calibrate budget``
  (pan, tilt, height, object_m);
* ``all``: every calibration term non-zero in the truth (``TRUTH_ALL``) and every term free.

Reported per term: how often it is identified / weakly identified / merged / unidentifiable, and among the
campaigns where it is called **identified**, the share whose 95 % interval contains the truth (goal: >= 93 %);
the fits that converged and whether ``converged`` and the message ever contradict; the wall time per fit. For
``default``, a single-camera campaign per seed too, whose calibration terms must all be unidentifiable.
Writes ``DIR/fit_recovery.json`` and ``DIR/fit_recovery.md``; exit status 1 if a goal is missed.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "src"))

from footprint_uq.validation.campaigns import synthetic_campaign  # noqa: E402
from footprint_uq.validation.fit import FITTABLE_TERMS, fit_budget  # noqa: E402

OBJECT_SIGMA_M = 0.3
TRUTH_DEFAULT = {"pan_deg": 0.1, "tilt_deg": 0.05, "height_m": 0.2}
TRUTH_ALL = {"focal_px": 20.0, "principal_point_px": [10.0, 10.0], "position_m": [0.3, 0.3], "height_m": 0.2,
             "pan_deg": 0.1, "tilt_deg": 0.05, "roll_deg": 0.05, "ground_height_m": 0.05, "ground_slope_deg": 0.1}
CONFIGS = {"default": (TRUTH_DEFAULT, ["pan_deg", "tilt_deg", "height_m", "object_m"]),
           "all": (TRUTH_ALL, [*FITTABLE_TERMS, "object_m"])}
GOAL = 0.93
STATUSES = ("identified", "weakly identified", "merged", "unidentifiable")


def _sigma(v) -> float:
    return float(v[0] if isinstance(v, list) else v)


def run(config: str, n_campaigns: int, n_cameras: int, n_objects: int, first_seed: int = 0) -> dict:
    truth_budget, free = CONFIGS[config]
    truth = {**{k: _sigma(v) for k, v in truth_budget.items()}, "object_m": OBJECT_SIGMA_M}
    rows = {k: [] for k in free}
    times, conv, contradict, single_ok = [], 0, 0, 0
    for seed in range(first_seed, first_seed + n_campaigns):
        c = synthetic_campaign(truth_budget, n_cameras, n_objects, object_sigma_m=OBJECT_SIGMA_M,
                               bias_m=(0.2, -0.1), seed=seed)
        t0 = time.perf_counter()
        fit = fit_budget(c.residual_m, c.dxy_dp, c.cov_object_m2, c.group, free=free)
        times.append(time.perf_counter() - t0)
        conv += fit.converged
        contradict += fit.converged != fit.message.startswith("converged")
        for k in free:
            t = fit.terms[k]
            rows[k].append((t.status, t.sigma, *t.ci95))
        if config == "default":
            one = synthetic_campaign(truth_budget, 1, n_objects * 4, object_sigma_m=OBJECT_SIGMA_M, seed=10_000 + seed)
            f1 = fit_budget(one.residual_m, one.dxy_dp, one.cov_object_m2, one.group, free=free)
            single_ok += all(f1.terms[k].status == "unidentifiable" for k in truth_budget)
        print(f"{config} {seed}: {times[-1]:.2f} s", file=sys.stderr, flush=True)
    terms = {}
    for k, r in rows.items():
        ident = [(lo, hi) for st, _, lo, hi in r if st == "identified"]
        hits = sum(lo <= truth[k] <= hi for lo, hi in ident)
        terms[k] = {"truth": truth[k], "statuses": {s: sum(st == s for st, *_ in r) for s in STATUSES},
                    "identified": len(ident), "covered_when_identified": hits,
                    "coverage_95_when_identified": hits / len(ident) if ident else None,
                    "estimates": [float(x[1]) for x in r], "median_estimate": float(np.median([x[1] for x in r]))}
    out = {"config": config, "campaigns": n_campaigns, "cameras": n_cameras, "objects_per_camera": n_objects,
           "free": free, "truth": truth_budget, "terms": terms, "converged": conv,
           "converged_contradicts_message": contradict, "seconds_per_fit": times,
           "seconds_per_fit_median": float(np.median(times)), "first_seed": first_seed}
    if config == "default":
        out["single_camera_unidentifiable"] = single_ok
    return out


def markdown(results: list[dict]) -> str:
    lines = []
    for res in results:
        lines += [f"## `{res['config']}`: {res['campaigns']} campaigns x {res['cameras']} cameras x "
                  f"{res['objects_per_camera']} objects, free: {', '.join(res['free'])}", "",
                  "| term | truth | identified | weakly identified | merged | unidentifiable | 95 % interval contains "
                  "the truth, when identified | median estimate |", "|---|---|---|---|---|---|---|---|"]
        for k, t in res["terms"].items():
            c = t["coverage_95_when_identified"]
            cov = "-" if c is None else f"{100 * c:.1f} % ({t['covered_when_identified']} / {t['identified']})"
            st = t["statuses"]
            lines.append(f"| {k} | {t['truth']:g} | {st['identified']} | {st['weakly identified']} | {st['merged']} | "
                         f"{st['unidentifiable']} | {cov} | {t['median_estimate']:.4g} |")
        lines += ["", f"Converged: {res['converged']} / {res['campaigns']} (converged and message contradict: "
                  f"{res['converged_contradicts_message']}); median {res['seconds_per_fit_median']:.2f} s per fit."]
        if "single_camera_unidentifiable" in res:
            lines.append(f"Single-camera campaigns with every calibration term reported unidentifiable: "
                         f"{res['single_camera_unidentifiable']} / {res['campaigns']}.")
        lines.append("")
    return "# Fit recovery (bench/fit_recovery.py)\n\n" + "\n".join(lines)


def goals_met(res: dict) -> bool:
    cov = [t["coverage_95_when_identified"] for t in res["terms"].values() if t["identified"]]
    return all(c >= GOAL for c in cov) and res["converged_contradicts_message"] == 0


def combine(parts: list[dict]) -> list[dict]:
    """Runs of the same configuration (disjoint seeds) added up: one result per configuration."""
    out: dict[str, dict] = {}
    for r in parts:
        c = out.get(r["config"])
        if c is None:
            out[r["config"]] = json.loads(json.dumps(r))
            continue
        for k in ("campaigns", "converged", "converged_contradicts_message", "single_camera_unidentifiable"):
            if k in c:
                c[k] += r[k]
        c["seconds_per_fit"] += r["seconds_per_fit"]
        c["seconds_per_fit_median"] = float(np.median(c["seconds_per_fit"]))
        c["first_seed"] = min(c["first_seed"], r["first_seed"])
        for k, t in c["terms"].items():
            u = r["terms"][k]
            for s in STATUSES:
                t["statuses"][s] += u["statuses"][s]
            t["identified"] += u["identified"]
            t["covered_when_identified"] += u["covered_when_identified"]
            t["coverage_95_when_identified"] = (t["covered_when_identified"] / t["identified"]) if t["identified"] \
                else None
            t["estimates"] += u["estimates"]
            t["median_estimate"] = float(np.median(t["estimates"]))
    return list(out.values())


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--campaigns", type=int, default=200)
    ap.add_argument("--cameras", type=int, default=8)
    ap.add_argument("--objects", type=int, default=120)
    ap.add_argument("--terms", default="default,all", help="configurations, comma-separated: default, all")
    ap.add_argument("--first-seed", type=int, default=0)
    ap.add_argument("--combine", nargs="+", type=Path, default=None, metavar="JSON",
                    help="add up fit_recovery.json files of runs over disjoint seeds (no campaign is run)")
    ap.add_argument("--out", type=Path, default=ROOT / "bench" / "results")
    a = ap.parse_args(argv)
    if a.combine:
        results = combine([r for f in a.combine for r in json.loads(f.read_text())])
    else:
        results = [run(c.strip(), a.campaigns, a.cameras, a.objects, a.first_seed) for c in a.terms.split(",")
                   if c.strip()]
    a.out.mkdir(parents=True, exist_ok=True)
    (a.out / "fit_recovery.json").write_text(json.dumps(results, indent=2) + "\n")
    md = markdown(results)
    (a.out / "fit_recovery.md").write_text(md)
    print(md)
    return 0 if all(goals_met(r) for r in results) else 1


if __name__ == "__main__":
    raise SystemExit(main())
