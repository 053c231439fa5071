"""The 3-camera intersection of footprint_uq.tracking.rsu_synthetic as ``serve`` input: camera files, a registry, and
detector frames of a few vehicles on the lanes, a parked car and a pedestrian (used by tests/test_cp_serve.py and
tests/test_cp_serve_mqtt.py).

Each camera sees the truth through its nominal calibration (no calibration error drawn: the tests check the wiring,
the messages and the rules; the fusion's statistics are tests/test_rsu_fusion.py's) plus 1 px of pixel noise, as
one corner per object (``u0_px, v0_px``: the ground contact point).
"""

from __future__ import annotations

import numpy as np

from footprint_uq.io import save_camera
from footprint_uq.tracking.rsu_synthetic import LANES, intersection_cameras

T0 = 1714564800.0
#: object id -> (start point (m), velocity (m/s), class); ids 100 (parked car) and 200 (pedestrian) stand or walk
OBJECTS = {
    1: (LANES[0][0] + np.array([0.0, -30.0]), 10.0 * LANES[0][1], "car"),
    2: (LANES[2][0] + np.array([0.0, 25.0]), 9.0 * LANES[2][1], "car"),
    3: (LANES[4][0] + np.array([-28.0, 0.0]), 11.0 * LANES[4][1], "truck"),
    4: (LANES[7][0] + np.array([20.0, 0.0]), 8.0 * LANES[7][1], "car"),
    100: (np.array([3.0, -12.0]), np.zeros(2), "car"),
    200: (np.array([-9.5, -4.0]), np.array([0.0, 1.2]), "person"),
}


def write_site(folder, *, clock_offset_sigma_s: float = 0.005, sensor_ids=(None, None, None)):
    """The three camera files and ``registry.csv`` (``sensor_id`` column: None -> the default) in ``folder``."""
    rows = ["camera_id,camera,budget,sensor_id,clock_offset_sigma_s"]
    for k, cam in enumerate(intersection_cameras()):
        save_camera(cam, folder / f"cam{k}.yaml")
        sid = "" if sensor_ids[k] is None else str(sensor_ids[k])
        rows.append(f"cam{k},cam{k}.yaml,basler1@deg,{sid},{clock_offset_sigma_s}")
    reg = folder / "registry.csv"
    reg.write_text("\n".join(rows) + "\n")
    return reg


def truth(t_s: float) -> dict:
    """Object id -> (xy (m), class) at ``t_s`` s after T0."""
    return {oid: (p + v * t_s, c) for oid, (p, v, c) in OBJECTS.items()}


def frames(n_steps: int, rate_hz: float = 10.0, seed: int = 0, skip=()) -> list[dict]:
    """Every camera's frames of ``n_steps`` time steps, in time order (camera 0, 1, 2 at each step): each object
    the camera images inside the picture, in front of it, within 60 m; ``skip``: (step, camera) pairs left out."""
    rng = np.random.default_rng(seed)
    cams = intersection_cameras()
    out = []
    for k in range(n_steps):
        t = k / rate_hz
        tr = truth(t)
        for j, cam in enumerate(cams):
            if (k, j) in skip:
                continue
            dets = []
            for oid, (xy, cls) in tr.items():
                pr = cam.project_ground(np.asarray(xy, float)[None])
                uv = pr.uv_px[0] + rng.normal(0.0, 1.0, 2)
                w, h = cam.image_size_px
                rel = np.asarray(xy) - np.asarray(cam.position_m)
                if (pr.valid[0] and 0 <= uv[0] < w and 0 <= uv[1] < h and np.hypot(*rel) < 60.0
                        and _ahead(cam, rel)):
                    dets.append({"object_id": oid, "class": cls, "class_confidence": 0.9, "u0_px": float(uv[0]),
                                 "v0_px": float(uv[1])})
            out.append({"camera_id": f"cam{j}", "frame": k, "timestamp_s": T0 + t, "detections": dets})
    return out


def _ahead(cam, rel) -> bool:
    pan = np.radians(cam.pan_deg)
    fwd = rel @ np.array([np.sin(pan), np.cos(pan)])
    side = rel @ np.array([np.cos(pan), -np.sin(pan)])
    return bool(fwd > 0 and abs(side) < fwd * 0.5 * cam.image_size_px[0] / cam.focal_px)
