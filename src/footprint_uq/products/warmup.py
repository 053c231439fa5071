"""The compiled kernels' first run: whether a command's kernels still have to be compiled (an empty numba cache),
the one-line notice a command prints before that happens, and :func:`warmup`, which compiles them ahead of time
(``footprint-uq warmup``: for container images and services).

numba compiles a kernel on its first call and keeps the machine code in its cache folder
(:mod:`footprint_uq._numba_cache`); a command compiles only the kernels it calls.  Kernel groups:

* ``map``: the per-pixel map kernels (``footprint-uq map``, ``demo``);
* ``points``: the scattered-point kernels (``covariance_points``, the fusion and service checks);
* ``objects``: the fused per-frame kernel (``footprint-uq objects``, ``serve``, :class:`FrameProcessor`).

A command line does not wait for a cold group (:class:`KernelGate`, the handler of
:mod:`footprint_uq._notices`): it says so in one line, starts ``footprint-uq warmup --only GROUP
--background`` as a detached process (which outlives the command, so that the next run finds the kernels in
the cache; a lock file in the cache folder keeps two commands from compiling the same group twice) and runs
on the numpy reference path meanwhile -- the same numbers to 1e-9 relative, slower per row.  A long job
(``objects`` on a large file, ``serve``) asks again before each chunk or frame and switches to the compiled
kernels once the background compile is done (loading them from the cache takes about a second).
``FOOTPRINT_UQ_COMPILE`` chooses otherwise: ``foreground`` (compile in the command itself, as a library
call does), ``reference`` (never compile: the reference path only).
"""

from __future__ import annotations

import contextlib
import os
import subprocess
import sys
import threading
import time
import warnings
from collections.abc import Callable, Iterable
from pathlib import Path

import numpy as np
from filelock import FileLock, Timeout

from .._checks import COV_PSD_RTOL
from .._numba_cache import cache_dir
from ..cameras import general
from ..cameras.opencv import OpenCVCamera
from ..cameras.pantilt import PanTiltCamera
from ..errors import InputError
from ..fast import core
from ..fast import footprint_kernels as fk
from ..fast import frame_columns as fc
from ..fast import map_kernels as mk
from ..fast.cov_checks import first_bad_cov2
from ..uncertainty.budget import load_budget
from .covariance import covariance_points, kernel_constants
from .footprints import FrameProcessor
from .maps import uncertainty_map

__all__ = ["GROUPS", "ABOUT_S", "MODES", "cold_groups", "compile_notice", "compile_handler", "KernelGate",
           "compile_mode", "group_lock", "start_background", "warmup", "compiling_elsewhere", "wait_for_compile",
           "LibraryGate", "CompileWaitWarning", "CompileNotice", "WAIT_S", "compile_wait_s", "wait_notice"]

#: the entry kernels of each group (their cache index files tell whether the group is compiled)
GROUPS = {
    "map": mk.MAP_KERNELS,
    "points": mk.POINT_KERNELS,
    "objects": (fk.process_corners, fk.process_boxes3d, first_bad_cov2, fk.point_jacobian_into, fc.boxes2d_columns),
    "lens": (core.undistort_many,),
}
#: the notice's "about": a group's background compile on the 2-core VM of 2026-11-26, quiet (bench/bench_first_run.py
#: ``compile_s``: objects 92 s, map 98 s; points 43 s by ``warmup``), rounded up; 2026-11-24's VM took ~40 % of it
ABOUT_S = {"map": 100, "points": 45, "objects": 95, "lens": 15}
#: values of ``FOOTPRINT_UQ_COMPILE``: what a command does when a kernel group is cold (default: background)
MODES = ("background", "foreground", "reference")
#: how often a running command looks whether the background compile is done (seconds)
_POLL_S = 0.5
#: how long ``group_lock(wait=False)`` tries: another process's probe holds the lock for microseconds (seconds)
_PROBE_GRACE_S = 0.25


def _cached(dispatcher) -> bool:
    """Whether numba will load ``dispatcher``'s kernel from its on-disk cache: an index file that is current (one
    written for other sources -- ``_numba_cache.install_sources_stamp`` -- or another numba loads as empty)."""
    cache_file = getattr(getattr(dispatcher, "_cache", None), "_cache_file", None)
    index = getattr(cache_file, "_index_path", None)
    if index is None:
        return True  # no on-disk cache at all: nothing to say
    if not Path(index).is_file():
        return False
    load = getattr(cache_file, "_load_index", None)
    try:
        return load is None or bool(load())
    except Exception:  # noqa: BLE001 - an index numba cannot read (truncated, foreign pickle) is no cache
        return False


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


def compile_handler(emit: Callable[[str], None]) -> KernelGate:
    """The handler a command line passes to :func:`footprint_uq._notices.set_compile_handler` (``emit``: its
    stderr printer): a :class:`KernelGate` in the mode ``FOOTPRINT_UQ_COMPILE`` says."""
    return KernelGate(emit)


def compile_mode(environ=os.environ) -> str:
    """``FOOTPRINT_UQ_COMPILE`` (:data:`MODES`; unset or empty: "background")."""
    mode = environ.get("FOOTPRINT_UQ_COMPILE", "").strip().lower() or "background"
    if mode not in MODES:
        raise InputError("FOOTPRINT_UQ_COMPILE", mode, f"one of {', '.join(MODES)}")
    return mode


def background_notice(group: str) -> str:
    """The line a command says when it leaves a cold group to a background compile."""
    return (f"compiling the {group} kernels in the background, about {ABOUT_S[group]} s on 2 cores, once (cached in "
            f"{cache_dir()}); this run uses the numpy reference path meanwhile (the same numbers, slower per row; a "
            "long run switches when they are ready); `footprint-uq warmup` compiles them ahead of time")


def _lock_path(group: str) -> Path:
    return cache_dir() / f"footprint-uq-warmup-{group}.lock"


#: the groups whose compile lock this process holds (:func:`group_lock`): its own compile is not "another's"
_HELD: set[str] = set()


def compiling_elsewhere(group: str) -> bool:
    """Whether another process holds the compile lock of ``group`` right now (a compile under way).  The lock is
    an OS file lock (``filelock``): a compile that crashed or was killed holds nothing."""
    if group in _HELD:
        return False
    path = _lock_path(group)
    if not path.exists():
        return False
    probe = FileLock(path, thread_local=False)
    try:
        probe.acquire(timeout=0)
    except Timeout:
        return True
    except OSError:  # a cache folder we cannot lock in: nobody can compile there either
        return False
    probe.release()
    return False


def wait_for_compile(group: str, timeout_s: float) -> bool:
    """Wait at most ``timeout_s`` seconds for another process's compile of ``group`` (its lock); whether it is
    over (the lock free)."""
    deadline = time.monotonic() + timeout_s
    while compiling_elsewhere(group):
        left = deadline - time.monotonic()
        if left <= 0:
            return False
        time.sleep(min(_POLL_S, left))
    return True


@contextlib.contextmanager
def group_lock(group: str, *, wait: bool):
    """Hold the compile lock of ``group`` (an OS file lock in the cache folder, ``filelock``: released by the OS
    when its process ends, a crash included) in the ``with`` block; yields whether it is held.  Another process
    holding it: ``wait=True`` waits for it to finish, ``wait=False`` yields False after :data:`_PROBE_GRACE_S` (a
    moment: long enough not to mistake another process's probe, :func:`compiling_elsewhere`, for a compile)."""
    path = _lock_path(group)
    path.parent.mkdir(parents=True, exist_ok=True)
    lock = FileLock(path, thread_local=False)
    try:
        lock.acquire(timeout=-1 if wait else _PROBE_GRACE_S, poll_interval=_POLL_S if wait else 0.02)
    except Timeout:
        yield False
        return
    _HELD.add(group)
    try:
        yield True
    finally:
        _HELD.discard(group)
        lock.release()


def start_background(group: str) -> subprocess.Popen | None:
    """Start ``footprint-uq warmup --only group --background`` as a detached process (its own session: it
    outlives the command, and a Ctrl-C of the command does not stop it; niceness +10: the command comes first
    where cores are scarce); None when another process is compiling the group already."""
    if compiling_elsewhere(group):
        return None
    env = {**os.environ, "FOOTPRINT_UQ_COMPILE": "foreground", "NUMBA_CACHE_DIR": str(cache_dir())}
    if not os.environ.get("NUMBA_CACHE_DIR"):  # numba's default (beside the sources): leave it so
        env.pop("NUMBA_CACHE_DIR")
    cmd = [sys.executable, "-m", "footprint_uq.cli", "warmup", "--only", group, "--background"]
    return subprocess.Popen(cmd, stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                            env=env, start_new_session=True, close_fds=True)


class KernelGate:
    """A command line's handler for :func:`footprint_uq._notices.set_compile_handler`: whether a group's compiled
    kernels run now (see the module doc).

    A warm group: True.  A cold group, mode "background" (default): one line through ``emit``
    (:func:`background_notice`), the compile started in a detached process (:func:`start_background`), False
    (the reference path) until that compile is done -- asked at most every :data:`_POLL_S` seconds -- then True.
    Mode "foreground": the notice of :func:`compile_notice`, True (the caller compiles).  Mode "reference":
    always False, nothing said.  Thread-safe (a batch's chunks run on two threads).
    """

    def __init__(self, emit: Callable[[str], None], mode: str | None = None):
        self.emit = emit
        self.mode = compile_mode() if mode is None else mode
        self._state: dict[str, str] = {}  # group -> "ready" | "waiting" | "reference"
        self._jobs: dict[str, list] = {}  # group -> [Popen or None, next poll time]
        self._lock = threading.Lock()

    def __call__(self, group: str) -> bool:
        state = self._state.get(group)
        if state == "ready":
            return True
        if state == "reference":
            return False
        with self._lock:
            if group not in self._state:
                self._state[group] = self._first(group)
            elif self._state[group] == "waiting":
                self._state[group] = self._poll(group)
            return self._state[group] == "ready"

    def _first(self, group: str) -> str:
        if self.mode == "reference":
            return "reference"
        if not cold_groups([group]):
            return "ready"
        if self.mode == "foreground":
            self.emit(compile_notice([group]))
            return "ready"
        self._jobs[group] = [start_background(group), time.monotonic() + _POLL_S]
        self.emit(background_notice(group))
        return "waiting"

    def _poll(self, group: str) -> str:
        job = self._jobs[group]
        now = time.monotonic()
        if now < job[1]:
            return "waiting"
        job[1] = now + _POLL_S
        if job[0] is not None and job[0].poll() is None:
            return "waiting"
        if compiling_elsewhere(group):  # another command's compile
            return "waiting"
        # done; a compile that failed (still cold) leaves this run on the reference path
        return "reference" if cold_groups([group]) else "ready"

    def wait(self, timeout_s: float | None = None) -> None:
        """Wait for the background compiles this gate started (tests; a command never waits)."""
        for job in self._jobs.values():
            if job[0] is not None:
                job[0].wait(timeout_s)


class CompileWaitWarning(RuntimeWarning):
    """A library call found its kernels being compiled by another process and did not wait for it past a bound."""


class CompileNotice(UserWarning):
    """A library call is about to compile a kernel group in its own process (once per installation): said once,
    so that a first call of tens of seconds is never silent (``warnings.simplefilter("ignore", CompileNotice)``
    silences it; ``footprint-uq warmup`` avoids the wait)."""


#: how long a library call waits, at most, for another process's compile of its kernels (seconds)
WAIT_S = 20.0


def compile_wait_s(environ=os.environ) -> float:
    """``FOOTPRINT_UQ_COMPILE_WAIT_S`` (seconds, finite and >= 0; unset or empty: :data:`WAIT_S`)."""
    text = environ.get("FOOTPRINT_UQ_COMPILE_WAIT_S", "").strip()
    if not text:
        return WAIT_S
    try:
        value = float(text)
    except ValueError:
        value = float("nan")
    if not (0.0 <= value < float("inf")):
        raise InputError("FOOTPRINT_UQ_COMPILE_WAIT_S", text, "a finite number of seconds >= 0")
    return value


def wait_notice(group: str, wait_s: float) -> str:
    """The warning of a library call whose kernels another process is compiling."""
    return (f"footprint-uq: another process is compiling the {group} kernels (lock {_lock_path(group)}); this call "
            f"waits for it at most {wait_s:g} s, then runs on the numpy reference path (the same numbers, slower) "
            "until that compile is done. Run `footprint-uq warmup` ahead of time to avoid the wait "
            "(FOOTPRINT_UQ_COMPILE_WAIT_S sets the bound)")


class LibraryGate:
    """The library's handler (:func:`footprint_uq._notices.set_library_handler`, installed on import): whether a
    library call runs a group's compiled kernels now.

    Nobody else compiling the group (no lock held: the usual case, a lock probe of microseconds): True -- the kernels
    run, compiled on first use in this process.  Another process compiling it: one :class:`CompileWaitWarning`
    per group (:func:`wait_notice`), a wait of at most ``wait_s`` seconds (``FOOTPRINT_UQ_COMPILE_WAIT_S``,
    default :data:`WAIT_S`) for that compile, then True if it is over, else False (the reference path) until it
    is -- asked again at most every :data:`_POLL_S` seconds.  Thread-safe."""

    def __init__(self, wait_s: float | None = None):
        self.wait_s = wait_s
        self._ready: set[str] = set()
        self._next_poll: dict[str, float] = {}
        self._lock = threading.Lock()

    def __call__(self, group: str) -> bool:
        if group in self._ready:
            return True
        with self._lock:
            if group in self._ready:
                return True
            if group in self._next_poll:  # waited once already: look again now and then, never wait
                now = time.monotonic()
                if now < self._next_poll[group]:
                    return False
                self._next_poll[group] = now + _POLL_S
                if compiling_elsewhere(group):
                    return False
            elif cold_groups([group]):
                if compiling_elsewhere(group):
                    wait_s = compile_wait_s() if self.wait_s is None else self.wait_s
                    warnings.warn(wait_notice(group, wait_s), CompileWaitWarning, stacklevel=4)
                    if not wait_for_compile(group, wait_s):
                        self._next_poll[group] = time.monotonic() + _POLL_S
                        return False
                else:  # compiled here, now: said once, never a silent wait of tens of seconds
                    warnings.warn(f"footprint-uq: {compile_notice([group])}", CompileNotice, stacklevel=4)
            self._ready.add(group)  # (a compile elsewhere that failed leaves the group cold: compiled here)
            return True


def _cameras():
    pt = PanTiltCamera(focal_px=400.0, image_size_px=(320, 240), height_m=8.0, pan_deg=30.0, tilt_deg=20.0)
    T = pt.T_cam_world
    cv = OpenCVCamera(pt.K, np.array([-0.17, 0.12, -1.2e-4, -2.35e-3, -0.03]), T[:3, :3], T[:3, 3], (320, 240))
    return pt, cv


def _warm_map(budget) -> None:
    for cam in _cameras():
        uncertainty_map(cam, budget, 16, linearity=True)


def _warm_points(budget) -> None:
    """The serial kernel through :func:`covariance_points`, the threaded one called directly: the public call picks
    the threaded kernel only when a second core is free at that instant (``fast.cores.free_cores``)."""
    n = 8
    uv = np.c_[np.linspace(0.0, 319.0, n), np.linspace(150.0, 239.0, n)]
    Suv = np.ascontiguousarray(np.broadcast_to(budget.pixel_covariance(), (n, 2, 2)))
    for cam in _cameras():
        covariance_points(cam, budget, uv, get_nonlinearity=True)
        out = np.empty((n, 2)), np.empty((n, 2, 2)), np.empty(n, np.bool_), np.empty(n, np.int8), np.empty(n)
        mk.points_into(kernel_constants(cam, budget), cam.lens_domain.packed, uv, Suv, *out, threaded=True)


def _warm_objects(budget) -> None:
    first_bad_cov2(np.zeros((1, 2, 2)), COV_PSD_RTOL)  # FrameProcessor's check of a frame's pixel covariances
    for cam in _cameras():
        fp = FrameProcessor(cam, budget)
        fp.boxes2d(np.array([[100.0, 150.0, 140.0, 200.0]]))
        fp.boxes2d_columns(np.array([[100.0, 150.0, 140.0, 200.0]]))  # (the service's untracked compact frame)
        # (the tracked one: the centres' Jacobians too, the record's motion rows -- the same signature)
        FrameProcessor(cam, budget, shared_jacobian=True).boxes2d_columns(np.array([[100.0, 150.0, 140.0, 200.0]]),
                                                                          value_rows=10)
        fp.boxes3d(np.array([[0.0, 20.0, 0.8, 4.5, 1.8, 1.5, 0.3]]))
        fp.corners(np.array([[[100.0, 200.0], [140.0, 200.0], [140.0, 210.0], [100.0, 210.0]]]))
        kernel, args = fp.point_jacobian_kernel()  # (the tracker's B at its predicted positions)
        kernel(np.array([[120.0, 200.0]]), *args, np.empty((1, 2, fp.budget.param_factor().rank)),
               np.empty(fk.SCRATCH_SHAPE))


def _warm_lens(budget) -> None:
    """The undistortion of a camera with lens distortion (every command's reference path needs it)."""
    cv = _cameras()[1]
    general.backproject(cv.params, np.array([[10.0, 200.0]]))


_WARM = {"map": _warm_map, "points": _warm_points, "objects": _warm_objects, "lens": _warm_lens}


def warmup(groups: Iterable[str] | None = None, *, progress: Callable[[str], None] | None = None,
           background: bool = False, on_wait: Callable[[str], None] | None = None) -> dict[str, float]:
    """Compile (or load from the cache) every kernel of ``groups`` (default: all); returns seconds per group.

    Each group is compiled under its lock (:func:`group_lock`): a compile of the same group already running
    elsewhere is waited for (then its kernels load from the cache), or with ``background=True`` (the detached
    compile a command starts) the group is skipped; ``on_wait(group)`` is called before such a wait."""
    budget = load_budget("basler1")
    out = {}
    for g in list(groups) if groups is not None else list(GROUPS):
        if on_wait is not None and not background and compiling_elsewhere(g):
            on_wait(g)  # (said, not waited for silently)
        with group_lock(g, wait=not background) as held:
            if not held:
                continue
            if progress is not None:
                progress(g)
            t0 = time.perf_counter()
            with warnings.catch_warnings():  # compiling is what was asked for: no CompileNotice about it
                warnings.simplefilter("ignore", CompileNotice)
                _WARM[g](budget)
            out[g] = time.perf_counter() - t0
    return out
