"""A synthetic checkerboard campaign on disk (the ``footprint-uq calibrate synthetic`` job).

:func:`run_synthetic` renders board images with exact corners (``truth.json``,
:func:`footprint_uq.calibration.synthetic.write_campaign`) and, optionally, runs a planning
study (:func:`~footprint_uq.calibration.synthetic.simulate_campaigns`) written to ``plan.json``:
the intrinsic error sizes (the paper's Table 2) that the campaign delivers for a given corner
noise.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import InputError
from ..io import load_intrinsics
from ..io.atomic import atomic_write_text, check_output_folder, output_set
from .boards import parse_board
from .synthetic import DEFAULT_CAMERA, SyntheticCamera, simulate_campaigns, write_campaign

__all__ = ["SyntheticOptions", "synthetic_camera", "run_synthetic", "SYNTHETIC_OWN"]

#: every name a run writes into its folder (swapped in as one set; anything else there: refused)
SYNTHETIC_OWN = ("board_*.png", "truth.json", "plan.json")


@dataclass(frozen=True)
class SyntheticOptions:
    """Settings of a synthetic campaign (defaults: those of the command).

    Attributes
    ----------
    views : int
        Board poses.
    fill : (float, float)
        Board width as a fraction of the image width (min, max).
    max_tilt_deg : float
        Largest board tilt.
    supersample : int
        Render supersampling per axis.
    blur_sigma_px : float
        Optical blur.
    noise_sigma_dn : float
        Sensor noise, grey levels.
    render : bool
        Render the images (False: planning study only).
    campaigns : int
        Repetitions of the planning study (0: no study).
    corner_noise_px : float
        Corner noise per coordinate of the planning study.
    plan_bootstrap : int
        Bootstrap resamples of the first planning campaign (0: none).
    seed : int
        Seed of the poses, the noise and the bootstrap.
    """

    views: int = 20
    fill: tuple[float, float] = (0.3, 0.55)
    max_tilt_deg: float = 40.0
    supersample: int = 4
    blur_sigma_px: float = 0.6
    noise_sigma_dn: float = 2.0
    render: bool = True
    campaigns: int = 0
    corner_noise_px: float = 0.1
    plan_bootstrap: int = 100
    seed: int = 0


def synthetic_camera(camera_file=None, scale: float = 1.0) -> SyntheticCamera:
    """The camera to simulate: a camera/intrinsics file, or the default Basler-ace-2-like camera.

    Parameters
    ----------
    camera_file : path, optional
        Any file :func:`footprint_uq.io.load_intrinsics` reads; it must state the image size,
        have zero skew and at most the distortion terms k1, k2, p1, p2, k3 (the renderer's lens
        model).
    scale : float
        Scale the sensor, same field of view (:meth:`SyntheticCamera.scaled`).

    Returns
    -------
    SyntheticCamera

    Raises
    ------
    InputError
        The file's camera cannot be rendered (field ``--camera ...``).
    """
    if camera_file is None:
        cam = DEFAULT_CAMERA
    else:
        K, dist, size = load_intrinsics(camera_file)
        if size is None:
            raise InputError("--camera", camera_file, "a camera file that states the image size")
        d = np.zeros(5)
        d[:min(5, len(dist))] = np.asarray(dist, dtype=float)[:5]
        if len(dist) > 5 and np.any(np.asarray(dist)[5:]):
            raise InputError("--camera dist", list(dist), "at most k1, k2, p1, p2, k3 (the renderer's lens model)")
        if abs(K[0, 1]) > 0:
            raise InputError("--camera K skew", K[0, 1], "zero skew (the renderer's lens model)")
        cam = SyntheticCamera(K[0, 0], K[1, 1], K[0, 2], K[1, 2], tuple(size), tuple(d))
    return cam if scale == 1.0 else cam.scaled(scale)


def _plain(o):
    """numpy values -> JSON values (non-finite floats -> None)."""
    if isinstance(o, dict):
        return {str(k): _plain(v) for k, v in o.items()}
    if isinstance(o, (list, tuple)):
        return [_plain(v) for v in o]
    if isinstance(o, np.ndarray):
        return _plain(o.tolist())
    if isinstance(o, (np.floating, float)):
        x = float(o)
        return x if math.isfinite(x) else None
    if isinstance(o, np.integer):
        return int(o)
    if isinstance(o, np.bool_):
        return bool(o)
    return o


def run_synthetic(out_dir, board: str = "14x9", square_m: float = 0.1, *, margin_m: float = 0.05,
                  camera=None, scale: float = 1.0, options: SyntheticOptions | None = None, stage=None,
                  progress=None) -> dict:
    """Render a synthetic checkerboard campaign and/or run its planning study into ``out_dir``.

    Parameters
    ----------
    out_dir : path
        Output directory (created): ``board_NNN.png`` and ``truth.json`` when rendering,
        ``plan.json`` with a planning study; one set, swapped in together
        (:func:`footprint_uq.io.atomic.output_set`; the folder must be new or hold only a previous run's
        files, :data:`SYNTHETIC_OWN`).
    board : str
        Inner corners, ``"COLSxROWS"`` (default: the paper's board).
    square_m, margin_m : float
        Square size and white border, metres.
    camera : SyntheticCamera or path, optional
        The camera, or a camera/intrinsics file (:func:`synthetic_camera`); default
        :data:`~footprint_uq.calibration.synthetic.DEFAULT_CAMERA`.
    scale : float
        Scale the sensor, same field of view.
    options : SyntheticOptions, optional
    stage : callable(str), optional
        Called with a short message as each stage starts (rendering, planning study).
    progress : callable(done, total), optional
        Called after each rendered image and after each campaign of the planning study.

    Returns
    -------
    dict
        ``board`` (:class:`Checkerboard`), ``camera`` (the simulated one), ``rendered`` (bool), ``plan`` (the
        :func:`~footprint_uq.calibration.synthetic.simulate_campaigns` result, or None) and
        ``plan_file`` (path or None).
    """
    o = options if options is not None else SyntheticOptions()
    say = stage or (lambda msg: None)
    b = parse_board(board, square_m, margin_m)
    if isinstance(camera, SyntheticCamera):
        cam = camera if scale == 1.0 else camera.scaled(scale)
    else:
        cam = synthetic_camera(camera, scale)
    out = Path(out_dir)
    check_output_folder(out, SYNTHETIC_OWN, "calibrate synthetic")  # before the work, not after
    pose_kw = {"fill": tuple(o.fill), "max_tilt_deg": o.max_tilt_deg}
    plan = plan_file = None
    if o.campaigns:
        say(f"planning study: {o.campaigns} campaigns of {o.views} views, {o.plan_bootstrap} bootstrap resamples")
        plan = simulate_campaigns(cam, b, o.views, corner_noise_px=o.corner_noise_px, n_campaigns=o.campaigns,
                                  bootstrap=o.plan_bootstrap, seed=o.seed, pose_kw=pose_kw, progress=progress)
    with output_set(out, SYNTHETIC_OWN, "calibrate synthetic") as stage:
        if o.render:
            say(f"rendering {o.views} images ({cam.image_size_px[0]}x{cam.image_size_px[1]} px, supersampled "
                f"{o.supersample}x)")
            write_campaign(stage, cam, b, o.views, seed=o.seed, pose_kw=pose_kw, supersample=o.supersample,
                           blur_sigma_px=o.blur_sigma_px, noise_sigma_dn=o.noise_sigma_dn, progress=progress)
        if plan is not None:
            atomic_write_text(stage / "plan.json", json.dumps(_plain(plan), indent=2))
            plan_file = out / "plan.json"
    return {"board": b, "camera": cam, "rendered": o.render, "plan": plan, "plan_file": plan_file}
