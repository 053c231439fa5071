"""``footprint-uq carla capture``: drive a left turn in CARLA and record it
(:func:`footprint_uq.integrations.carla.capture.record_left_turn`).

Without the ``carla`` package, or without a reachable server, it fails fast with one line
on stderr and exit status 2.
"""

from __future__ import annotations

from pathlib import Path

import click

from ..integrations.carla.capture import CaptureOptions, record_left_turn
from .common import FiniteFloatRange

__all__ = ["capture"]


@click.command("capture")
@click.option("--host", default="127.0.0.1", show_default=True, help="CARLA server host.")
@click.option("--port", default=2000, show_default=True, type=click.IntRange(1, 65535), help="CARLA RPC port.")
@click.option("--out", "out_file", required=True, type=click.Path(dir_okay=False, path_type=Path),
              help="Recording to write (JSON Lines).")
@click.option("--timeout", "timeout_s", default=5.0, show_default=True, type=FiniteFloatRange(0.1, 600),
              help="Seconds to wait for the server.")
@click.option("--map", "map_name", default=None, help="Load this map first (e.g. Town03); default: the current one.")
@click.option("--fps", default=10.0, show_default=True, type=FiniteFloatRange(1, 100), help="Frame rate.")
@click.option("--speed", "speed_mps", default=8.0, show_default=True, type=FiniteFloatRange(0.5, 40),
              help="Vehicle speed, m/s.")
@click.option("--lead-in", "lead_in_m", default=35.0, show_default=True, type=FiniteFloatRange(0, 200),
              help="Path length before the junction connection, metres.")
@click.option("--lead-out", "lead_out_m", default=35.0, show_default=True, type=FiniteFloatRange(0, 200),
              help="Path length after the junction connection, metres.")
@click.option("--vehicle", "vehicle_filter", default="vehicle.lincoln.mkz*", show_default=True,
              help="Blueprint filter of the vehicle (falls back to any four-wheeled vehicle).")
@click.option("--images", "images_dir", default=None, type=click.Path(file_okay=False, path_type=Path),
              help="Also save the two cameras' images here (PNG per frame).")
def capture(host, port, out_file, timeout_s, map_name, fps, speed_mps, lead_in_m, lead_out_m, vehicle_filter,
            images_dir):
    """Drive a left turn through a junction in CARLA and record cameras and vehicle boxes."""
    options = CaptureOptions(fps=fps, speed_mps=speed_mps, lead_in_m=lead_in_m, lead_out_m=lead_out_m,
                             vehicle_filter=vehicle_filter, images_dir=images_dir)
    rec = record_left_turn(host, port, out_file, timeout_s=timeout_s, map_name=map_name, options=options)
    click.echo(f"recorded {rec['frames']} frames of a left turn at junction {rec['junction_id']} "
               f"({rec['map']}) to {out_file}")
