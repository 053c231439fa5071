"""Helpers shared by several commands: camera, pose and budget loading, option checks, stderr lines.

(Those of the ``calibrate`` commands only are in :mod:`.calibrate_common`, so that the other
commands do not load the calibration package.)
"""

from __future__ import annotations

import functools
import math
import sys
import threading
import time

import click
from tqdm import tqdm

from ..errors import InputError
from ..io import load_camera
from ..uncertainty.budget import load_budget
from ..uncertainty.ellipse import chi2_scale

__all__ = ["FiniteFloat", "FiniteFloatRange", "AscendingFloats", "FINITE", "LATITUDE_DEG", "LONGITUDE_DEG",
           "min_max_callback", "load_camera_and_budget", "check_confidence", "note", "warn", "pose_options",
           "pose_from_options", "budget_notice", "DEFAULT_STEP_PX", "Stages"]

#: the default grid step of every map the command line draws (``map``, ``demo``), pixels
DEFAULT_STEP_PX = 4

class FiniteFloat(click.types.FloatParamType):
    """A float option that refuses ``nan``, ``inf`` and ``-inf`` (click's ``float`` takes them).

    Every float option of the command line uses this type or :class:`FiniteFloatRange`
    (``tests/test_cli_options.py`` walks the command tree and gives each float option ``nan``, ``inf``
    and ``-inf``): a NaN option would otherwise become a verdict computed with NaN, a band named
    "0-nan m", a cost limit nothing meets.
    """

    name = "finite float"

    def convert(self, value, param, ctx):
        rv = super().convert(value, param, ctx)
        if not math.isfinite(rv):
            self.fail(f"{value!r} is not a finite number (expected a finite number)", param, ctx)
        return rv


class FiniteFloatRange(click.FloatRange):
    """:class:`click.FloatRange` that refuses ``nan``, ``inf`` and ``-inf`` first (click's range check
    lets NaN through: every comparison with NaN is false)."""

    name = "finite float range"

    def convert(self, value, param, ctx):
        rv = click.types.FloatParamType.convert(self, value, param, ctx)
        if not math.isfinite(rv):
            self.fail(f"{value!r} is not a finite number (expected a finite number in {self._describe_range()})",
                      param, ctx)
        return super().convert(rv, param, ctx)


class AscendingFloats(click.ParamType):
    """A comma-separated list of finite, strictly ascending numbers (``--range-bands 0,25,50,100``).

    Parameters
    ----------
    min_value : float or None
        Smallest value allowed (None: any).
    example : str
        An example shown in the error message.
    """

    name = "ascending list"

    def __init__(self, min_value: float | None = 0.0, example: str = "0,25,50,100"):
        self.min_value = min_value
        self.example = example

    def convert(self, value, param, ctx):
        if isinstance(value, tuple):
            return value
        expected = "comma-separated finite numbers in ascending order"
        if self.min_value is not None:
            expected += f", none below {self.min_value:g}"
        expected += f", e.g. {self.example}"
        try:
            edges = tuple(float(v) for v in str(value).split(","))
        except ValueError:
            self.fail(f"{value!r} (expected {expected})", param, ctx)
        bad = (not all(math.isfinite(v) for v in edges)
               or any(b <= a for a, b in zip(edges, edges[1:], strict=False))
               or (self.min_value is not None and edges[0] < self.min_value))
        if bad:
            self.fail(f"{value!r} (expected {expected})", param, ctx)
        return edges


def min_max_callback(ctx, param, value):
    """Callback of a ``(min, max)`` option (``type=(FiniteFloatRange(..), FiniteFloatRange(..))``): refuses
    ``min > max`` with click's one-line message."""
    if value is not None and len(value) == 2 and value[0] > value[1]:
        raise click.BadParameter(f"{value[0]:g} {value[1]:g} (expected MIN MAX with MIN <= MAX)", ctx, param)
    return value


#: the shared instance of :class:`FiniteFloat` (``type=FINITE``)
FINITE = FiniteFloat()
#: a WGS84 latitude / longitude option, degrees
LATITUDE_DEG = FiniteFloatRange(-90.0, 90.0)
LONGITUDE_DEG = FiniteFloatRange(-180.0, 180.0)

_POSE_HELP = "; with an intrinsics-only camera file (e.g. the camera.yaml of `calibrate intrinsics`)."
_POSE_OPTIONS = (
    click.option("--pose-file", default=None, metavar="FILE",
                 help="The camera's pose, a YAML/JSON file with R and t (world -> camera), rvec and tvec, or "
                      "height_m, pan_deg, tilt_deg [, roll_deg, position_m, ground_z_m] (docs/file-formats.md)"
                      + _POSE_HELP),
    click.option("--height-m", type=FINITE, default=None, metavar="H",
                 help="Pose: camera height above the ground plane, metres (with --pan-deg and --tilt-deg)"
                      + _POSE_HELP),
    click.option("--pan-deg", type=FINITE, default=None, metavar="DEG",
                 help="Pose: compass heading of the optical axis, degrees clockwise from north."),
    click.option("--tilt-deg", type=FINITE, default=None, metavar="DEG",
                 help="Pose: tilt below the horizontal, degrees (positive down)."),
    click.option("--roll-deg", type=FINITE, default=None, metavar="DEG",
                 help="Pose: roll about the optical axis, degrees (default 0)."),
    click.option("--position-m", type=(FINITE, FINITE), default=None, metavar="X Y",
                 help="Pose: camera foot point, metres east and north of the world origin (default 0 0)."),
)
_POSE_ARGS = ("pose_file", "height_m", "pan_deg", "tilt_deg", "roll_deg", "position_m")


def pose_from_options(pose_file=None, height_m=None, pan_deg=None, tilt_deg=None, roll_deg=None,
                      position_m=None):
    """The ``pose`` argument of :func:`footprint_uq.io.load_camera` from the pose options: None (no pose
    option), the pose file's path, or a mapping of the paper's pose parameters (InputError when mixed
    or incomplete)."""
    angles = {"--height-m": height_m, "--pan-deg": pan_deg, "--tilt-deg": tilt_deg}
    extra = {"--roll-deg": roll_deg, "--position-m": position_m}
    given = [k for k, v in {**angles, **extra}.items() if v is not None]
    if pose_file is not None:
        if given:
            raise InputError(given[0], "given with --pose-file", "one pose: --pose-file, or --height-m, --pan-deg "
                             "and --tilt-deg [--roll-deg, --position-m]")
        return str(pose_file)
    if not given:
        return None
    missing = [k for k, v in angles.items() if v is None]
    if missing:
        raise InputError(missing[0], "missing", f"all of --height-m, --pan-deg and --tilt-deg (given: "
                         f"{', '.join(given)})")
    pose = {"height_m": height_m, "pan_deg": pan_deg, "tilt_deg": tilt_deg}
    if roll_deg is not None:
        pose["roll_deg"] = roll_deg
    if position_m is not None:
        pose["position_m"] = list(position_m)
    return pose


def pose_options(f):
    """Decorator of a command: adds the pose options (:data:`_POSE_OPTIONS`) and passes them on as one
    ``pose`` keyword (:func:`pose_from_options`)."""

    @functools.wraps(f)
    def wrapper(*args, **kwargs):
        pose = pose_from_options(**{k: kwargs.pop(k) for k in _POSE_ARGS})
        return f(*args, pose=pose, **kwargs)

    for option in reversed(_POSE_OPTIONS):
        wrapper = option(wrapper)
    return wrapper


def budget_notice(budget) -> str | None:
    """The loud line for a budget without extrinsic terms (None for one that has them)."""
    missing = budget.missing_terms()
    if "extrinsic" not in missing:
        return None
    what = " or ".join(missing)
    return (f"the budget {budget.name!r} has no {what} error terms (as the budget.yaml of `calibrate intrinsics`): "
            "the covariances are those of the intrinsics and the pixel noise alone, far smaller than a deployed "
            "camera's; add the pose's errors (height_m, pan_deg, tilt_deg, ...; docs/file-formats.md)")


def load_camera_and_budget(camera_path, budget_spec, pose=None):
    """``(camera, budget)`` from a camera file (with ``pose`` for an intrinsics-only one) and a preset name
    or budget file (bad input: InputError); a budget without extrinsic terms is named on stderr."""
    camera, budget = load_camera(camera_path, pose=pose), load_budget(budget_spec)
    msg = budget_notice(budget)
    if msg is not None:
        warn(msg)
    return camera, budget


def check_confidence(confidence: float | None) -> float | None:
    """``--confidence``: None, or a probability in (0, 1) (else InputError naming ``confidence``)."""
    if confidence is None:
        return None
    chi2_scale(confidence)  # raises InputError("confidence", ...) outside (0, 1)
    return float(confidence)


def note(msg: str) -> None:
    """One line on stderr: ``footprint-uq: MSG``."""
    click.echo(f"footprint-uq: {msg}", err=True)


class Stages:
    """A long command's progress on stderr: one line per stage, ``footprint-uq: COMMAND: STAGE [12 s]`` (the
    seconds since the command started), and for counted steps a tqdm bar when stderr is a terminal (else a line
    when the count ends: no bar in a log file).  ``bar``: None (a terminal decides), True, False.

    Used as a context manager around the library call.  A stage's line is said once the stage has run for
    ``delay_s`` (default 1 s) or when the next stage starts, whichever comes first, and at the end of the ``with``
    block; a stage cut short by an error within ``delay_s`` says nothing, so that a bad input is still the one line
    of its error (inputs are checked at once; a long stage is said within a second).

    >>> with Stages("demo") as say:                  # doctest: +SKIP
    ...     say("maps")
    footprint-uq: demo: maps [0 s]
    """

    def __init__(self, command: str, *, bar: bool | None = None, delay_s: float = 1.0):
        self.command = command
        self.t0 = time.monotonic()
        self.bar = sys.stderr.isatty() if bar is None else bar
        self.delay_s = delay_s
        self._tqdm = None
        self._pending: str | None = None
        self._timer: threading.Timer | None = None
        self._lock = threading.Lock()

    def __enter__(self) -> Stages:
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        if exc_type is None:
            self.flush()
        else:  # an error: its one line, not the stage it cut short
            self._cancel()
        self.close()

    def __call__(self, msg: str) -> None:
        self.close()
        self.flush()
        with self._lock:
            self._pending = f"footprint-uq: {self.command}: {msg} [{time.monotonic() - self.t0:.0f} s]"
            self._timer = threading.Timer(self.delay_s, self.flush)
            self._timer.daemon = True
            self._timer.start()

    def flush(self) -> None:
        """Say the pending stage's line now (if any)."""
        with self._lock:
            line, self._pending = self._pending, None
            if self._timer is not None:
                self._timer.cancel()
                self._timer = None
        if line is not None:
            click.echo(line, err=True)

    def _cancel(self) -> None:
        with self._lock:
            self._pending = None
            if self._timer is not None:
                self._timer.cancel()
                self._timer = None

    def count(self, done: int, total: int) -> None:
        """``done`` of ``total`` steps of the current stage are done."""
        self.flush()
        if self.bar:
            if self._tqdm is None:
                self._tqdm = tqdm(total=total, file=sys.stderr, leave=False, unit="step")
            self._tqdm.update(done - self._tqdm.n)
        if done >= total:
            self.close()
            click.echo(f"footprint-uq: {self.command}: {done} of {total} done [{time.monotonic() - self.t0:.0f} s]",
                       err=True)

    def close(self) -> None:
        if self._tqdm is not None:
            self._tqdm.close()
            self._tqdm = None


def warn(msg: str) -> None:
    """One warning line on stderr: ``footprint-uq: warning: MSG``."""
    click.echo(f"footprint-uq: warning: {msg}", err=True)
