"""``footprint-uq convert``: write a camera in another model (e.g. the homography of any camera).

The work is done by :func:`footprint_uq.io.convert.convert_camera_file`.
"""

from __future__ import annotations

import click

from ..io.convert import convert_camera_file

__all__ = ["convert_cmd"]


@click.command("convert")
@click.option("--camera", required=True, metavar="FILE", help="Camera file (any format footprint-uq reads).")
@click.option("--to", "to", type=click.Choice(["homography", "opencv"]), required=True,
              help="Target model: homography (H_ground_image) or opencv (K, R, t).")
@click.option("--keep-intrinsics", is_flag=True, help="homography: also write K (the file then decomposes back).")
@click.option("--out", "out", required=True, metavar="FILE", help="Output file (.yaml, .yml or .json).")
def convert_cmd(camera, to, keep_intrinsics, out):
    """Convert a camera file to another model (written atomically)."""
    p = convert_camera_file(camera, to, out, keep_intrinsics=keep_intrinsics)
    click.echo(f"wrote {p}")
