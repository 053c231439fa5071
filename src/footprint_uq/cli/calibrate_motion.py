"""``footprint-uq calibrate motion``: the tracker's manoeuvre noise fitted to a site's detections (docs/motion-fit.md).

The work is done by :func:`footprint_uq.batch.motion_fit_run.run_motion_fit`; the command is registered on the
``calibrate`` group in :mod:`footprint_uq.cli.calibrate`.  Bad input: one line, exit status 2.
"""

from __future__ import annotations

import click

from ..batch.motion_fit_run import MODES, run_motion_fit
from ..batch.schema import DEFAULT_CHUNK_ROWS
from ..products.footprints import CONTACT_MODES
from ..uncertainty.presets import PRESET_NAMES
from .common import FiniteFloatRange, load_camera_and_budget, pose_options

__all__ = ["motion_cmd"]


@click.command("motion")
@click.option("--camera", "camera_path", required=True, metavar="FILE", help="Camera file (docs/file-formats.md).")
@click.option("--budget", "budget_spec", required=True, metavar="FILE_OR_PRESET",
              help=f"The camera's error budget: a preset ({', '.join(PRESET_NAMES)}) or a budget file; its motion "
                   "section, if any, is the prior.")
@click.option("--detections", required=True, metavar="FILE",
              help="A recording of the site's detections (.csv, .jsonl, .parquet, as `objects` reads) with "
                   "timestamp_s and object_id (class: one fit per class; camera_id: tracks per camera).")
@click.option("--out", "out_dir", required=True, metavar="DIR",
              help="Output folder: budget.yaml (the budget with its motion section) and motion_fit.json, written as "
                   "one set (the folder must be new or hold only a previous run's files).")
@click.option("--box-type", type=click.Choice(["2d", "3d", "corners"]), default=None,
              help="Box family (default: detected from the columns).")
@click.option("--contact", type=click.Choice(list(CONTACT_MODES)), default="bottom-centre", show_default=True,
              help="Ground contact of 2D boxes.")
@click.option("--modes", type=click.Choice(list(MODES)), default="auto", show_default=True,
              help="auto: also try the prior's two-mode (IMM) model, kept per class where the data favour it; "
                   "one: the one-mode model only (half the work); imm: also fit the IMM's manoeuvre density and "
                   "mean sojourns where the data identify them (~10 x the work of auto; docs/motion-fit.md).")
@click.option("--q-min", "q_min", type=FiniteFloatRange(min=0, min_open=True), default=1e-4, show_default=True,
              metavar="Q",
              help="Lowest acceleration density of the grid, m^2/s^3.")
@click.option("--q-max", "q_max", type=FiniteFloatRange(min=0, min_open=True), default=100.0, show_default=True,
              metavar="Q",
              help="Highest acceleration density of the grid, m^2/s^3.")
@click.option("--per-decade", type=click.IntRange(min=2), default=6, show_default=True,
              help="Grid densities per decade.")
@click.option("--min-tracks", type=click.IntRange(min=1), default=10, show_default=True,
              help="Tracks a class needs to be fitted (else the prior is kept).")
@click.option("--min-updates", type=click.IntRange(min=1), default=300, show_default=True,
              help="Track updates a class needs to be fitted (else the prior is kept).")
@click.option("--chunk-rows", type=click.IntRange(min=1), default=DEFAULT_CHUNK_ROWS, show_default=True,
              help="Rows per chunk (memory grows with it, not with the recording).")
@pose_options
def motion_cmd(camera_path, budget_spec, detections, out_dir, box_type, contact, modes, q_min, q_max, per_decade,
               min_tracks, min_updates, chunk_rows, pose):
    """Fit the manoeuvre (process) noise per object class by maximum likelihood of the tracker's innovations.

    Writes OUT/budget.yaml (use it as --budget of `objects --tracks` and `serve --tracks`) and
    OUT/motion_fit.json; prints one line per class.
    """
    cam, bud = load_camera_and_budget(camera_path, budget_spec, pose)
    summary, files = run_motion_fit(cam, bud, detections, out_dir, chunk_rows=chunk_rows, box_type=box_type,
                                    contact=contact, modes=modes, q_min_m2ps3=q_min, q_max_m2ps3=q_max,
                                    per_decade=per_decade, min_tracks=min_tracks, min_updates=min_updates,
                                    info={"camera": str(camera_path), "budget": str(budget_spec)})
    rows = summary["rows"]
    click.echo(f"footprint-uq calibrate motion: {rows['rows_in']} rows, {summary['motion']['source']}")
    if rows["rows_error"] or rows["rows_partial"]:
        first = ", ".join(f"row {r} ({why})" for r, _, why in summary["bad_rows"][:3])
        click.echo(f"  {rows['rows_error']} rows with errors, {rows['rows_partial']} partial, not tracked (listed in "
                   f"{files['summary'].name}): {first}{', ...' if len(summary['bad_rows']) > 3 else ''}", err=True)
    entries = dict(summary["motion"]["classes"])
    if "default" in summary["motion"]:
        entries["(default: all classes)"] = summary["motion"]["default"]
    for name, e in entries.items():
        ci = e.get("accel_psd_ci95_m2ps3")
        ci_text = "" if ci is None else f"  95 % [{ci[0]:.3g}, {'inf' if ci[1] is None else f'{ci[1]:.3g}'}]"
        man = e.get("manoeuvre_accel_psd_m2ps3")
        man_text = "none" if man is None else f"{man:.3g}"
        if man is not None and "quiet_sojourn_s" in e:
            man_text += f" (sojourns {e['quiet_sojourn_s']:.3g} / {e['manoeuvre_sojourn_s']:.3g} s)"
        click.echo(f"  {name:24s} q {e['accel_psd_m2ps3']:.3g} m^2/s^3{ci_text}  manoeuvre "
                   f"{man_text}  {e['status']} ({e['n_tracks']} tracks, "
                   f"{e['n_updates']} updates){': ' + e['note'] if e.get('note') else ''}")
    click.echo(f"  wrote {files['budget']} and {files['summary']}")
