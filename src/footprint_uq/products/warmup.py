"""The compiled kernels' first run: whether a command's kernels still have to be compiled (an empty numba cache),
the one-line notice a command prints before that happens, and :func:`warmup`, which compiles them ahead of time
(``footprint-uq warmup``: for container images and services).

numba compiles a kernel on its first call and keeps the machine code in its cache folder
(:mod:`footprint_uq._numba_cache`); a command compiles only the kernels it calls.  Kernel groups:

* ``map``: the per-pixel map kernels (``footprint-uq map``, ``demo``);
* ``points``: the scattered-point kernels (``covariance_points``, the fusion and service checks);
* ``objects``: the fused per-frame kernel (``footprint-uq objects``, ``serve``, :class:`FrameProcessor`).
"""

from __future__ import annotations

import time
from collections.abc import Callable, Iterable
from pathlib import Path

import numpy as np

from .._numba_cache import cache_dir
from ..cameras.opencv import OpenCVCamera
from ..cameras.pantilt import PanTiltCamera
from ..fast import footprint_kernels as fk
from ..fast import map_kernels as mk
from ..uncertainty.budget import load_budget
from .covariance import covariance_points
from .footprints import FrameProcessor
from .maps import uncertainty_map

__all__ = ["GROUPS", "ABOUT_S", "cold_groups", "compile_notice", "compile_handler", "warmup"]

#: the entry kernels of each group (their cache index files tell whether the group is compiled)
GROUPS = {
    "map": mk.MAP_KERNELS,
    "points": mk.POINT_KERNELS,
    "objects": (fk.process_corners,),
}
#: first compile of each group on the reference machine (2-core VM, quiet), seconds: the notice's "about"
ABOUT_S = {"map": 10, "points": 6, "objects": 35}


def _cached(dispatcher) -> bool:
    cache = getattr(dispatcher, "_cache", None)
    index = getattr(getattr(cache, "_cache_file", None), "_index_path", None)
    return index is None or Path(index).is_file()  # no on-disk cache at all: nothing to say


def cold_groups(groups: Iterable[str]) -> list[str]:
    """The groups among ``groups`` whose kernels are not in the on-disk cache yet (compiled on first use)."""
    return [g for g in groups if not all(_cached(d) for d in GROUPS[g])]


def compile_notice(groups: Iterable[str]) -> str | None:
    """``"compiling the kernels once: about N s ..."`` when a group of ``groups`` is cold, else None."""
    cold = cold_groups(groups)
    if not cold:
        return None
    n = sum(ABOUT_S[g] for g in cold)
    return (f"compiling the {'/'.join(cold)} kernels once: about {n} s on 2 cores (cached in {cache_dir()}; later runs "
            "start at once; `footprint-uq warmup` does it ahead of time)")


def compile_handler(emit: Callable[[str], None]) -> Callable[[str], None]:
    """A handler for :func:`footprint_uq._notices.set_compile_handler`: ``emit(compile_notice([group]))`` when
    the group's kernels are cold (a command line passes its stderr printer)."""
    def handler(group: str) -> None:
        msg = compile_notice([group])
        if msg is not None:
            emit(msg)
    return handler


def _cameras():
    pt = PanTiltCamera(focal_px=400.0, image_size_px=(320, 240), height_m=8.0, pan_deg=30.0, tilt_deg=20.0)
    T = pt.T_cam_world
    cv = OpenCVCamera(pt.K, np.array([-0.17, 0.12, -1.2e-4, -2.35e-3, -0.03]), T[:3, :3], T[:3, 3], (320, 240))
    return pt, cv


def _warm_map(budget) -> None:
    for cam in _cameras():
        uncertainty_map(cam, budget, 16, linearity=True)


def _warm_points(budget) -> None:
    for cam in _cameras():
        for n in (4, mk.SERIAL_BELOW):  # the serial and the threaded kernel
            uv = np.c_[np.linspace(0.0, 319.0, n), np.linspace(150.0, 239.0, n)]
            covariance_points(cam, budget, uv, get_nonlinearity=True)


def _warm_objects(budget) -> None:
    for cam in _cameras():
        fp = FrameProcessor(cam, budget)
        fp.boxes2d(np.array([[100.0, 150.0, 140.0, 200.0]]))
        fp.boxes3d(np.array([[0.0, 20.0, 0.8, 4.5, 1.8, 1.5, 0.3]]))
        fp.corners(np.array([[[100.0, 200.0], [140.0, 200.0], [140.0, 210.0], [100.0, 210.0]]]))


_WARM = {"map": _warm_map, "points": _warm_points, "objects": _warm_objects}


def warmup(groups: Iterable[str] | None = None, *, progress: Callable[[str], None] | None = None) -> dict[str, float]:
    """Compile (or load from the cache) every kernel of ``groups`` (default: all); returns seconds per group."""
    budget = load_budget("basler1")
    out = {}
    for g in list(groups) if groups is not None else list(GROUPS):
        if progress is not None:
            progress(g)
        t0 = time.perf_counter()
        _WARM[g](budget)
        out[g] = time.perf_counter() - t0
    return out
