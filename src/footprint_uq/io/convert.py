"""``footprint-uq convert``: a camera file in another model (a homography from any camera, an OpenCV camera).

The conversion itself lives with the camera models
(:func:`footprint_uq.cameras.homography.homography_from_camera`); this module reads, converts and
writes atomically.
"""

from __future__ import annotations

import json
from pathlib import Path

import yaml

from ..cameras.homography import homography_from_camera
from ..cameras.opencv import OpenCVCamera
from ..errors import InputError
from ._common import read_mapping, sanitize
from .atomic import atomic_write_text
from .camera_files import camera_to_dict, load_camera
from .homography_files import load_homography

__all__ = ["TARGETS", "convert_camera_file"]

#: the models `convert` writes
TARGETS = ("homography", "opencv")


def convert_camera_file(camera, to: str, out, *, keep_intrinsics: bool = False) -> Path:
    """Read ``camera`` (any format :func:`footprint_uq.io.load_camera` reads, or a ``model: homography``
    file), convert it to model ``to`` and write ``out`` (``.yaml``/``.yml``/``.json``) atomically.

    ``to="homography"`` writes ``H_ground_image`` of the camera's ground plane (cameras without lens
    distortion only); ``keep_intrinsics`` adds ``K`` so that the file decomposes back into the camera.
    ``to="opencv"`` writes K, R, t.  Returns the path written.
    """



    if to not in TARGETS:
        raise InputError("--to", to, f"one of {', '.join(TARGETS)}")
    out = Path(out)
    if out.suffix.lower() not in (".yaml", ".yml", ".json"):
        raise InputError("--out", str(out), "a file name ending in .yaml, .yml or .json")
    _, data = read_mapping(camera)
    if isinstance(data, dict) and str(data.get("model", "")).strip().lower() == "homography":
        f = load_homography(camera)
        cam = f.camera
        if cam is None and to == "opencv":
            raise InputError(f"{camera}: K", "missing", "K to turn a homography into an OpenCV camera")
        src = cam if cam is not None else f.homography
    else:
        src = cam = load_camera(camera)
    if to == "homography":
        H = homography_from_camera(src)
        d = {"model": "homography", "image_size_px": list(src.image_size_px), "H_ground_image": H.tolist(),
             "ground_z_m": float(src.ground_z_m)}
        if keep_intrinsics:
            if cam is None:
                raise InputError("--keep-intrinsics", True, "a camera with intrinsics (this homography has no K)")
            d["K"] = cam.K.tolist()
        header = "footprint-uq homography: pixel (u, v, 1) -> ground (x, y, 1) in W, up to scale"
    else:
        if not hasattr(cam, "T_cam_world"):
            raise InputError("camera", type(cam).__name__, "a camera with a pose")

        T = cam.T_cam_world
        dist = cam.dist
        oc = OpenCVCamera(cam.K, dist if any(dist[5:]) else dist[:5], T[:3, :3], T[:3, 3], cam.image_size_px,
                          cam.ground_z_m)
        d = camera_to_dict(oc)
        header = "footprint-uq camera file (docs/file-formats.md)"
    d = sanitize(d)
    if out.suffix.lower() == ".json":
        text = json.dumps(d, indent=2, allow_nan=False) + "\n"
    else:
        text = f"# {header}\n" + yaml.safe_dump(d, sort_keys=False, default_flow_style=None, width=100)
    return atomic_write_text(out, text, parents=True)
