"""``footprint-uq case-study``: the paper's left-turn case study
(:func:`footprint_uq.viz.case_study_run.run_case_study`)."""

from __future__ import annotations

from pathlib import Path

import click

from ..viz.case_study_run import run_case_study
from .common import Stages

__all__ = ["case_study"]


@click.command("case-study")
@click.option("--out", "out_dir", required=True, type=click.Path(file_okay=False, path_type=Path),
              help="Output directory (figures, case_study_frames.csv, summary.json, report.html).")
@click.option("--config", "config", type=click.Path(exists=True, dir_okay=False, path_type=Path),
              help="Scenario settings, YAML or JSON (docs/case-study.md); default: the paper-like set-up.")
@click.option("--recording", type=click.Path(exists=True, dir_okay=False, path_type=Path),
              help="Analyse a CARLA recording (JSON Lines, docs/carla-recording.md) instead of the generator.")
@click.option("--camera-type", "camera_types", multiple=True,
              help="Budget preset or file; repeat to compare several (default: basler1, bw-bullet1, bw-cube1).")
@click.option("--ellipse-every", default=4, show_default=True, type=click.IntRange(1, 1000),
              help="Draw the ellipse of every n-th frame.")
@click.option("--dpi", default=130, show_default=True, type=click.IntRange(50, 600), help="PNG resolution.")
@click.option("--save-recording", type=click.Path(dir_okay=False, path_type=Path),
              help="Also write the analysed scene as a recording (JSON Lines).")
def case_study(out_dir, config, recording, camera_types, ellipse_every, dpi, save_recording):
    """The paper's left-turn case study: two roadside cameras, three camera types.

    Writes one PNG per figure, a CSV of every per-frame value, a self-contained
    report.html with the paper's statements tested (PASS/FAIL, tolerances fixed in
    footprint_uq.scenario.claims) and paper-reproduction.md (every table and statement
    of the paper under both readings of Table 3's angles). Camera types accept
    NAME@deg (Table 3's angles read as degrees).
    """
    with Stages("case-study") as say:
        paths = run_case_study(out_dir, config=config, recording=recording,
                               camera_types=list(camera_types) or None, ellipse_every=ellipse_every, dpi=dpi,
                               write_recording_to=save_recording, progress=say)
    res = paths["result"]
    click.echo(f"case study: {len(res.scene)} frames, {len(res.camera_names)} cameras x {len(res.type_names)} "
               f"camera types")
    for c in paths["claims"]:
        click.echo(f"  {c['id']}: {c['verdict']} ({', '.join(f'{k} {v}' for k, v in c['per_camera'].items())})")
    click.echo(f"figures: {len(paths['figures'])} PNG in {out_dir}")
    click.echo(f"csv: {paths['csv']}")
    click.echo(f"report: {paths['report']}")
    click.echo(f"paper reproduction: {paths['reproduction']}")
