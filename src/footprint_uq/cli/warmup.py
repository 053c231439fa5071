"""``footprint-uq warmup``: compile the kernels ahead of time (:func:`footprint_uq.products.warmup.warmup`), e.g.
while building a container image or before a service starts, so that no command pays for it later.

Without it a command whose kernels are not in the cache compiles them in a detached background process and
runs the numpy reference path meanwhile (``FOOTPRINT_UQ_COMPILE``: background, foreground, reference)."""

from __future__ import annotations

import contextlib
import os

import click

from .._numba_cache import cache_dir
from ..products.warmup import GROUPS, cold_groups, warmup

__all__ = ["warmup_cmd"]


@click.command("warmup")
@click.option("--only", "only", type=click.Choice(list(GROUPS)), multiple=True,
              help="Compile only these kernel groups (repeat; default: all): map (map, demo), points "
                   "(scattered pixels), objects (objects, serve, FrameProcessor), lens (undistortion: every command on "
                   "a camera with lens distortion).")
@click.option("--background", is_flag=True, hidden=True,
              help="The detached compile a command starts: skip a group another process is compiling; no output.")
def warmup_cmd(only, background):
    """Compile every kernel once into numba's cache folder (later runs of every command start at once).

    Without it, a command whose kernels are not cached compiles them in the background and runs the (slower)
    reference path meanwhile; FOOTPRINT_UQ_COMPILE=foreground makes it compile first, =reference never."""
    groups = list(only) or list(GROUPS)
    if background:
        with contextlib.suppress(OSError):  # the command the user waits for runs first where cores are scarce
            os.nice(10)
        warmup(groups, background=True)
        return
    cold = set(cold_groups(groups))
    times = warmup(groups, progress=lambda g: click.echo(f"footprint-uq: warmup: {g} kernels "
                                                         f"{'compiling' if g in cold else 'cached'}", err=True),
                   on_wait=lambda g: click.echo(f"footprint-uq: warmup: another process is compiling the {g} kernels; "
                                                "waiting for it (then they load from the cache)", err=True))
    for g, s in times.items():
        click.echo(f"{g}: {s:.1f} s ({'compiled' if g in cold else 'loaded from the cache'})")
    click.echo(f"cache: {cache_dir()}")
