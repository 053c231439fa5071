"""A layout on disk, its evaluation and its sensitivity.

``layout.yaml`` (written by ``footprint-uq plan``, read by ``plan --evaluate`` and ``plan --serve``)::

    site: site.yaml                 # informational
    cameras:
      - name: east-1                # unique; the camera file is cameras/<name>.yaml
        camera_file: cameras/east-1.yaml   # any camera file format footprint-uq reads
        budget: basler1             # preset, budget file (relative to layout.yaml) or mapping;
                                    # default: the budget of camera_type in the site file
        mount: east-1               # optional (the site's mount, camera type and lens)
        camera_type: hd
        lens: wide

Every camera file is a plain footprint-uq camera file: ``footprint-uq map``, ``locate``,
``objects`` ... take it as it is.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import yaml

from .. import params as P
from ..cameras.opencv import OpenCVCamera
from ..cameras.pantilt import PanTiltCamera
from ..cameras.rotation import R_W_C
from ..errors import ConfigError, InputError
from ..io import load_camera, save_camera
from ..io._common import label, read_mapping, sanitize
from ..io.atomic import atomic_write_text, path_component
from ..uncertainty.budget import load_budget
from .coverage import CameraConfig, build_camera, camera_information, evaluate_information

__all__ = ["LayoutCamera", "layout_from_configs", "write_layout", "read_layout", "evaluate_cameras",
           "perturbed_camera", "sensitivity", "write_json"]


@dataclass
class LayoutCamera:
    """One camera of a layout: name, model, budget and, when known, the site configuration it came from."""

    name: str
    camera: object
    budget: object
    config: CameraConfig | None = None
    budget_spec: object = None


def layout_from_configs(site, configs) -> list[LayoutCamera]:
    """The cameras of planned configurations (named after their mounts)."""
    out = []
    for cfg in configs:
        ct = site.camera_type(cfg.camera_type)
        out.append(LayoutCamera(cfg.mount, build_camera(site, cfg), ct.budget, cfg, ct.budget_spec))
    return out


def _budget_entry(lc: LayoutCamera, out_dir: Path):
    spec = lc.budget_spec
    if isinstance(spec, str):
        p = Path(spec)
        if not p.exists():
            return spec  # a preset name
        return str(p.resolve())
    return lc.budget.to_dict()


def write_layout(cameras: list[LayoutCamera], out_dir, *, site_path=None) -> dict[str, Path]:
    """Write ``layout.yaml`` and one camera file per camera under ``out_dir/cameras`` (atomically)."""
    out = Path(out_dir)
    (out / "cameras").mkdir(parents=True, exist_ok=True)
    files, entries = {}, []
    for lc in cameras:
        rel = Path("cameras") / f"{path_component(lc.name)}.yaml"
        files[f"camera:{lc.name}"] = save_camera(lc.camera, out / rel)
        e = {"name": lc.name, "camera_file": str(rel), "budget": _budget_entry(lc, out)}
        if lc.config is not None:
            e.update({"mount": lc.config.mount, "camera_type": lc.config.camera_type, "lens": lc.config.lens})
        entries.append(e)
    doc = {"site": None if site_path is None else str(site_path), "cameras": entries}
    p = out / "layout.yaml"
    atomic_write_text(p, "# footprint-uq plan: layout (docs/planning.md)\n"
                      + yaml.safe_dump(sanitize(doc), sort_keys=False, default_flow_style=None, width=100))
    files["layout"] = p
    return files


_ENTRY = {"name", "camera_file", "budget", "mount", "camera_type", "lens"}


def _read_entry(site, where, i, e, base: Path, seen) -> LayoutCamera:
    fld = f"cameras[{i}]"
    if not isinstance(e, dict):
        raise ConfigError(label(where, fld), e, "a mapping with name, camera_file and budget")
    unknown = sorted(set(e) - _ENTRY)
    if unknown:
        raise ConfigError(label(where, f"{fld}.{unknown[0]}"), e[unknown[0]], f"one of {sorted(_ENTRY)}")
    name = e.get("name")
    if not isinstance(name, str) or not name or name in seen:
        raise ConfigError(label(where, f"{fld}.name"), name, "a non-empty name, unique in the layout")
    seen.add(name)
    if "camera_file" not in e:
        raise ConfigError(label(where, f"{fld}.camera_file"), "missing", "the camera's file (required)")
    cam = load_camera(base / str(e["camera_file"]))
    cfg = None
    if "camera_type" in e:
        ct = site.camera_type(str(e["camera_type"]))
        spec = e.get("budget", ct.budget_spec)
        m = e.get("mount")
        if m is not None:
            site.mount(str(m))
            cfg = CameraConfig(str(m), ct.name, str(e.get("lens", ct.lenses[0].name)), cam.height_m,
                               float(np.mod(cam.pan_deg, 360.0)), cam.tilt_deg)
    else:
        spec = e.get("budget")
        if spec is None:
            raise ConfigError(label(where, f"{fld}.budget"), "missing", "a budget (or a camera_type of the site)")
    if isinstance(spec, str) and (base / spec).exists():
        spec = str((base / spec).resolve())
    try:
        budget = load_budget(spec)
    except InputError as err:
        raise ConfigError(label(where, f"{fld}.budget"), spec, err.expected) from None
    return LayoutCamera(name, cam, budget, cfg, spec)


def read_layout(path, site) -> list[LayoutCamera]:
    """Read ``layout.yaml`` (see the module docstring); camera files and budgets relative to it."""
    p, d = read_mapping(path, what="layout file")
    cams = d.get("cameras")
    if not isinstance(cams, list) or not cams:
        raise ConfigError(label(str(p), "cameras"), cams, "a list of at least one camera")
    seen: set = set()
    return [_read_entry(site, str(p), i, e, p.parent, seen) for i, e in enumerate(cams)]


def evaluate_cameras(site, samples, cameras: list[LayoutCamera], *, fusion: bool = True, budget_scale: float = 1.0):
    """:class:`~footprint_uq.planning.coverage.LayoutEvaluation` of a layout of any camera models."""
    infos = [camera_information(lc.camera, lc.budget if budget_scale == 1.0 else lc.budget.scaled(budget_scale),
                                samples.xy_world_m, site.occluders) for lc in cameras]
    return evaluate_information(site, samples, infos, fusion=fusion), infos


def perturbed_camera(camera, *, height_m: float = 0.0, tilt_deg: float = 0.0, pan_deg: float = 0.0):
    """The same camera raised by ``height_m`` and tilted further down by ``tilt_deg`` (any model)."""
    p = camera.params
    h = float(p[P.HM]) + height_m
    tilt = float(np.clip(np.rad2deg(p[P.TILT]) + tilt_deg, -90.0, 90.0))
    pan = float(np.mod(np.rad2deg(p[P.PAN]) + pan_deg + 180.0, 360.0) - 180.0)
    if h <= 0:
        raise InputError("height_m", h, "a camera above the ground (> 0 m)")
    if isinstance(camera, PanTiltCamera):
        return PanTiltCamera(camera.focal_px, camera.image_size_px, h, pan, tilt, camera.roll_deg,
                             camera.position_m, camera.principal_point_px, camera.ground_z_m)
    Rwc = R_W_C(np.deg2rad(pan), np.deg2rad(tilt), p[P.ROLL])
    C = np.array([p[P.XM], p[P.YM], h + camera.ground_z_m])
    R = Rwc.T
    return OpenCVCamera(camera.K, camera.dist, R, -R @ C, camera.image_size_px, camera.ground_z_m)


PERTURBATIONS = (("height +1 m", {"height_m": 1.0}), ("height -1 m", {"height_m": -1.0}),
                 ("tilt +2 deg", {"tilt_deg": 2.0}), ("tilt -2 deg", {"tilt_deg": -2.0}))


def _info(site, samples, camera, budget):
    return camera_information(camera, budget, samples.xy_world_m, site.occluders)


def sensitivity(site, samples, cameras: list[LayoutCamera], *, fusion: bool = True) -> list[dict]:
    """How the weighted met fraction changes: each camera and all cameras at +-1 m of height and +-2 deg of
    tilt, and every budget sigma doubled.  Rows: ``{"change", "camera", "fraction_met", "delta_points"}``
    (``delta_points`` in percentage points of the weighted area).

    Each camera's information is computed once per perturbation and combined with the others' nominal
    information (one evaluation per camera and perturbation, not per row).
    """
    base_infos = [_info(site, samples, lc.camera, lc.budget) for lc in cameras]

    def frac(infos):
        return evaluate_information(site, samples, infos, fusion=fusion).fraction

    base = frac(base_infos)
    rows = [{"change": "as planned", "camera": "all", "fraction_met": base, "delta_points": 0.0}]

    def row(change, cam, f):
        rows.append({"change": change, "camera": cam, "fraction_met": f, "delta_points": 100 * (f - base)})

    for label_, kw in PERTURBATIONS:
        moved = [_info(site, samples, perturbed_camera(lc.camera, **kw), lc.budget) for lc in cameras]
        row(label_, "all", frac(moved))
        for k, lc in enumerate(cameras):
            row(label_, lc.name, frac(base_infos[:k] + [moved[k]] + base_infos[k + 1:]))
    row("budget sigmas x2", "all", frac([_info(site, samples, lc.camera, lc.budget.scaled(2.0)) for lc in cameras]))
    return rows


def _finite(obj):
    if isinstance(obj, dict):
        return {k: _finite(v) for k, v in obj.items()}
    if isinstance(obj, list):
        return [_finite(v) for v in obj]
    if isinstance(obj, float) and not np.isfinite(obj):
        return None
    return obj


def write_json(path, data) -> Path:
    """Write ``data`` as JSON (atomically; NaN/inf as null)."""
    p = Path(path)
    p.parent.mkdir(parents=True, exist_ok=True)
    atomic_write_text(p, json.dumps(_finite(sanitize(data)), indent=2, allow_nan=False) + "\n")
    return p
