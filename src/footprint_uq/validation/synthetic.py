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
from ..tracking.synthetic import default_camera, trajectories, true_pixels
from ..uncertainty.budget import load_budget
from .readers import NO_DETECTION, LabelChunk

__all__ = ["random_cameras", "campaign_chunks", "campaign_table", "motion_chunks"]


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


def motion_chunks(n_campaigns: int, n_objects: int, budget="basler1@deg", *, duration_s: float = 4.0,
                  rate_hz: float = 10.0, truth_accel_psd_m2ps3: float = 1.5, detector_sigma_px: float = 1.5,
                  scenario: str = "straight", seed: int = 0) -> Iterator[LabelChunk]:
    """Seeded labelled sequences with a known truth velocity: one :class:`LabelChunk` per campaign (one camera,
    :func:`~footprint_uq.tracking.synthetic.default_camera`, with one calibration draw), every frame's objects
    with ``time_s``, ``object_id`` and ``truth_v_world_mps``.

    The truth moves as :func:`~footprint_uq.tracking.synthetic.trajectories` (``scenario``, white-noise
    acceleration of density ``truth_accel_psd_m2ps3``, m^2/s^3); each detection is a box whose bottom centre is
    the truth's pixel in the true camera plus the budget's pixel noise and the detector's (``detector_sigma_px``,
    given as the rows' ``cov_uv_px2``).
    """
    bud = load_budget(budget)
    rng = np.random.default_rng(seed)
    cam = default_camera()
    L = bud.param_factor().dense()
    det = detector_sigma_px ** 2 * np.eye(2)
    A_px = np.linalg.cholesky(bud.pixel_covariance() + det)
    for c in range(n_campaigns):
        tr = trajectories(scenario, n_objects, rate_hz, duration_s, rng, truth_accel_psd_m2ps3=truth_accel_psd_m2ps3)
        p_true = np.repeat((cam.params + L @ rng.standard_normal(L.shape[1]))[None], n_objects, axis=0)
        F = len(tr.t_s)
        uv = np.concatenate([true_pixels(cam, p_true, tr.xy_m[k]) for k in range(F)])
        uv = uv + rng.standard_normal(uv.shape) @ A_px.T
        n = len(uv)
        half_w, h = np.repeat(rng.uniform(20, 60, n_objects)[None], F, 0).ravel(), 40.0
        boxes = np.stack([uv[:, 0] - half_w, uv[:, 1] - h, uv[:, 0] + half_w, uv[:, 1]], 1)
        W, H = cam.image_size_px  # a road user that leaves the image (under the camera) is a truth without detection
        seen = np.isfinite(uv).all(1) & (uv[:, 0] >= 0) & (uv[:, 0] <= W) & (uv[:, 1] >= 0) & (uv[:, 1] <= H)
        boxes[~seen] = np.nan
        ids = np.array([f"{c}-{i}" for _ in range(F) for i in range(n_objects)], dtype=object)
        yield LabelChunk(source="synthetic", camera_key=f"camera:{c}", camera=cam, line=np.arange(n),
                         frame=np.repeat(np.arange(F), n_objects).astype(object), object_id=ids,
                         cls=np.full(n, "car", dtype=object), box_xyxy_px=boxes,
                         truth_xy_world_m=tr.xy_m.reshape(n, 2), truth_z_m=np.zeros(n),
                         yaw_world_rad=np.full(n, np.nan), error=[None if s else NO_DETECTION for s in seen],
                         cov_uv_px2=np.broadcast_to(det, (n, 2, 2)).copy(), time_s=np.repeat(tr.t_s, n_objects),
                         truth_v_world_mps=tr.v_mps.reshape(n, 2))
