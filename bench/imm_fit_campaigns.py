"""The fitted IMM on manoeuvring traffic (issue 36, part 1: the IMM's modes; docs/motion-fit.md, section 2).

Seeded campaigns of :func:`footprint_uq.tracking.motion_campaigns.campaign_frames` -- one camera (the budget
``basler1@deg`` x 0.25, one calibration draw per campaign), q = 0.5 m^2/s^3 on top of sustained turns
(``turning``) or braking to a stop (``stopping``), 1.5 px detector noise, 30 Hz -- each fitted with ``calibrate
motion --modes imm``'s fit (:func:`footprint_uq.tracking.imm_fit.run_imm_campaigns`: one-mode grid + IMM product
grid), then tracked again with its fitted model: how many campaigns keep a two-mode model, which IMM parameters
the data identify, and the 95 % velocity / heading coverage after the fit.  Two campaign sizes: the small
campaigns of the one-mode check (10 road users x 4 s) and larger ones (100 x 6 s).  Nothing is asserted.

    PYTHONPATH=src .venv/bin/python bench/imm_fit_campaigns.py [--campaigns 20] [--json ...] [--md ...]
"""

from __future__ import annotations

import argparse
import json
import time

from footprint_uq.tracking.imm_fit import IMM_PARAMETERS, run_imm_campaigns
from footprint_uq.uncertainty.budget import load_budget

#: (road users, seconds) per campaign
SIZES = ((10, 4.0), (100, 6.0))


def run(n_campaigns: int, seed: int = 0) -> list[dict]:
    budget = load_budget("basler1@deg").scaled(0.25)
    rows = []
    for scenario in ("turning", "stopping"):
        for n_objects, duration_s in SIZES:
            t0 = time.perf_counter()
            r = run_imm_campaigns(0.5, scenario=scenario, n_campaigns=n_campaigns, n_objects=n_objects,
                                  duration_s=duration_s, seed=seed, budget=budget)
            imm = [e for e in r.entries if e.get("manoeuvre_accel_psd_m2ps3") is not None]
            row = {"scenario": scenario, "n_objects": n_objects, "duration_s": duration_s,
                   "n_campaigns": n_campaigns, "n_two_modes": len(imm),
                   "fitted": [{k: e.get(k) for k in IMM_PARAMETERS} for e in imm],
                   "notes": [e.get("note", "") for e in r.entries],
                   "coverage_velocity": r.coverage_velocity, "coverage_heading": r.coverage_heading,
                   "n_velocity": r.n_velocity, "n_heading": r.n_heading, "elapsed_s": time.perf_counter() - t0}
            rows.append(row)
            print(json.dumps({k: v for k, v in row.items() if k not in ("notes", "fitted")}), flush=True)
    return rows


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--campaigns", type=int, default=20)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--json", default=None)
    ap.add_argument("--md", default=None)
    a = ap.parse_args(argv)
    rows = run(a.campaigns, a.seed)
    if a.json:
        with open(a.json, "w") as f:
            json.dump(rows, f, indent=1)
    if a.md:
        lines = ["| scenario | campaign | two-mode model kept | fitted IMMs (q_quiet, q_manoeuvre m^2/s^3, sojourns s) "
                 "| velocity / heading 95 % coverage after the fit |", "|---|---|---|---|---|"]
        for r in rows:
            fits = "; ".join(f"{f['accel_psd_m2ps3']:.2g}, {f['manoeuvre_accel_psd_m2ps3']:.2g}, "
                             f"{f['quiet_sojourn_s']:.2g} / {f['manoeuvre_sojourn_s']:.2g}" for f in r["fitted"][:4])
            lines.append(f"| {r['scenario']} | {r['n_objects']} road users x {r['duration_s']:g} s | "
                         f"{r['n_two_modes']} of {r['n_campaigns']} | {fits or '-'}"
                         f"{' ...' if len(r['fitted']) > 4 else ''} | {100 * r['coverage_velocity']:.1f} / "
                         f"{100 * r['coverage_heading']:.1f} % |")
        with open(a.md, "w") as f:
            f.write("q = 0.5 m^2/s^3 + manoeuvres, basler1@deg x 0.25, 1.5 px, 30 Hz (bench/imm_fit_campaigns.py)\n\n"
                    + "\n".join(lines) + "\n")


if __name__ == "__main__":
    main()
