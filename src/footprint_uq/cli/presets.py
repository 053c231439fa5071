"""``footprint-uq presets``: the paper's error-budget presets (:mod:`footprint_uq.uncertainty.preset_tables`)."""

from __future__ import annotations

import json

import click

from ..uncertainty.preset_tables import presets_csv, presets_table, presets_text

__all__ = ["presets_cmd"]


@click.command("presets")
@click.argument("names", nargs=-1, metavar="[NAME[@deg]]...")
@click.option("--format", "fmt", type=click.Choice(["text", "json", "csv"]), default="text", show_default=True,
              help="Output: an aligned text table, JSON, or CSV.")
def presets_cmd(names, fmt):
    """The error-budget presets of the paper (Tables 2-3): 1-sigma values of every source.

    Table 3's sigma X is along north and sigma Y along east (the paper's earth frame,
    docs/conventions.md): the world position sigma is (east, north) = (sigma Y, sigma X).
    Table 3 prints sigma alpha and sigma theta in 1e-3 deg. A preset name alone
    (basler1) reads them as printed: the default. NAME@deg (basler1@deg) reads the same
    numbers as degrees; the suffix works wherever a preset is accepted (--budget of
    every command, case-study camera_types, load_budget). Give NAMES to list only
    those, e.g. `footprint-uq presets basler1 basler1@deg`.
    """
    rows = presets_table(names)
    if fmt == "json":
        click.echo(json.dumps(rows, indent=2))
    elif fmt == "csv":
        click.echo(presets_csv(rows), nl=False)
    else:
        click.echo(presets_text(rows))
