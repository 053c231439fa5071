"""``footprint-uq calibrate ...``: error sizes from calibration data.

The ``calibrate`` group holds one command per calibration, each in its own module, and
registers them here, one ``calibrate.add_command(...)`` line each.  The group itself is
registered in :mod:`footprint_uq.cli.main`.

Bad input raises :class:`footprint_uq.errors.InputError`; the top-level group turns it into a
one-line message and exit status 2.  Frame-level problems (unreadable image, no board found)
never stop a run: they are listed in ``frames.csv``, ``summary.json`` and on stderr.
"""

from __future__ import annotations

import click

from .calibrate_budget import budget_cmd
from .calibrate_extrinsics import extrinsics_cmd
from .calibrate_gcp import gcp_cmd
from .calibrate_intrinsics import intrinsics_cmd
from .calibrate_motion import motion_cmd
from .calibrate_synthetic import synthetic_cmd
from .groups import SuggestingGroup

__all__ = ["calibrate"]


@click.group("calibrate", cls=SuggestingGroup)
def calibrate():
    """Error budgets from calibration data (checkerboard images, ...)."""


# -- the registry of calibrate sub-commands: one line per command ---------------------------
calibrate.add_command(intrinsics_cmd)
calibrate.add_command(synthetic_cmd)
calibrate.add_command(extrinsics_cmd)
calibrate.add_command(gcp_cmd)
calibrate.add_command(budget_cmd)
calibrate.add_command(motion_cmd)
