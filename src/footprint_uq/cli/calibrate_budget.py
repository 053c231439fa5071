"""``footprint-uq calibrate budget``: fit the error budget to labelled field data (docs/budget-fit.md).

The work is done by :func:`footprint_uq.viz.budget_fit_run.run_budget_fit`; the command is registered on
the ``calibrate`` group in :mod:`footprint_uq.cli.calibrate`.  Bad input: one line, exit status 2.
"""

from __future__ import annotations

import click

from ..validation.fit import FITTABLE_TERMS, OBJECT_TERMS
from ..validation.pairs import CONTACT_MODELS
from ..viz.budget_fit_run import DEFAULT_FREE, run_budget_fit
from .validate import label_source_options, size_priors_option

__all__ = ["budget_cmd"]


@click.command("budget")
@click.option("--labels", required=True, metavar="PATH",
              help="Labelled data, as for `validate`: a KITTI-layout folder (Rope3D), a DAIR-V2X-I folder, TUMTraf "
                   "OpenLABEL .json file(s), or a pairs table (.csv, .jsonl, .parquet).")
@click.option("--out", "out_dir", required=True, metavar="DIR", help="Output folder (created): budget.yaml, fit.json.")
@click.option("--budget", "budget_spec", default=None, metavar="FILE_OR_PRESET",
              help="Base budget: the values of the terms that are not free (default: zero).")
@click.option("--free", default=",".join(DEFAULT_FREE), show_default=True, metavar="TERMS",
              help=f"Comma-separated terms to fit: {', '.join([*FITTABLE_TERMS, *OBJECT_TERMS])}.")
@click.option("--contact", type=click.Choice(sorted(CONTACT_MODELS)), default="bottom-centre", show_default=True,
              help="Where a 2-D box touches the ground.")
@size_priors_option
@click.option("--method", type=click.Choice(["reml", "ml"]), default="reml", show_default=True,
              help="Restricted (REML: the bias's degrees of freedom accounted for) or plain maximum likelihood.")
@click.option("--min-groups", type=click.IntRange(min=1), default=3, show_default=True,
              help="Calibration groups (cameras) a shared term needs to be fitted.")
@click.option("--no-cv", is_flag=True, help="No cross-validated coverage (faster).")
@label_source_options
def budget_cmd(labels, out_dir, budget_spec, free, contact, size_priors, method, min_groups, no_cv, kind, camera_path,
               registry, calibration, image_size, origin_lat, origin_lon, heading_offset_deg):
    """Fit the error budget to labelled detections: REML with the calibration error shared per camera.

    Writes OUT/budget.yaml (usable as --budget by every command) and OUT/fit.json (sigmas, 95 % intervals,
    weakly identified, unidentifiable and merged terms, bias, cross-validated coverage); prints one line per
    term.  A fit that did not converge says so on stderr and in fit.json (converged false, the message).
    """
    summary, files = run_budget_fit(
        labels, out_dir, base_budget=budget_spec, free=[t.strip() for t in free.split(",") if t.strip()], kind=kind,
        contact=contact, size_priors=size_priors, camera=camera_path, registry=registry, calibration=calibration,
        image_size_px=tuple(image_size) if image_size else None, origin_lat_deg=origin_lat, origin_lon_deg=origin_lon,
        heading_offset_deg=heading_offset_deg, method=method, min_groups=min_groups, cross_validation=not no_cv)
    fit = summary["fit"]
    if not fit["converged"]:
        click.echo(f"footprint-uq calibrate budget: warning: the fit did not converge ({fit['message']})", err=True)
    click.echo(f"footprint-uq calibrate budget: {fit['n_objects']} pairs in {fit['n_groups']} group(s), "
               f"{fit['method'].upper()}, converged {fit['converged']}")
    for name, t in fit["terms"].items():
        ci = t["ci95"]
        hi = "inf" if ci[1] is None else f"{ci[1]:.4g}"
        extra = f" ({t['note']})" if t["status"] != "identified" else ""
        click.echo(f"  {name:18s} {t['sigma']:.4g}  95 % [{ci[0]:.4g}, {hi}]  {t['status']}{extra}")
    for by, cv in summary["cross_validation"].items():
        cov = ", ".join(f"{100 * lv:g} %: {100 * c:.1f} %" for lv, c in zip(cv["levels"], cv["coverage"], strict=True))
        click.echo(f"  leave-one-{by}-out coverage ({cv['n']} pairs): {cov}")
    click.echo(f"  wrote {files['budget']} and {files['summary']}")
