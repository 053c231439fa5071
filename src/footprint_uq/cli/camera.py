"""``footprint-uq camera ...``: camera files.

``camera compose``: intrinsics from one file (the ``camera.yaml`` of ``calibrate intrinsics``, an OpenCV
or ROS calibration, a TUMTraf file without extrinsics) and a pose from another (a surveyed pose file)
or from options, written as one full camera file (:func:`footprint_uq.io.load_camera` with ``pose``,
:func:`footprint_uq.io.save_camera`).
"""

from __future__ import annotations

import click

from ..errors import InputError
from ..io import load_camera, save_camera
from .common import pose_options
from .groups import SuggestingGroup

__all__ = ["camera"]


@click.group("camera", cls=SuggestingGroup)
def camera():
    """Camera files: compose intrinsics and a pose into one file."""


@camera.command("compose")
@click.option("--intrinsics", "intrinsics_path", required=True, metavar="FILE",
              help="Camera file with the intrinsics (any format footprint-uq reads; its pose, if any, is refused "
                   "with a pose option: one pose only).")
@click.option("--out", "out", required=True, metavar="FILE",
              help="The full camera file to write (.yaml, .yml or .json; written atomically).")
@pose_options
def compose_cmd(intrinsics_path, out, pose):
    """A full camera file from intrinsics and a pose (--pose-file, or --height-m, --pan-deg, --tilt-deg
    [--roll-deg, --position-m]); then --camera OUT works in every command."""
    if pose is None:
        raise InputError("--pose-file/--height-m", "missing", "a pose: --pose-file FILE, or --height-m, --pan-deg "
                         "and --tilt-deg [--roll-deg, --position-m]")
    cam = load_camera(intrinsics_path, pose=pose)
    p = save_camera(cam, out)
    x, y, z = (float(v) for v in cam.position_world_m)
    click.echo(f"wrote {p}: camera centre at x {x:.3f} m east, y {y:.3f} m north, {cam.height_m:.3f} m above the "
               f"ground (z {z:.3f} m); pan {cam.pan_deg:.2f} deg, tilt {cam.tilt_deg:.2f} deg")
