"""``footprint-uq carla ...``: record the case study in a running CARLA simulator, export our scenario.

The group registers its commands here, one ``carla.add_command(...)`` line each:

* ``carla capture`` (:mod:`.carla_capture`): drive a left turn in CARLA and record it;
* ``carla export`` (:mod:`.carla_export`): our own generated scenario as a recording.

Recordings: ``docs/carla-recording.md``; analyse one with ``footprint-uq case-study --recording FILE``.
"""

from __future__ import annotations

import click

from .carla_capture import capture
from .carla_export import export
from .groups import SuggestingGroup

__all__ = ["carla"]


@click.group("carla", cls=SuggestingGroup)
def carla():
    """CARLA simulator: capture the case study, export our scenario (docs/carla-recording.md)."""


# -- the registry of carla sub-commands: one line per command ---------------------------------
carla.add_command(capture)
carla.add_command(export)
