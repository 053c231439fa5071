"""``footprint-uq carla export``: our generated scenario as a recording
(:func:`footprint_uq.integrations.carla.export.export_scenario`)."""

from __future__ import annotations

from pathlib import Path

import click

from ..integrations.carla.export import export_scenario

__all__ = ["export"]


@click.command("export")
@click.option("--out", "out_file", required=True, type=click.Path(dir_okay=False, path_type=Path),
              help="Recording to write (JSON Lines).")
@click.option("--config", "config", type=click.Path(exists=True, dir_okay=False, path_type=Path),
              help="Scenario settings (docs/case-study.md); default: the paper-like set-up.")
def export(out_file, config):
    """Write our generated left-turn scenario as a recording (CARLA coordinates)."""
    scene = export_scenario(out_file, config)
    click.echo(f"wrote {len(scene)} frames, {len(scene.cameras)} cameras to {out_file}")
