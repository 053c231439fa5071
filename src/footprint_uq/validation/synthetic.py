"""Synthetic labelled campaigns drawn from a known budget: the truth of the validation's own tests.

Each camera draws its calibration error **once** (``delta ~ N(0, Sigma_params)``, shared by all its
objects); each object is a pixel ``uv`` of the *true* camera (nominal parameters + delta) whose ray meets
the true ground at the truth point, and the detection is a 2-D box whose bottom-centre is ``uv`` plus the
budget's pixel noise.  Validating with the nominal camera and the same budget must then be consistent.
"""

from __future__ import annotations

from collections.abc import Iterator

import numpy as np
import pyarrow as pa

from ..cameras.general import backproject
from ..cameras.pantilt import PanTiltCamera
from ..uncertainty.budget import load_budget
from .readers import LabelChunk

__all__ = ["random_cameras", "campaign_chunks", "campaign_table"]


def random_cameras(n_cameras: int, *, seed: int = 0, image_size_px=(1920, 1080)) -> dict[str, PanTiltCamera]:
    """``n_cameras`` plausible roadside cameras (6-14 m high, tilt 8-25 deg, focal 1200-2400 px), by id."""
    rng = np.random.default_rng(seed)
    out = {}
    for k in range(n_cameras):
        out[f"cam{k:03d}"] = PanTiltCamera(focal_px=rng.uniform(1200, 2400), image_size_px=image_size_px,
                                           height_m=rng.uniform(6, 14), pan_deg=rng.uniform(0, 360),
                                           tilt_deg=rng.uniform(8, 25), roll_deg=rng.uniform(-1, 1),
                                           position_m=(rng.uniform(-500, 500), rng.uniform(-500, 500)))
    return out


def _draw(camera, budget, n: int, rng):
    """Truth points and detection boxes of ``n`` objects seen by ``camera`` with one calibration draw."""
    S = budget.param_covariance()
    w, V = np.linalg.eigh(S)
    delta = V @ (np.sqrt(np.clip(w, 0, None)) * rng.standard_normal(len(w)))
    p_true = camera.params + delta
    W, H = camera.image_size_px
    v_hor = float(np.max(camera.horizon_v_px(np.array([0.0, W - 1.0]))))
    v0 = min(max(v_hor + 0.12 * H, 0.35 * H), 0.9 * H)
    uv = np.stack([rng.uniform(0.05 * W, 0.95 * W, n), rng.uniform(v0, H - 1.0, n)], 1)
    truth = backproject(p_true, uv, domain=camera.lens_domain).xy_world_m
    L = np.linalg.cholesky(budget.pixel_covariance() + 1e-300 * np.eye(2))
    uv_det = uv + rng.standard_normal((n, 2)) @ L.T
    half_w, h = rng.uniform(20, 80, n), rng.uniform(30, 120, n)
    boxes = np.stack([uv_det[:, 0] - half_w, uv_det[:, 1] - h, uv_det[:, 0] + half_w, uv_det[:, 1]], 1)
    return truth, boxes


def campaign_chunks(cameras: dict, budget, n_per_camera: int, *, seed: int = 0) -> Iterator[LabelChunk]:
    """One :class:`LabelChunk` per camera: ``n_per_camera`` objects with the camera's one calibration draw."""
    bud = load_budget(budget)
    rng = np.random.default_rng(seed)
    for cid, cam in cameras.items():
        truth, boxes = _draw(cam, bud, n_per_camera, rng)
        n = len(boxes)
        ids = np.array([str(i) for i in range(n)], dtype=object)
        yield LabelChunk(source="synthetic", camera_key=f"camera:{cid}", camera=cam, line=np.arange(n),
                         frame=np.zeros(n, dtype=object), object_id=ids, cls=np.full(n, "car", dtype=object),
                         box_xyxy_px=boxes, truth_xy_world_m=truth, truth_z_m=np.zeros(n),
                         yaw_world_rad=np.full(n, np.nan), error=[None] * n)


def campaign_table(cameras: dict, budget, n_per_camera: int, *, seed: int = 0) -> Iterator[pa.Table]:
    """The same campaign as pairs-table blocks (one per camera): ``camera_id, frame, object_id, class,
    u_min_px, v_min_px, u_max_px, v_max_px, x_m, y_m`` (docs/validation.md, "Pairs table")."""
    for ch, cid in zip(campaign_chunks(cameras, budget, n_per_camera, seed=seed), cameras, strict=True):
        n = len(ch)
        cols = {"camera_id": pa.array([cid] * n), "frame": pa.array(np.zeros(n, dtype=np.int64)),
                "object_id": pa.array(ch.object_id.tolist(), pa.string()), "class": pa.array(ch.cls.tolist())}
        for j, c in enumerate(("u_min_px", "v_min_px", "u_max_px", "v_max_px")):
            cols[c] = pa.array(ch.box_xyxy_px[:, j])
        cols["x_m"], cols["y_m"] = pa.array(ch.truth_xy_world_m[:, 0]), pa.array(ch.truth_xy_world_m[:, 1])
        yield pa.table(cols)
