"""CameraTracker.step_frame (tracking/camera_tracker.py): the service's one tracking call per frame is the sequence
of calls it replaces -- ClassTracks.step, NisMonitor.observe, ContactSlide.apply (2-D boxes), object_motion -- on
seeded frames with births, deaths (timeouts), missed frames, objects without a centre, 2-D and 3-D boxes and
classes of two motion models."""

from __future__ import annotations

import numpy as np
import pytest

from footprint_uq import PanTiltCamera
from footprint_uq.products.footprints import FrameProcessor
from footprint_uq.tracking import SharedJacobianAt, TrackerConfig, object_motion
from footprint_uq.tracking.camera_tracker import CameraTracker, FrameMotion
from footprint_uq.tracking.classes import ClassTracks
from footprint_uq.tracking.consistency import NisMonitor
from footprint_uq.tracking.contact_slide import ContactSlide

CAMERA = dict(focal_px=1400.0, image_size_px=(1920, 1080), height_m=8.0, pan_deg=30.0, tilt_deg=20.0)
BUDGET = "basler1@deg"
HEADING_OFFSET_DEG = 12.5
CLASSES = ("car", "pedestrian", None)


def _components(cam, at):
    """A camera's tracks (two motion models: pedestrians their own), slide term and NIS monitor, fresh."""
    base = TrackerConfig(timeout_s=0.25)
    tracks = ClassTracks(base, {"pedestrian": TrackerConfig(timeout_s=0.25, accel_psd_m2ps3=0.4,
                                                            manoeuvre_accel_psd_m2ps3=4.0)},
                         rank=at.rank, shared_at=at)
    return tracks, ContactSlide.for_camera(cam), NisMonitor(tracks, window_s=5.0, min_updates=5)


def _frames(cam, family: str, seed: int, count: int = 40, n: int = 14):
    """Seeded frames of ``n`` objects driving on the ground at 30 Hz: (time_s, ids, classes, columns, yaw): each
    object is missing from ~15 % of the frames, some for longer than the timeout (its track dies; the id starts
    again), a third of the objects get a new id every ~0.7 s (births); the class fixes the model."""
    rng = np.random.default_rng(seed)
    d = rng.uniform(15.0, 40.0, n)
    a = np.deg2rad(cam.pan_deg + rng.uniform(-18.0, 18.0, n))
    xy0 = np.column_stack([d * np.sin(a), d * np.cos(a)])
    course = rng.uniform(-np.pi, np.pi, n)
    v = rng.uniform(1.0, 9.0, n)[:, None] * np.column_stack([np.cos(course), np.sin(course)])
    cls = [CLASSES[k % 3] for k in range(n)]
    gone = rng.integers(0, count, n)  # a gap of 10 frames (> timeout) for each object, somewhere
    for f in range(count):
        t = 100.0 + f / 30.0
        keep = (rng.random(n) > 0.15) & ~((f >= gone) & (f < gone + 10))
        idx = np.flatnonzero(keep)
        ids = [int(k + 1000 * (f // 20) if k % 3 == 0 else k) for k in idx]  # births: new ids every 20 frames
        xy = xy0[idx] + v[idx] * (t - 100.0)
        if family == "3d":
            cols = np.column_stack([xy, np.zeros(len(idx)), np.full(len(idx), 4.2), np.full(len(idx), 1.8),
                                    np.full(len(idx), 1.5), course[idx]])
        else:
            uv = cam.project(np.column_stack([xy, np.zeros(len(idx))])).uv_px
            cols = np.column_stack([uv[:, 0] - 40.0, uv[:, 1] - 70.0, uv[:, 0] + 40.0, uv[:, 1]])
            cols += rng.normal(0.0, 0.5, cols.shape)
        yield t, ids, [cls[k] for k in idx], cols, (course[idx] if family == "3d" else None)


def _estimate(proc, family: str, cols, k: int):
    det = np.broadcast_to(np.eye(2) * 2.0, (cols.shape[0], 2, 2))
    est = proc.boxes3d(cols, pixel_cov_px2=det) if family == "3d" else proc.boxes2d(cols, pixel_cov_px2=det)
    xy, cov, B = est.centre_xy_world_m.copy(), est.centre_cov_m2.copy(), est.centre_shared_m.copy()
    if k % 7 == 3 and len(xy):  # an object without a centre this frame (its track waits)
        xy[0] = np.nan
    return xy, cov, B


def _equal(a, b):
    np.testing.assert_array_equal(np.asarray(a), np.asarray(b))  # (NaN == NaN here: the same calls, same bits)


@pytest.mark.parametrize("family", ["2d", "3d"])
def test_step_frame_is_the_sequence_of_calls(family):
    cam = PanTiltCamera(**CAMERA)
    proc = FrameProcessor(cam, BUDGET, joint_cov=False, linearity=False, v2x_policy="linear", shared_jacobian=True)
    at = SharedJacobianAt(cam, BUDGET)
    tracks, slide, nis = _components(cam, at)
    ref_tracks, ref_slide, ref_nis = _components(cam, at)
    tracker = CameraTracker(tracks, slide=slide, nis=nis, heading_offset_deg=HEADING_OFFSET_DEG)
    seen = {"new": 0, "untracked": 0, "velocity": 0, "nis": 0}
    for k, (t, ids, classes, cols, yaw) in enumerate(_frames(cam, family, seed=7 + (family == "3d"))):
        xy, cov, B = _estimate(proc, family, cols, k)
        got = tracker.step_frame(t, ids, classes, xy, cov, B, yaw_rad=yaw, contact_2d=family == "2d")
        # the sequence the service ran before the one call
        out = ref_tracks.step(t, ids, classes, xy, shared_m=B, cov_m2=cov)
        ref_nis.observe(t, out, classes)
        if family == "2d":
            out = ref_slide.apply(out, classes)
        motion = object_motion(out, heading_offset_deg=HEADING_OFFSET_DEG, yaw_rad=yaw)
        assert isinstance(got, FrameMotion)
        _equal(got.track_id, out.track_id)
        for a, b in zip(got.tracks, out, strict=True):
            _equal(a, b)
        for a, b in zip(got.motion, motion, strict=True):
            _equal(a, b)
        assert got.motion.age_s is got.tracks.age_s  # (the step's own ages: no copy)
        seen["new"] += int(got.tracks.new_track.sum())
        seen["untracked"] += int((got.track_id < 0).sum())
        seen["velocity"] += int(np.isfinite(got.motion.speed_mps).sum())
        seen["nis"] += int(np.isfinite(tracks.frame_nis()).sum())
    assert nis.status() == ref_nis.status()
    # the frames exercised what they are meant to: births and restarts, objects without a centre, both models
    assert seen["new"] > 20 and seen["untracked"] >= 5 and seen["velocity"] > 200 and seen["nis"] > 200
    assert all(len(t) > 0 for t in tracks.tables)
    assert {c for c in nis.status()} >= {"car", "pedestrian", ""}


def test_step_frame_slide_term_only_for_2d_boxes():
    """The slide term is in the 2-D boxes' velocity covariance (and in the tracks handed on), not in 3-D boxes'."""
    cam = PanTiltCamera(**CAMERA)
    proc = FrameProcessor(cam, BUDGET, joint_cov=False, linearity=False, v2x_policy="linear", shared_jacobian=True)
    at = SharedJacobianAt(cam, BUDGET)
    both = [CameraTracker(*_components(cam, at)[:1], slide=ContactSlide.for_camera(cam)) for _ in range(2)]
    for k, (t, ids, classes, cols, _) in enumerate(_frames(cam, "2d", seed=3, count=30)):
        xy, cov, B = _estimate(proc, "2d", cols, k + 1)
        with_term = both[0].step_frame(t, ids, classes, xy, cov, B, contact_2d=True)
        without = both[1].step_frame(t, ids, classes, xy, cov, B, contact_2d=False)
    v = np.isfinite(without.tracks.v_mps).all(1)
    assert v.sum() > 5
    extra = with_term.tracks.cov_v_m2ps2[v] - without.tracks.cov_v_m2ps2[v]
    assert np.all(extra[:, 0, 0] + extra[:, 1, 1] > 0.0)  # a second moment: positive where a velocity is known
    _equal(with_term.tracks.v_mps, without.tracks.v_mps)  # (the track's own state is not changed)


def test_fresh_and_missing_jacobian():
    """``fresh`` is an empty tracker of the same models and window; ``shared_m`` None: the tracks take B at their
    predicted positions and start nothing (a B of NaN)."""
    cam = PanTiltCamera(**CAMERA)
    tracker = CameraTracker.for_camera(cam, FrameProcessor(cam, BUDGET).budget, TrackerConfig(),
                                       window_s=7.0, heading_offset_deg=5.0)
    f = tracker.fresh()
    assert f.nis.window_s == 7.0 and f.heading_offset_deg == 5.0 and f.slide is tracker.slide
    assert f.tracks is not tracker.tracks and len(f.tracks.tables[0]) == 0
    got = f.step_frame(1.0, [1, 2], ["car", "car"], np.array([[1.0, 20.0], [3.0, 25.0]]),
                       np.broadcast_to(np.eye(2) * 0.1, (2, 2, 2)).copy())
    _equal(got.track_id, [-1, -1])
    assert np.isnan(got.motion.speed_mps).all()
