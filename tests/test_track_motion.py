"""tracking.motion.track_motion: a table's step and the motion fields of its output in one call.

It is :meth:`TrackTable.step` then :func:`object_motion` with the same arguments, to the bit, whichever way the
step goes: the one compiled call (``imm_kernels.frame_step`` forms the fields at its end), the dictionary's two
calls (a list with new ids), a burst of new ids beyond the free rows (the one call stops after the rows), a stale
frame (untracked), a table without ``B``'s kernel (the generic calls).  Bad motion arguments are refused before the
step, so the tracks are left as they were."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from footprint_uq.errors import InputError
from footprint_uq.tracking import TrackerConfig, TrackTable, object_motion, track_motion
from footprint_uq.tracking import table as table_module

_AT: list = []  # (one SharedJacobianAt for the module: its processor's set-up is the costly part)


def _at():
    if not _AT:
        from footprint_uq import PanTiltCamera
        from footprint_uq.tracking import SharedJacobianAt

        cam = PanTiltCamera(focal_px=1400.0, image_size_px=(1920, 1080), height_m=8.0, pan_deg=0.0, tilt_deg=20.0)
        _AT.append(SharedJacobianAt(cam, "basler1@deg"))
    return _AT[0]


def _bits(a):
    return np.ascontiguousarray(a, dtype=np.float64).view(np.int64)


def _frames(rng, count: int):
    """Frames of up to 12 objects in front of the camera: ids from a small pool (new ones, returns after a timeout,
    a repeated id), some None, NaN centres, a frame back in time, a burst of new ids, ids as int64 or a list."""
    t, last, pool = 0.0, 0.0, 10
    for f in range(count):
        last, t = t, t + float(rng.choice([0.033, 0.1, 0.8]))
        n = int(rng.integers(0, 13))
        ids = rng.integers(0, pool, n).tolist()
        xy = np.column_stack([rng.normal(0.0, 2.0, n) + 4.0 * np.array(ids) - 20.0, rng.uniform(20.0, 40.0, n)])
        xy[rng.random(n) < 0.1] = np.nan
        if f == 7:  # (a burst beyond the free rows: the one call stops after the rows)
            ids, xy = list(range(500, 580)), np.column_stack([np.linspace(-30, 30, 80), np.full(80, 30.0)])
            n = 80
        if rng.random() < 0.4:
            if rng.random() < 0.3 and n:
                ids[int(rng.integers(0, n))] = None
        else:
            ids = np.array(ids, np.int64)
        yield (last - 0.1 if f == 11 else t), ids, xy, n


@settings(max_examples=12, deadline=None)
@given(seed=st.integers(0, 2 ** 31 - 1), h=st.sampled_from([0.0, 12.5, -170.0]), with_yaw=st.booleans(),
       with_sigma=st.booleans(), ratio=st.sampled_from([3.0, 0.5]))
def test_track_motion_is_the_step_then_object_motion_to_the_bit(seed, h, with_yaw, with_sigma, ratio):
    at = _at()
    cfg = TrackerConfig(timeout_s=0.5)
    one, two = TrackTable(cfg, rank=at.rank, shared_at=at), TrackTable(cfg, rank=at.rank, shared_at=at)
    rng = np.random.default_rng(seed)
    for t, ids, xy, n in _frames(rng, 16):
        B = rng.normal(0.0, 0.05, (n, 2, at.rank))
        cov = np.repeat(np.eye(2)[None] * 0.04, n, 0) + B @ np.swapaxes(B, 1, 2)
        boxes = rng.uniform(-np.pi, np.pi, (n, 7))  # (the yaw a strided column, as a frame's boxes hand it)
        yaw = boxes[:, 6] if with_yaw else None
        sigma = rng.uniform(0.0, 0.2, n) if with_sigma else None
        opts = dict(heading_offset_deg=h, yaw_rad=yaw, sigma_yaw_rad=sigma, heading_min_ratio=ratio)
        got_tracks, got = track_motion(one, t, ids, xy, shared_m=B, cov_m2=cov, **opts)
        want_tracks = two.step(t, ids.copy() if isinstance(ids, np.ndarray) else list(ids), xy, shared_m=B,
                               cov_m2=cov)
        want = object_motion(want_tracks, **opts)
        for name, g, w in zip(want_tracks._fields, got_tracks, want_tracks, strict=True):
            assert np.array_equal(g, w, equal_nan=g.dtype.kind == "f"), (t, name)
        for name, g, w in zip(want._fields, got, want, strict=True):
            assert g.shape == w.shape and np.array_equal(_bits(g), _bits(w)), (t, name)
        assert got.age_s is got_tracks.age_s
    assert one.n_stale_frames == two.n_stale_frames == 1 and one._cap == two._cap > 64


def test_the_fields_come_from_the_steps_compiled_call(monkeypatch):
    """An int64 frame with room for its new ids forms the fields in ``frame_step`` (no ``motion_fields`` call
    from Python); a list with a new id among ids that are not all integers takes the table's two calls and one
    call of ``motion_fields`` after them; without ``B``'s kernel (the generic calls) too."""
    at = _at()
    table = TrackTable(TrackerConfig(), rank=at.rank, shared_at=at)
    B, cov = np.zeros((3, 2, at.rank)), np.repeat(np.eye(2)[None] * 0.04, 3, 0)
    xy = np.array([[0.0, 20.0], [2.0, 25.0], [-3.0, 30.0]])
    track_motion(table, 0.0, np.array([4, 5, 6]), xy, shared_m=B, cov_m2=cov)
    calls = []
    real = table_module.motion_fields
    monkeypatch.setattr(table_module, "motion_fields", lambda *a: calls.append(1) or real(*a))
    out, motion = track_motion(table, 0.1, np.array([4, 7, 6]), xy + [0.3, 0.0], shared_m=B, cov_m2=cov)
    assert calls == [] and out.new_track.tolist() == [False, True, False]
    assert np.isfinite(motion.speed_mps[[0, 2]]).all() and np.isnan(motion.speed_mps[1])
    xy2 = np.array([[-10.0, 35.0], [0.6, 20.0], [-2.4, 30.0]])  # (a new id "a", 4 and 6 where they were going)
    out, motion = track_motion(table, 0.2, ["a", 4, 6], xy2, shared_m=B, cov_m2=cov)
    assert calls == [1] and out.new_track.tolist() == [True, False, False]
    assert motion.speed_mps[1] == pytest.approx(3.0, rel=0.3)
    plain = TrackTable(TrackerConfig(), rank=at.rank)  # (no shared_at: the generic calls)
    track_motion(plain, 0.0, [1, 2, 3], xy, cov, B)
    assert calls == [1, 1]


@pytest.mark.parametrize("bad", [dict(yaw_rad=np.zeros(2)), dict(sigma_yaw_rad=np.zeros(4)),
                                 dict(heading_offset_deg=float("nan")), dict(heading_min_ratio=0.0),
                                 dict(heading_min_ratio=True)])
def test_bad_motion_arguments_are_named_before_the_step(bad):
    at = _at()
    table = TrackTable(TrackerConfig(), rank=at.rank, shared_at=at)
    B, cov = np.zeros((3, 2, at.rank)), np.repeat(np.eye(2)[None] * 0.04, 3, 0)
    xy = np.array([[0.0, 20.0], [2.0, 25.0], [-3.0, 30.0]])
    track_motion(table, 0.0, np.array([4, 5, 6]), xy, shared_m=B, cov_m2=cov)
    with pytest.raises(InputError) as err:
        track_motion(table, 0.1, np.array([4, 5, 6]), xy, shared_m=B, cov_m2=cov, **bad)
    assert next(iter(bad)) in str(err.value)
    assert len(table) == 3 and table._last_time == 0.0  # (the tracks as they were)


def test_read_only_and_listed_yaws_compile_nothing_new():
    """Yaws as a read-only array, a list or a strided column reach ``frame_step`` as the one signature it has (a
    read-only array would be a new specialisation, compiled mid-frame)."""
    from footprint_uq.tracking.imm_kernels import frame_step

    at = _at()
    table = TrackTable(TrackerConfig(), rank=at.rank, shared_at=at)
    B, cov = np.zeros((3, 2, at.rank)), np.repeat(np.eye(2)[None] * 0.04, 3, 0)
    xy = np.array([[0.0, 20.0], [2.0, 25.0], [-3.0, 30.0]])
    track_motion(table, 0.0, np.array([4, 5, 6]), xy, shared_m=B, cov_m2=cov, yaw_rad=np.zeros(3))
    known = len(frame_step.signatures)
    ro = np.array([0.1, 0.2, 0.3])
    ro.flags.writeable = False
    for k, yaw in enumerate((ro, [0.1, 0.2, 0.3], np.zeros((3, 4))[:, 1], np.arange(3))):
        _, motion = track_motion(table, 0.1 * (k + 1), np.array([4, 5, 6]), xy, shared_m=B, cov_m2=cov, yaw_rad=yaw,
                                 sigma_yaw_rad=ro)
        assert np.allclose(motion.sigma_yaw_deg, np.rad2deg(ro))
    assert len(frame_step.signatures) == known


def test_motion_arrays_of_another_size_are_refused_by_the_step():
    """TrackTable.step's ``motion`` arrays are written and read over the frame's n objects in compiled code: other
    sizes are named before anything runs (the tracks as they were)."""
    at = _at()
    table = TrackTable(TrackerConfig(), rank=at.rank, shared_at=at)
    B, cov = np.zeros((3, 2, at.rank)), np.repeat(np.eye(2)[None] * 0.04, 3, 0)
    xy = np.array([[0.0, 20.0], [2.0, 25.0], [-3.0, 30.0]])
    e = np.zeros(0)
    for bad in ((1.0, 0.0, 3.0, e, e, 0.0, np.empty((8, 2)), np.empty((3, 2, 2))),
                (1.0, 0.0, 3.0, e, e, 0.0, np.empty((8, 3)), np.empty((4, 2, 2))),
                (1.0, 0.0, 3.0, np.zeros(2), e, 0.0, np.empty((8, 3)), np.empty((3, 2, 2))),
                (1.0, 0.0, 3.0, e, e, 0.0, np.empty((8, 3)))):
        with pytest.raises(InputError, match="motion"):
            table.step(0.0, np.array([4, 5, 6]), xy, shared_m=B, cov_m2=cov, motion=bad)
    assert len(table) == 0 and table.n_stale_frames == 0
