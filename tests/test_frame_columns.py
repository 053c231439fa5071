"""The service's lean untracked frame (issue 31: the frame without the processor's Python).

* :meth:`footprint_uq.products.frame_processor.FrameProcessor.boxes2d_columns` (one compiled call:
  ``fast/frame_columns.py``) gives :meth:`~footprint_uq.products.frame_processor.FrameProcessor.boxes2d`'s numbers
  bit for bit (Hypothesis: boxes across the image, beyond it, above the horizon, degenerate; with and without a
  detector covariance; both contacts), and declines (None) exactly the frames it must leave to ``boxes2d``: a
  covariance the check refuses, a centre the V2X policy samples;
* :meth:`footprint_uq.service.Service._lean_frame` is the path an untracked compact frame takes (a spy, and a
  broken column that reaches the record), and a frame it declines is the general path's record, byte for byte
  (the general writers, ``Service._columnar = False``, are the reference: ``tests/test_service_columnar.py``).
"""

from __future__ import annotations

import numpy as np
import orjson
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from footprint_uq import FrameProcessor, PanTiltCamera
from footprint_uq.errors import InputError
from footprint_uq.fast import frame_columns as fc
from footprint_uq.products.footprint_estimate import centre_reason_texts
from footprint_uq.service import Service

T0 = 1714564800.0


@pytest.fixture(scope="module")
def camera():
    return PanTiltCamera(focal_px=1400, image_size_px=(1920, 1080), height_m=8.0, pan_deg=30.0, tilt_deg=20.0)


@pytest.fixture(scope="module")
def procs(camera):
    """The service's processor (policy "sampled") and one whose V2X policy is "linear" (declines nothing)."""
    return {p: FrameProcessor(camera, "basler1", joint_cov=False, v2x_policy=p) for p in ("sampled", "linear")}


def _boxes(rng, n: int) -> np.ndarray:
    u, v = rng.uniform(-300, 2200, n), rng.uniform(-100, 1300, n)
    w, h = rng.uniform(0, 200, n) * (rng.random(n) > 0.1), rng.uniform(0, 150, n) * (rng.random(n) > 0.1)
    return np.column_stack([u, v - h, u + w, v])


def _covariances(rng, n: int, kind: str) -> np.ndarray | None:
    if kind == "none":
        return None
    a, d = rng.uniform(0.5, 30.0, n), rng.uniform(0.5, 30.0, n)
    b = rng.uniform(-0.9, 0.9, n) * np.sqrt(a * d)
    return np.ascontiguousarray(np.stack([np.stack([a, b], -1), np.stack([b, d], -1)], -2))


def _same(cols, est) -> None:
    """The columns are the estimate's, bit for bit."""
    c, cov = est.centre_xy_world_m, est.centre_cov_m2
    want = np.array([c[:, 0], c[:, 1], cov[:, 0, 0], cov[:, 0, 1], cov[:, 1, 1]])
    for name, x, y in (("values", cols.values, want), ("v2x", cols.v2x_rows, est.v2x_codes.T),
                       ("largest_index", cols.largest_index, est.largest_index),
                       ("centre_reason", cols.centre_reason, est.centre_reason),
                       ("centre_bad_corner", cols.centre_bad_corner, est.centre_bad_corner)):
        assert x.shape == y.shape and x.dtype == y.dtype and x.tobytes() == np.ascontiguousarray(y).tobytes(), name
    assert cols.n_valid == int(est.centre_valid.sum()) and cols.n_corners == est.corners_px.shape[1]
    assert cols.v2x_rows.flags.c_contiguous and cols.values.flags.c_contiguous
    assert cols.object_rows.tobytes() == est.object_rows.tobytes()
    assert centre_reason_texts(cols.centre_reason, cols.centre_bad_corner, cols.n_corners).tolist() == \
        est.centre_reason_text().tolist()


@settings(max_examples=80, deadline=None)
@given(st.integers(0, 40), st.integers(0, 2 ** 32 - 1), st.sampled_from(["bottom-centre", "bottom-corners"]),
       st.sampled_from(["none", "random"]))
def test_columns_are_the_estimate(procs, n, seed, contact, cov_kind):
    rng = np.random.default_rng(seed)
    boxes = _boxes(rng, n)
    cov = _covariances(rng, n, cov_kind)
    for policy, proc in procs.items():
        est = proc.boxes2d(boxes, contact=contact, pixel_cov_px2=cov)
        cols = proc.boxes2d_columns(boxes, cov, contact=contact)
        flagged = bool(np.any(est.v2x_source != 0) & np.any(est.centre_valid & ~est.centre_linear_ok))
        if policy == "linear":
            assert cols is not None
        if cols is None:  # (declined: a valid centre whose V2X fields the policy samples or leaves unavailable)
            assert policy == "sampled" and flagged
            continue
        _same(cols, est)


def test_columns_decline_what_boxes2d_must_do(procs, camera):
    """A covariance the check refuses, and a valid centre that is not ``linear_ok`` under the sampling policy: None
    (``boxes2d`` names the covariance; its estimate carries the sampled V2X fields); the linear policy's columns
    of that frame are its estimate's."""
    proc = procs["sampled"]
    boxes = np.array([[900.0, 600.0, 1000.0, 700.0], [100.0, 800.0, 160.0, 860.0]])
    bad = np.array([[[4.0, 0.0], [0.0, 9.0]], [[1.0, 5.0], [5.0, 1.0]]])  # (the second: not PSD)
    assert proc.boxes2d_columns(boxes, bad) is None
    with pytest.raises(InputError, match=r"pixel_cov_px2\[1"):
        proc.boxes2d(boxes, pixel_cov_px2=bad)
    far = np.array([[900.0, 600.0, 1000.0, 700.0], [950.0, 21.0, 990.0, 31.0]])  # (the second near the horizon)
    est = proc.boxes2d(far)
    assert est.centre_valid.all() and not est.centre_linear_ok[1] and est.v2x_source[1] != 0
    assert proc.boxes2d_columns(far) is None
    _same(procs["linear"].boxes2d_columns(far), procs["linear"].boxes2d(far))


def test_settings_set_after_construction_reach_the_columns(camera):
    """The settings packed into ``boxes2d_columns``' constants (linearity, threshold, V2X policy, outside image)
    set again on a processor: its columns follow them, as ``boxes2d`` does (not the values packed at
    construction)."""
    far = np.array([[900.0, 600.0, 1000.0, 700.0], [950.0, 21.0, 990.0, 31.0], [-80.0, 500.0, -20.0, 560.0]])
    proc = FrameProcessor(camera, "basler1", joint_cov=False, v2x_policy="sampled")
    assert proc.boxes2d_columns(far) is None  # (a valid centre that is not linear_ok: sampled)
    proc.v2x_policy = "linear"
    _same(proc.boxes2d_columns(far), proc.boxes2d(far))
    for name, value in (("linear_threshold", 1e9), ("linearity", False), ("allow_outside_image", True)):
        setattr(proc, name, value)
        cols, est = proc.boxes2d_columns(far), proc.boxes2d(far)
        _same(cols, est)
    assert proc.boxes2d_columns(far).n_valid == 3  # (the third box outside the image: allowed now)


def test_columns_entry_checks(procs):
    proc = procs["linear"]
    with pytest.raises(InputError, match="contact"):
        proc.boxes2d_columns(np.zeros((1, 4)), contact="top")
    assert proc.boxes2d_columns(np.zeros((2, 4)), np.zeros((3, 2, 2))) is None  # (another shape: boxes2d's call)
    assert proc.boxes2d_columns(np.zeros((1, 4), np.float32)) is None
    boxes = np.array([[900.0, 600.0, 1000.0, 700.0], [100.0, 800.0, 160.0, 860.0]])
    cov = np.array([[[4.0, 1.0], [1.0, 9.0]], [[2.0, 0.0], [0.0, 3.0]]])
    want = proc.boxes2d_columns(boxes, cov)
    got = proc.boxes2d_columns(np.asfortranarray(boxes), np.asfortranarray(cov))  # (copied to row-major)
    assert all(a.tobytes() == b.tobytes() if isinstance(a, np.ndarray) else a == b  # (bits: a block holds int64 rows)
               for a, b in zip(want, got, strict=True))


def test_camera_parts_rebuild_the_camera(procs):
    cam = procs["linear"]._cam
    scalars, has_dist, dist, R, dom = fc.camera_parts(cam)
    assert scalars.tolist() == [getattr(cam, k) for k in fc.CAMERA_SCALARS] and has_dist == cam.has_dist
    assert dist is cam.dist and R is cam.R and dom is cam.dom
    assert set(fc.CAMERA_SCALARS) | {"dist", "has_dist", "R", "dom"} == set(cam._fields)


@pytest.mark.parametrize("kind", ["pantilt", "opencv"])
def test_packed_constants_are_the_processors(procs, random_opencv_camera, kind):
    """``columns_constants`` packs a processor's constants and settings into two arrays and ``unpack_constants``
    (the kernel's) gives them back: the same values, and the camera the same numba type as the processor's own
    (``process_corners`` is compiled once for both paths); a camera with distortion and a lens domain, and one
    with a heading offset, no linearity and the linear policy (every setting away from the other's)."""
    from numba import typeof

    from footprint_uq._checks import COV_PSD_RTOL

    if kind == "pantilt":
        proc = procs["sampled"]
    else:
        proc = FrameProcessor(random_opencv_camera(np.random.default_rng(3)), "basler1", joint_cov=False,
                              heading_offset_deg=31.0, linearity=False, v2x_policy="linear", allow_outside_image=True,
                              linear_threshold=0.07)
    assert proc._cam.dom.shape[0] > 0 and (kind == "pantilt" or proc._cam.has_dist)
    cam, dR, Lr, Lc, Lv, r, spx, no_det, allow_outside, ch, sh, flag, threshold, cov_tol, decline = \
        fc.unpack_constants(*proc._columns_consts)
    for name in proc._cam._fields:
        a, b = getattr(cam, name), getattr(proc._cam, name)
        assert np.array_equal(a, b) and np.asarray(a).dtype == np.asarray(b).dtype, name
    assert typeof(cam) == typeof(proc._cam)
    for a, b in ((dR, proc._dR), (Lr, proc._Lr), (Lc, proc._Lc), (Lv, proc._Lv), (spx, proc._spx),
                 (no_det, proc._no_det)):
        assert a.shape == b.shape and a.dtype == b.dtype and np.array_equal(a, b) and typeof(a) == typeof(b)
    assert (r, allow_outside, ch, sh, flag, threshold, cov_tol, decline) == (
        proc._r, proc.allow_outside_image, proc._ch, proc._sh, proc.linearity, proc.linear_threshold, COV_PSD_RTOL,
        proc.v2x_policy != "linear")
    with pytest.raises(ValueError, match="Lr"):
        fc.columns_constants(proc._cam, proc._dR, proc._Lr[:-1], proc._Lc, proc._Lv, proc._r, proc._spx,
                             allow_outside=False, ch=1.0, sh=0.0, flag=True, threshold=0.1, cov_tol=1e-9,
                             decline_flagged=True)


def _payload(rng, n: int, k: int, cov: bool = False) -> bytes:
    u, v, w = rng.uniform(50, 1800, n), rng.uniform(420, 1070, n), rng.uniform(20, 120, n)
    dets = [{"object_id": i, "class": "car" if i % 3 else "truck", "u_min_px": round(float(u[i]), 2),
             "v_min_px": round(float(v[i] - 0.8 * w[i]), 2), "u_max_px": round(float(u[i] + w[i]), 2),
             "v_max_px": round(float(v[i]), 2), **({"cov_uu_px2": 4.0, "cov_uv_px2": 1.0, "cov_vv_px2": 9.0}
                                                    if cov else {})} for i in range(n)]
    return orjson.dumps({"camera_id": "cam0", "frame": k, "timestamp_s": T0 + k / 30.0, "detections": dets})


def _record(out) -> bytes:
    return out.data[:out.data.rindex(b',"processing_us":')]


def test_the_lean_path_is_the_one_taken(camera, monkeypatch):
    """An untracked compact frame of 2-D boxes is written from the processor's columns, without an estimate: the
    general ``_footprints`` is not called, and a column broken in the processor's answer reaches the record."""
    svc = Service(camera, "basler1", record="compact")
    payload = _payload(np.random.default_rng(5), 30, 0)
    before = svc.process_frame_json(payload)
    monkeypatch.setattr(Service, "_footprints", lambda *a, **k: pytest.fail("the general path was taken"))
    assert _record(svc.process_frame_json(payload)) == _record(before)
    monkeypatch.undo()
    real = FrameProcessor.boxes2d_columns

    def shifted(self, *a, **k):  # (every centre 1 m east)
        cols = real(self, *a, **k)
        cols.values[0] += 1.0
        return cols

    monkeypatch.setattr(FrameProcessor, "boxes2d_columns", shifted)
    after = Service(camera, "basler1", record="compact").process_frame_json(payload)
    assert _record(after) != _record(before) and after.cpm_uper != before.cpm_uper


@pytest.mark.parametrize("case", ["bad-covariance", "flagged", "over-255", "no-centre"])
def test_declined_and_odd_frames_are_the_general_paths_bytes(camera, case, monkeypatch):
    """Frames the lean path declines (a covariance the kernel refuses: that detection's error entry; a centre the
    V2X policy samples) or writes with its less usual branches (> 255 objects, objects without a centre) are the
    general writers' record and CPM, byte for byte."""
    fast, ref = Service(camera, "basler1", record="compact"), Service(camera, "basler1", record="compact")
    ref._columnar = False
    taken = []
    real = FrameProcessor.boxes2d_columns
    monkeypatch.setattr(FrameProcessor, "boxes2d_columns", lambda self, *a, **k: taken.append(real(self, *a, **k))
                        or taken[-1])
    rng = np.random.default_rng(11)
    frame = orjson.loads(_payload(rng, 300 if case == "over-255" else 20, 0, cov=case == "bad-covariance"))
    dets = frame["detections"]
    if case == "bad-covariance":
        dets[3].update(cov_uu_px2=1.0, cov_uv_px2=5.0, cov_vv_px2=1.0)  # (in range, not PSD)
    if case == "flagged":
        dets[4].update(u_min_px=950.0, v_min_px=21.0, u_max_px=990.0, v_max_px=31.0)  # (near the horizon)
    if case == "no-centre":
        dets[2].update(v_min_px=5.0, v_max_px=20.0)  # (above the horizon, v ~ 30 px)
    for k in range(2):
        frame["frame"], frame["timestamp_s"] = k, T0 + k / 30.0
        a, b = fast.process_frame_json(orjson.dumps(frame)), ref.process_frame_json(orjson.dumps(frame))
        assert a.type == b.type == "footprints" and _record(a) == _record(b) and a.cpm_uper == b.cpm_uper
    # (the lean path declined the first two, wrote the others)
    assert taken and all((c is None) == (case in ("bad-covariance", "flagged")) for c in taken)
    rec = orjson.loads(a.data)
    if case == "bad-covariance":
        assert [e["index"] for e in rec["detection_errors"]] == [3]
    if case == "over-255":
        assert rec["objects_not_in_messages"] == 45
    if case == "no-centre":
        assert rec["objects"][2]["status"] == "error" and "reason" in rec["objects"][2]


# -- the tracked frame on the lean columns (wave 9 e) ------------------------------------------------------------


@pytest.fixture(scope="module")
def tracked_procs(camera):
    """The tracked service's processors (``shared_jacobian``: the tracker's input), both policies."""
    return {p: FrameProcessor(camera, "basler1", joint_cov=False, v2x_policy=p, shared_jacobian=True)
            for p in ("sampled", "linear")}


def _same_tracked(cols, est) -> None:
    """The tracker's inputs of the columns are the estimate's, bit for bit and with the same strides (the
    tracker reads the same arrays the same way)."""
    _same(cols._replace(values=cols.values[:5]), est)
    for name in ("centre_xy_world_m", "centre_cov_m2", "centre_shared_m"):
        x, y = getattr(cols, name), getattr(est, name)
        assert x.shape == y.shape and x.dtype == y.dtype and x.strides == y.strides, name
        assert x.tobytes() == y.tobytes(), name  # (NaN rows included: no centre, no Jacobian)


@settings(max_examples=60, deadline=None)
@given(st.integers(0, 40), st.integers(0, 2 ** 32 - 1), st.sampled_from(["bottom-centre", "bottom-corners"]),
       st.sampled_from(["none", "random"]), st.sampled_from([5, 10]))
def test_tracked_columns_are_the_estimate(tracked_procs, n, seed, contact, cov_kind, rows):
    rng = np.random.default_rng(seed)
    boxes = _boxes(rng, n)
    cov = _covariances(rng, n, cov_kind)
    for policy, proc in tracked_procs.items():
        est = proc.boxes2d(boxes, contact=contact, pixel_cov_px2=cov)
        cols = proc.boxes2d_columns(boxes, cov, contact=contact, value_rows=rows)
        if policy == "linear":
            assert cols is not None
        if cols is None:
            assert policy == "sampled"
            continue
        assert cols.values.shape == (rows, n)
        _same_tracked(cols, est)


def test_untracked_columns_carry_no_jacobian(procs):
    cols = procs["linear"].boxes2d_columns(np.array([[900.0, 600.0, 1000.0, 700.0]]))
    assert cols.centre_shared_m is None and cols.centre_xy_world_m is None and cols.centre_cov_m2 is None
    assert cols.values.shape == (5, 1) and cols.object_rows.shape[1] == 1


def _tracked_payloads(n: int, frames: int, cov: bool = False) -> list:
    rng = np.random.default_rng(7)
    u, v, w = rng.uniform(50, 1800, n), rng.uniform(420, 1070, n), rng.uniform(20, 120, n)
    du, dv = rng.uniform(-15, 15, n), rng.uniform(-5, 5, n)
    out = []
    for k in range(frames):
        uk, vk = u + k * du, v + k * dv
        dets = [{"object_id": i, "class": "car" if i % 3 else "truck", "u_min_px": round(float(uk[i]), 2),
                 "v_min_px": round(float(vk[i] - 0.8 * w[i]), 2), "u_max_px": round(float(uk[i] + w[i]), 2),
                 "v_max_px": round(float(vk[i]), 2),
                 **({"cov_uu_px2": 4.0, "cov_uv_px2": 1.0, "cov_vv_px2": 9.0} if cov else {})}
                for i in range(n) if not (k == 2 and i % 5 == 1)]  # (a fifth missed in frame 2)
        out.append({"camera_id": "cam0", "frame": k, "timestamp_s": T0 + k / 10.0, "detections": dets})
    return out


def _tracks_state(svc) -> bytes:
    """The camera's tracks after the frames (ids, states, covariances), as bytes."""
    (setup,) = svc.cameras.values()
    t = setup.last_tracks
    return b"".join(np.ascontiguousarray(getattr(t, f)).tobytes() for f in t._fields
                    if isinstance(getattr(t, f), np.ndarray))


def test_the_lean_tracked_path_is_the_one_taken(camera, monkeypatch):
    """A tracked compact frame of 2-D boxes is written from the processor's columns and tracked on them, without
    an estimate: neither ``_footprints`` nor ``boxes2d`` is called, the record, CPM and tracks are the general
    path's; and a Jacobian column broken in the processor's answer reaches the tracks (the tracker reads it)."""
    frames = [orjson.dumps(f) for f in _tracked_payloads(30, 4)]
    ref = Service(camera, "basler1", record="compact", tracks=True)
    ref._columnar = False
    want = [ref.process_frame_json(f) for f in frames]
    svc = Service(camera, "basler1", record="compact", tracks=True)
    monkeypatch.setattr(Service, "_footprints", lambda *a, **k: pytest.fail("the general path was taken"))
    monkeypatch.setattr(FrameProcessor, "boxes2d", lambda *a, **k: pytest.fail("an estimate was formed"))
    got = [svc.process_frame_json(f) for f in frames]
    for a, b in zip(got, want, strict=True):
        assert _record(a) == _record(b) and a.cpm_uper == b.cpm_uper and b'"v_east_mps":' in a.data
    assert _tracks_state(svc) == _tracks_state(ref)
    monkeypatch.undo()
    real = FrameProcessor.boxes2d_columns

    def scaled(self, *a, **k):  # (the calibration share of every centre halved: the tracks then differ)
        cols = real(self, *a, **k)
        cols.centre_shared_m[...] *= 0.5
        return cols

    monkeypatch.setattr(FrameProcessor, "boxes2d_columns", scaled)
    broken = Service(camera, "basler1", record="compact", tracks=True)
    bad = [broken.process_frame_json(f) for f in frames]
    assert _record(bad[-1]) != _record(want[-1]) and _tracks_state(broken) != _tracks_state(ref)


def test_the_lean_tracked_path_hands_the_tracks_int64_ids(camera):
    """A one-class tracked frame of integer ids steps its tracks with the ids as an int64 array (the table's
    compiled id look-up, ``tracking/kernels.py`` ``id_lookup``), the general path with a list (the dictionary's
    look-up, forced: a list of integers would be made int64 ids too):
    the same records, CPM and tracks, a missed object and the births of every frame included."""
    payloads = _tracked_payloads(30, 4)
    for f in payloads:
        for d in f["detections"]:
            d["class"] = "car"
    frames = [orjson.dumps(f) for f in payloads]
    ref = Service(camera, "basler1", record="compact", tracks=True)
    ref._columnar = False
    for t in next(iter(ref.cameras.values())).tracker.tracks.tables:  # (a list of integers: made int64 ids unless)
        t._int_ids = False
    want = [ref.process_frame_json(f) for f in frames]
    svc = Service(camera, "basler1", record="compact", tracks=True)
    got = [svc.process_frame_json(f) for f in frames]
    for a, b in zip(got, want, strict=True):
        assert _record(a) == _record(b) and a.cpm_uper == b.cpm_uper
    assert _tracks_state(svc) == _tracks_state(ref)
    (table,) = next(iter(svc.cameras.values())).tracker.tracks.tables
    (ref_table,) = next(iter(ref.cameras.values())).tracker.tracks.tables
    assert table._ids is not None and ref_table._ids is None  # (the compiled look-up; the reference's dictionary)


@pytest.mark.parametrize("case", ["bad-covariance", "flagged", "over-255", "cpm-declined", "on-tracked"])
def test_tracked_declined_frames_are_the_general_paths(camera, case, monkeypatch):
    """Tracked frames the lean path declines before the tracker's step (a covariance the kernel refuses, a centre
    the V2X policy samples), after it (the CPM writer declines: the general writers finish the frame, the tracks
    stepped once), the > 255 objects' branch, and a service whose ``on_tracked`` takes the estimate (the general
    path): the general path's record, CPM and tracks, frame after frame."""
    from footprint_uq.service import core

    frames = _tracked_payloads(300 if case == "over-255" else 20, 4, cov=case == "bad-covariance")
    for f in frames:
        if case == "bad-covariance":
            f["detections"][3].update(cov_uu_px2=1.0, cov_uv_px2=5.0, cov_vv_px2=1.0)  # (in range, not PSD)
        if case == "flagged":
            f["detections"][4].update(u_min_px=950.0, v_min_px=21.0, u_max_px=990.0, v_max_px=31.0)
    fast = Service(camera, "basler1", record="compact", tracks=True)
    ref = Service(camera, "basler1", record="compact", tracks=True)
    ref._columnar = False
    estimates = []
    if case == "on-tracked":
        fast.on_tracked = lambda cid, fno, ts, tracks, est, found: estimates.append(est)
    lean = []
    real_records = Service._lean_records
    monkeypatch.setattr(Service, "_lean_records", lambda *a, **k: lean.append(1) or real_records(*a, **k))
    if case == "cpm-declined":
        monkeypatch.setattr(core, "lean_cpm_uper", lambda *a, **k: None)
        monkeypatch.setattr(core, "plain_cpm_uper", lambda *a, **k: None)
    for f in frames:
        a, b = fast.process_frame_json(orjson.dumps(f)), ref.process_frame_json(orjson.dumps(f))
        assert a.type == b.type == "footprints" and _record(a) == _record(b) and a.cpm_uper == b.cpm_uper
    assert _tracks_state(fast) == _tracks_state(ref)
    assert bool(lean) == (case in ("over-255", "cpm-declined"))
    assert len(estimates) == (len(frames) if case == "on-tracked" else 0)
    rec = orjson.loads(a.data)
    if case == "bad-covariance":
        assert [e["index"] for e in rec["detection_errors"]] == [3]
    if case == "over-255":
        assert rec["objects_not_in_messages"] == 45
