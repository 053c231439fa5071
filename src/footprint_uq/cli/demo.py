"""``footprint-uq demo``: the demonstration report (:func:`footprint_uq.viz.demo.write_demo`)."""

from __future__ import annotations

import sys

import click

from ..viz.demo import write_demo
from .common import DEFAULT_STEP_PX, Stages, warn

__all__ = ["demo_cmd"]


@click.command("demo")
@click.option("--out", "out_dir", required=True, metavar="DIR", help="Output directory (created).")
@click.option("--step-px", type=click.IntRange(min=1), default=DEFAULT_STEP_PX, show_default=True,
              help="Map grid step in pixels (as in `map`).")
@click.option("--case-study/--no-case-study", default=True, show_default=True,
              help="Also run the paper's left-turn case study into DIR/case-study.")
def demo_cmd(out_dir, step_px, case_study):
    """Demonstration: a roadside camera (1920x1080, f 1400 px, 8 m high, tilt 20 deg) under three presets.

    Writes maps, figures and a self-contained report.html into DIR (and the
    left-turn case study into DIR/case-study unless --no-case-study).
    """
    with Stages("demo") as say:
        report = write_demo(out_dir, step_px=step_px, case_study=case_study, warn=warn, progress=say)
    click.echo(f"report: {report}")
    sys.stdout.flush()
