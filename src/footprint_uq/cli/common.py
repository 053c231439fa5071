"""Helpers shared by several commands: camera and budget loading, option checks, stderr lines.

(Those of the ``calibrate`` commands only are in :mod:`.calibrate_common`, so that the other
commands do not load the calibration package.)
"""

from __future__ import annotations

import click

from ..io import load_camera
from ..uncertainty.budget import load_budget
from ..uncertainty.ellipse import chi2_scale

__all__ = ["load_camera_and_budget", "check_confidence", "note", "warn"]


def load_camera_and_budget(camera_path, budget_spec):
    """``(camera, budget)`` from a camera file and a preset name or budget file (bad input: InputError)."""
    return load_camera(camera_path), load_budget(budget_spec)


def check_confidence(confidence: float | None) -> float | None:
    """``--confidence``: None, or a probability in (0, 1) (else InputError naming ``confidence``)."""
    if confidence is None:
        return None
    chi2_scale(confidence)  # raises InputError("confidence", ...) outside (0, 1)
    return float(confidence)


def note(msg: str) -> None:
    """One line on stderr: ``footprint-uq: MSG``."""
    click.echo(f"footprint-uq: {msg}", err=True)


def warn(msg: str) -> None:
    """One warning line on stderr: ``footprint-uq: warning: MSG``."""
    click.echo(f"footprint-uq: warning: {msg}", err=True)
