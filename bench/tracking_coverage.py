"""The tracker's coverage sweep (docs/uncertainty-model.md, "Motion: velocity and heading"), and its figure.

For every scenario (straight, turning, stopping) and rate (10, 20, 30 Hz), ``--runs`` seeded runs of 3 s (each run:
one calibration error drawn for the whole run, pixel noise every frame; :mod:`footprint_uq.tracking.synthetic`)
through these filters:

* ``imm`` -- the default: the split measurement model (``consider``) in the interacting-multiple-model filter
  (quiet mode q = 1.5, manoeuvre mode q = 30 m^2/s^3, mean sojourns 3 s / 1 s);
* ``cv`` -- the split model with the single constant-velocity mode q = 3 (the tracker before the IMM);
* ``cv-q6`` -- the same with q doubled (blanket inflation: what raising q alone buys and costs);
* ``white`` / ``ignore`` -- the IMM with the whole per-frame covariance fed as white noise, or the calibration
  error left out.  Prints the share of frames whose 95 % velocity
ellipse, heading interval and position ellipse hold the truth, writes them as JSON and draws
``docs/figures/tracking-coverage.png`` with ``--figure``.

    PYTHONPATH=src .venv/bin/python bench/tracking_coverage.py [--runs 1000] [--json out.json] [--figure PNG]

The small seeded version is ``tests/test_tracking.py::test_coverage_small_seeded_sweep``.  Nothing is asserted here.
"""

from __future__ import annotations

import argparse
import json
import time

from footprint_uq.tracking import TrackerConfig
from footprint_uq.tracking.synthetic import SCENARIOS, coverage

RATES_HZ = (10, 20, 30)
#: filter label -> (calibration mode, tracker options)
FILTERS = {
    "imm": ("consider", TrackerConfig()),
    "cv": ("consider", TrackerConfig(accel_psd_m2ps3=3.0, manoeuvre_accel_psd_m2ps3=None)),
    "cv-q6": ("consider", TrackerConfig(accel_psd_m2ps3=6.0, manoeuvre_accel_psd_m2ps3=None)),
    "white": ("white", TrackerConfig()),
    "ignore": ("ignore", TrackerConfig()),
}
MODES = tuple(FILTERS)


def sweep(n_runs: int = 1000, seed: int = 0, truth_psd: float = 2.5, filters=None) -> list[dict]:
    rows = []
    for mode, (calibration, cfg) in FILTERS.items():
        if filters and mode not in filters:
            continue
        for scenario in SCENARIOS:
            for hz in RATES_HZ:
                r = coverage(scenario, hz, n_runs=n_runs, seed=seed, calibration=calibration, config=cfg,
                             truth_accel_psd_m2ps3=truth_psd)
                rows.append(dict(mode=mode, scenario=scenario, rate_hz=hz, **{k: float(v) if isinstance(v, float)
                                                                              else v for k, v in r._asdict().items()}))
                print(f"{mode:9s} {scenario:9s} {hz:3d} Hz  velocity {r.velocity:6.1%}  heading {r.heading:6.1%}  "
                      f"position {r.position:6.1%}  sigma_v {r.mean_sigma_v_mps:.2f} m/s  rms error "
                      f"{r.rms_error_v_mps:.2f} m/s", flush=True)
    return rows


def figure(rows: list[dict], path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 3, figsize=(13, 4.4))
    cases = [(s, hz) for s in SCENARIOS for hz in RATES_HZ]
    style = {"imm": ("o", "C0", "split model, IMM (default)"), "cv": ("D", "C1", "split model, one CV mode, q = 3"),
             "cv-q6": ("v", "C4", "split model, one CV mode, q = 6"),
             "white": ("s", "C3", "full covariance as white noise (IMM)"),
             "ignore": ("^", "C2", "calibration left out (IMM)")}
    for ax, key, title in zip(axes, ("velocity", "heading", "position"),
                              ("velocity (95 % ellipse)", "heading (95 % interval)", "position (95 % ellipse)"),
                              strict=True):
        ax.axhspan(93, 97, color="0.9", zorder=0)
        ax.axhline(95, color="0.5", lw=0.8)
        for mode in [m for m in MODES if any(r["mode"] == m for r in rows)]:
            m, c, label = style[mode]
            y = [next(r[key] for r in rows if r["mode"] == mode and r["scenario"] == s and r["rate_hz"] == hz) * 100
                 for s, hz in cases]
            ax.plot(range(len(cases)), y, m, color=c, label=label, ms=5, alpha=0.85)
        ax.set_xticks(range(len(cases)), [f"{s[:4]}\n{hz} Hz" for s, hz in cases], fontsize=7)
        ax.set_title(title, fontsize=10)
        ax.set_ylim((85, 100.5) if key != "position" else (0, 101))
    axes[0].set_ylabel("coverage of the truth, %")
    axes[2].legend(fontsize=7, loc="lower center", bbox_to_anchor=(0.5, 0.1))
    fig.suptitle(f"Tracker coverage, {rows[0]['n_runs']} seeded runs per case (calibration error once per run, "
                 "pixel noise per frame); grey band: 95 +- 2 %", fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=110)


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=1000)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--truth-psd", type=float, default=2.5, help="the truth's random acceleration density, m^2/s^3")
    ap.add_argument("--filters", nargs="*", choices=MODES, help="only these filters (default: all)")
    ap.add_argument("--json", default=None)
    ap.add_argument("--figure", default=None)
    ap.add_argument("--from-json", default=None, help="draw the figure of an earlier --json file (no sweep)")
    a = ap.parse_args(argv)
    t0 = time.perf_counter()
    if a.from_json:
        with open(a.from_json) as f:
            rows = json.load(f)
    else:
        rows = sweep(a.runs, a.seed, a.truth_psd, a.filters)
    print(f"{time.perf_counter() - t0:.0f} s")
    if a.json:
        with open(a.json, "w") as f:
            json.dump(rows, f, indent=1)
    if a.figure:
        figure(rows, a.figure)


if __name__ == "__main__":
    main()
