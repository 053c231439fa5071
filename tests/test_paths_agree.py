"""Every path gives the reference's answer, including "no answer" (Hypothesis over whole domains).

Cameras: the paper's pan-tilt model and OpenCV cameras with strong barrel (past the lens fold
inside the image), pincushion, tangential and rational distortion, roll, tilt from nearly
horizontal to nearly straight down.  Pixels: over the whole image and 10 % beyond it.
Paths: :func:`propagate` (the numpy reference), :func:`covariance_points`,
:func:`covariance_map`, :class:`FrameProcessor` (corners, 2D boxes, 3D boxes against their
numpy reference) and the batch (:func:`process_table`).  The validity and the status code
must be the same exactly; where valid, the numbers to 1e-9 relative -- the linearity flag's
``nonlinearity`` too (plus 1e-12 absolute: a relative error of the axis far below anything the
flag resolves), with the same ``linear_ok`` and the same V2X fields where it is False.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pyarrow as pa
from hypothesis import HealthCheck, given, note, settings
from hypothesis import strategies as st

from footprint_uq import params as P
from footprint_uq import status
from footprint_uq.batch import process_table
from footprint_uq.cameras.distortion import distort
from footprint_uq.cameras.opencv import OpenCVCamera
from footprint_uq.cameras.pantilt import PanTiltCamera
from footprint_uq.cameras.rotation import R_W_C
from footprint_uq.products.covariance import covariance_map, covariance_points
from footprint_uq.products.footprints import FrameProcessor, footprints_from_boxes3d, footprints_from_corners
from footprint_uq.uncertainty.budget import load_budget
from footprint_uq.uncertainty.propagation import DEFAULT_LINEAR_THRESHOLD, propagate

RTOL = 1e-9
#: absolute floor of the flag's comparison (a nonlinearity of 1e-12 is 0 for every purpose)
NL_ATOL = 1e-12
W_PX, H_PX = 1280, 720

LENSES = {
    "none": lambda d: np.zeros(8),
    # folds inside the image: k1 = -0.33, k2 = 0.045 at f = 950 px folds 706 px from the centre
    "barrel": lambda d: np.array([d(st.floats(-0.45, -0.2)), d(st.floats(0.0, 0.08)), 0, 0,
                                  d(st.floats(-0.01, 0.01)), 0, 0, 0]),
    "pincushion": lambda d: np.array([d(st.floats(0.02, 0.3)), d(st.floats(-0.02, 0.05)), 0, 0, 0, 0, 0,
                                      0]),
    "tangential": lambda d: np.array([d(st.floats(-0.4, 0.1)), d(st.floats(-0.05, 0.08)),
                                      d(st.floats(-0.01, 0.01)), d(st.floats(-0.01, 0.01)),
                                      d(st.floats(-0.02, 0.02)), 0, 0, 0]),
    "rational": lambda d: np.array([d(st.floats(-0.35, 0.15)), d(st.floats(-0.1, 0.1)),
                                    d(st.floats(-5e-3, 5e-3)), d(st.floats(-5e-3, 5e-3)),
                                    d(st.floats(-0.02, 0.02)), d(st.floats(-0.1, 0.1)),
                                    d(st.floats(-0.05, 0.05)), d(st.floats(-0.02, 0.02))]),
}


@st.composite
def cameras(draw):
    f = draw(st.floats(400.0, 2500.0))
    tilt = draw(st.one_of(st.floats(0.05, 2.0), st.floats(2.0, 60.0), st.floats(85.0, 89.9)))
    pan = draw(st.floats(-180.0, 180.0))
    roll = draw(st.floats(-10.0, 10.0))
    h = draw(st.floats(3.0, 30.0))
    x0, y0 = draw(st.floats(-50, 50)), draw(st.floats(-50, 50))
    lens = draw(st.sampled_from(sorted(LENSES)))
    if lens == "none" and draw(st.booleans()):
        return PanTiltCamera(focal_px=f, image_size_px=(W_PX, H_PX), height_m=h, pan_deg=pan, tilt_deg=tilt,
                             roll_deg=roll, position_m=(x0, y0))
    dist = LENSES[lens](draw)
    cx = (W_PX - 1) / 2 + draw(st.floats(-20, 20))
    cy = (H_PX - 1) / 2 + draw(st.floats(-20, 20))
    K = np.array([[f, draw(st.floats(-2, 2)), cx], [0.0, f * draw(st.floats(0.98, 1.02)), cy], [0, 0, 1]])
    R = R_W_C(np.deg2rad(pan), np.deg2rad(tilt), np.deg2rad(roll)).T
    t = -R @ np.array([x0, y0, h])
    cam = OpenCVCamera(K, dist, R, t, (W_PX, H_PX))
    note(f"camera: K={K.tolist()!r} dist={dist.tolist()!r} pan/tilt/roll_deg={(pan, tilt, roll)!r} "
         f"position_m={(x0, y0, h)!r}")
    return cam


def _budget(draw_full: bool):
    b = load_budget("bw-cube1")
    if not draw_full:
        return b
    # a full budget: correlations between the intrinsics, distortion, position, angles and ground
    S = b.param_covariance()
    S[P.GDZ, P.GDZ], S[P.GSX, P.GSX], S[P.GSY, P.GSY] = 0.01, 1e-4, 1e-4
    used = np.flatnonzero(np.diag(S) > 0)
    d = np.sqrt(np.diag(S)[used])
    A = np.random.default_rng(7).normal(size=(used.size, used.size))
    C = A @ A.T
    C = C / np.sqrt(np.outer(np.diag(C), np.diag(C)))
    full = (0.5 * np.eye(used.size) + 0.5 * C) * np.outer(d, d)
    return dataclasses.replace(b, covariance_names=tuple(P.PARAM_NAMES[i] for i in used), covariance_matrix=full,
                               imaging_px=(0.3, 0.2))


def _pixels(draw, n=48):
    u = draw(st.lists(st.floats(-0.1 * W_PX, 1.1 * W_PX), min_size=n, max_size=n))
    v = draw(st.lists(st.floats(-0.1 * H_PX, 1.1 * H_PX), min_size=n, max_size=n))
    edge = [[-0.1 * W_PX, -0.1 * H_PX], [1.1 * W_PX, 1.1 * H_PX], [-0.1 * W_PX, 1.1 * H_PX], [W_PX / 2, H_PX - 1]]
    return np.concatenate([np.stack([u, v], -1), edge])


def _close(a, b, scale, rtol=RTOL):
    return np.all(np.abs(a - b) <= rtol * scale)


def _lens_rtol(cam, xy_world_m):
    """Per-point relative tolerance for paths that *project* world points first (3D boxes).

    Each path projects a box corner with its own arithmetic, so the pixels agree to a few ulp,
    not exactly.  Back-projection multiplies that difference by the condition number of the
    distortion Jacobian, the covariance (which holds the Jacobian's inverse twice) by its square.
    Near the lens fold the condition number reaches 10^3 and no two correct implementations can
    agree to 1e-9 there; the tolerance is 1e-9 plus 100 eps cond^2 -- 1e-9 for any lens the
    condition number of which stays below ~200.
    """
    xy = np.asarray(xy_world_m, dtype=float)
    if not isinstance(cam, OpenCVCamera) or not np.any(cam.params[P.DIST_SLICE]):
        return np.full(xy.shape[:-1], RTOL)
    X = np.concatenate([xy, np.full(xy.shape[:-1] + (1,), cam.ground_z_m)], -1)
    xc = X @ cam.R.T + cam.t
    _, J, _ = distort(xc[..., :2] / xc[..., 2:], cam.params[P.DIST_SLICE], get_gradients=True)
    cond = np.linalg.cond(J)
    return RTOL + 100.0 * np.finfo(float).eps * np.where(np.isfinite(cond), cond, 0.0) ** 2


def _assert_same(ref, xy, cov, reason, what, cam, uv=None):
    """``uv`` given: the path flags answers outside the image OUTSIDE_IMAGE (computed all the same)."""
    expected = ref.reason.copy()
    if uv is not None:
        expected[(expected == status.OK) & ~cam.in_image(uv)] = status.OUTSIDE_IMAGE
    np.testing.assert_array_equal(reason, expected, err_msg=f"{what}: status codes differ")
    ok = ref.reason == status.OK
    assert np.isnan(xy[~ok]).all() and np.isnan(cov[~ok]).all(), f"{what}: numbers where there is no answer"
    foot = cam.params[[P.XM, P.YM]]
    scale_xy = 1.0 + np.linalg.norm(ref.xy_world_m[ok] - foot, axis=-1)[:, None]
    assert _close(xy[ok], ref.xy_world_m[ok], scale_xy), f"{what}: positions differ"
    scale_c = np.abs(ref.cov_m2[ok]).max(axis=(-2, -1))[:, None, None]
    assert _close(cov[ok], ref.cov_m2[ok], scale_c), f"{what}: covariances differ"


def _assert_same_flag(ref_nl, nl, what, threshold=DEFAULT_LINEAR_THRESHOLD, rtol=RTOL):
    """The same nonlinearity (NaN where the reference has none) and the same linear_ok.

    ``rtol``: scalar or one per value (see :func:`_lens_rtol`).
    """
    ref_nl = np.asarray(ref_nl, dtype=float)
    nl = np.asarray(nl, dtype=float)
    np.testing.assert_array_equal(np.isnan(nl), np.isnan(ref_nl), err_msg=f"{what}: flag missing / extra")
    m = ~np.isnan(ref_nl)
    err = np.abs(nl[m] - ref_nl[m])
    rtol = np.broadcast_to(rtol, ref_nl.shape)[m]
    tol = rtol * np.abs(ref_nl[m]) + NL_ATOL
    assert np.all(err <= tol), f"{what}: nonlinearity differs by {np.max(err / tol):.3g} x the tolerance"
    at_edge = np.abs(ref_nl[m] - threshold) <= rtol * threshold  # (measure zero: a draw exactly at the threshold)
    np.testing.assert_array_equal((nl[m] <= threshold)[~at_edge], (ref_nl[m] <= threshold)[~at_edge],
                                  err_msg=f"{what}: linear_ok differs")


SETTINGS = settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])


@SETTINGS
@given(data=st.data())
def test_points_framewise_and_batch_agree_with_reference(data):
    cam = data.draw(cameras())
    budget = _budget(data.draw(st.booleans()))
    uv = _pixels(data.draw)
    ref = propagate(cam, budget, uv)
    xy, cov, _, reason, nl = covariance_points(cam, budget, uv, get_reason=True, get_nonlinearity=True)
    _assert_same(ref, xy, cov, reason, "covariance_points", cam)
    _assert_same_flag(ref.nonlinearity, nl, "covariance_points")
    est = FrameProcessor(cam, budget, allow_outside_image=True).corners(uv[:, None, :])
    _assert_same(ref, est.corners_xy_world_m[:, 0], est.corners_cov_m2[:, 0], est.corner_reason[:, 0],
                 "FrameProcessor.corners", cam, uv)
    _assert_same_flag(ref.nonlinearity, est.corners_nonlinearity[:, 0], "FrameProcessor.corners")
    # 2D boxes whose bottom-centre is the pixel
    boxes = np.stack([uv[:, 0] - 15, uv[:, 1] - 40, uv[:, 0] + 15, uv[:, 1]], -1)
    est = FrameProcessor(cam, budget, allow_outside_image=True).boxes2d(boxes)
    _assert_same(ref, est.corners_xy_world_m[:, 0], est.corners_cov_m2[:, 0], est.corner_reason[:, 0],
                 "FrameProcessor.boxes2d", cam, uv)
    _assert_same_flag(ref.nonlinearity, est.corners_nonlinearity[:, 0], "FrameProcessor.boxes2d")
    # one corner: the centre and the largest point are that corner, with its flag
    _assert_same_flag(ref.nonlinearity, est.centre_nonlinearity, "FrameProcessor.boxes2d centre")
    _assert_same_flag(ref.nonlinearity, est.largest_nonlinearity, "FrameProcessor.boxes2d largest point")
    # the batch, K = 1 corner per row, per-corner columns
    tab = process_table(cam, budget, pa.table({"u0_px": uv[:, 0], "v0_px": uv[:, 1]}), corners=True,
                        allow_outside_image=True)
    bxy = np.stack([tab.column("c0_x_m").to_numpy(), tab.column("c0_y_m").to_numpy()], -1)
    c01 = tab.column("c0_cov_xy_m2").to_numpy()
    bcov = np.stack([np.stack([tab.column("c0_cov_xx_m2").to_numpy(), c01], -1),
                     np.stack([c01, tab.column("c0_cov_yy_m2").to_numpy()], -1)], -2)
    _assert_same(ref, bxy, bcov, tab.column("c0_reason").to_numpy().astype(np.int8), "batch", cam, uv)
    _assert_same_flag(ref.nonlinearity, tab.column("c0_nonlinearity").to_numpy(), "batch c0_nonlinearity")
    _assert_same_flag(ref.nonlinearity, tab.column("nonlinearity").to_numpy(), "batch nonlinearity")
    np.testing.assert_array_equal(tab.column("linear_ok").to_numpy(zero_copy_only=False), ref.linear_ok)


@SETTINGS
@given(data=st.data())
def test_map_agrees_with_reference(data):
    cam = data.draw(cameras())
    budget = _budget(data.draw(st.booleans()))
    step = data.draw(st.integers(17, 61))
    xy, cov, valid, reason, nl = covariance_map(cam, budget, step, get_reason=True, get_nonlinearity=True)
    ref = propagate(cam, budget, cam.pixel_grid(step))
    np.testing.assert_array_equal(valid, ref.valid)
    _assert_same(ref, xy, cov, reason, "covariance_map", cam)
    _assert_same_flag(ref.nonlinearity, nl, "covariance_map")
    # the flag is an extra output of the same pass: the other outputs do not change
    xy0, cov0, valid0 = covariance_map(cam, budget, step)
    np.testing.assert_array_equal(valid0, valid)
    np.testing.assert_array_equal(cov0, cov)
    np.testing.assert_array_equal(xy0, xy)


@SETTINGS
@given(data=st.data())
def test_boxes3d_framewise_agrees_with_numpy_reference(data):
    cam = data.draw(cameras())
    budget = _budget(False)
    n = 24
    # boxes on the ground around the camera's foot, some behind it, some far
    foot = cam.params[[P.XM, P.YM]]
    r = np.array(data.draw(st.lists(st.floats(2.0, 150.0), min_size=n, max_size=n)))
    a = np.array(data.draw(st.lists(st.floats(-np.pi, np.pi), min_size=n, max_size=n)))
    yaw = np.array(data.draw(st.lists(st.floats(-np.pi, np.pi), min_size=n, max_size=n)))
    boxes = np.stack([foot[0] + r * np.cos(a), foot[1] + r * np.sin(a), np.full(n, 0.8), np.full(n, 4.5),
                      np.full(n, 1.9), np.full(n, 1.6), yaw], -1)
    ref = footprints_from_boxes3d(cam, budget, boxes, allow_outside_image=True)
    est = FrameProcessor(cam, budget, allow_outside_image=True).boxes3d(boxes)
    np.testing.assert_array_equal(est.corner_reason, ref.corner_reason)
    np.testing.assert_array_equal(est.centre_reason, ref.centre_reason)
    ok = ref.corner_reason == status.OK
    rt = _lens_rtol(cam, np.nan_to_num(ref.corners_xy_world_m))  # (n, 4): 1e-9 unless near the lens fold
    scale = 1.0 + np.abs(ref.corners_xy_world_m[ok] - foot).max(initial=0.0)
    assert _close(est.corners_xy_world_m[ok], ref.corners_xy_world_m[ok], scale, rt[ok][:, None])
    sc = np.abs(ref.corners_cov_m2[ok]).max(axis=(-2, -1))[:, None, None]
    assert _close(est.corners_cov_m2[ok], ref.corners_cov_m2[ok], sc, rt[ok][:, None, None])
    okc = ref.centre_valid
    rt_obj = np.where(ok, rt, RTOL).max(axis=1)  # an object's numbers come from its worst corner
    assert _close(est.centre_xy_world_m[okc], ref.centre_xy_world_m[okc], scale, rt_obj[okc][:, None])
    _assert_same_flag(ref.corners_nonlinearity, est.corners_nonlinearity, "boxes3d corners", rtol=rt)
    _assert_same_flag(ref.centre_nonlinearity, est.centre_nonlinearity, "boxes3d centre", rtol=rt_obj)
    _assert_same_flag(ref.largest_nonlinearity, est.largest_nonlinearity, "boxes3d largest point", rtol=rt_obj)
    np.testing.assert_array_equal(est.v2x_source, ref.v2x_source)
    np.testing.assert_array_equal(est.v2x_codes, ref.v2x_codes)


@SETTINGS
@given(data=st.data())
def test_framewise_flag_and_v2x_policy_agree_with_numpy_reference(data):
    """Objects from near the camera to the horizon (angles read in degrees: many centres are not
    linear_ok), every detector covariance form: the flag of every corner, largest point and centre, and
    the V2X fields the policy gives (sampled or unavailable) are the reference's."""
    cam = data.draw(cameras())
    budget = data.draw(st.sampled_from(["bw-cube1@deg", "basler1@deg", "basler1"]))
    n = 12
    u = np.array(data.draw(st.lists(st.floats(0.0, W_PX - 60.0), min_size=n, max_size=n)))
    v = np.array(data.draw(st.lists(st.floats(20.0, H_PX - 1.0), min_size=n, max_size=n)))
    uv = np.stack([u, v], -1)[:, None, :] + np.array([[0.0, 0.0], [50.0, 0.0], [50.0, -15.0], [0.0, -15.0]])
    form = data.draw(st.sampled_from(["none", "per-object", "per-corner", "full"]))
    pc = {"none": None, "per-object": np.tile(np.diag([0.8, 0.3]), (n, 1, 1)),
          "per-corner": np.tile(np.diag([0.5, 0.2]), (n, 4, 1, 1)),
          "full": np.tile(0.3 * np.eye(8) + 0.1, (n, 1, 1))}[form]
    opts = dict(allow_outside_image=True, v2x_samples=200, heading_offset_deg=data.draw(st.floats(-180.0, 180.0)))
    ref = footprints_from_corners(cam, budget, uv, pixel_cov_px2=pc, **opts)
    est = FrameProcessor(cam, budget, **opts).corners(uv, pixel_cov_px2=pc)
    np.testing.assert_array_equal(est.corner_reason, ref.corner_reason)
    np.testing.assert_array_equal(est.centre_reason, ref.centre_reason)
    _assert_same_flag(ref.corners_nonlinearity, est.corners_nonlinearity, "corners")
    _assert_same_flag(ref.centre_nonlinearity, est.centre_nonlinearity, "centre")
    _assert_same_flag(ref.largest_nonlinearity, est.largest_nonlinearity, "largest point")
    np.testing.assert_array_equal(est.centre_linear_ok, ref.centre_linear_ok)
    np.testing.assert_array_equal(est.v2x_source, ref.v2x_source)
    np.testing.assert_array_equal(est.v2x_codes, ref.v2x_codes)
    # the centre's flag is its worst corner's, the largest point's its corner's
    ok = ref.centre_valid
    np.testing.assert_array_equal(ref.centre_nonlinearity[ok], ref.corners_nonlinearity[ok].max(1))
    has = ref.largest_index >= 0
    np.testing.assert_array_equal(ref.largest_nonlinearity[has],
                                  ref.corners_nonlinearity[np.flatnonzero(has), ref.largest_index[has]])


def test_overflow_is_no_answer_in_every_pixel_path():
    """Finite inputs, infinite result (a camera 1e200 m up: the pixel-noise term overflows): OVERFLOW, NaN."""
    cam = PanTiltCamera(focal_px=1000.0, image_size_px=(W_PX, H_PX), height_m=10.0, pan_deg=20.0, tilt_deg=30.0)
    cam.params[P.HM] = 1e200
    budget = load_budget("bw-cube1")
    uv = cam.pixel_grid(40).reshape(-1, 2)
    ref = propagate(cam, budget, uv)
    assert (ref.reason == status.OVERFLOW).sum() > 100 and not ref.valid.any()
    assert np.isnan(ref.xy_world_m).all() and np.isnan(ref.cov_m2).all()
    xy, cov, valid, reason = covariance_points(cam, budget, uv, get_reason=True)
    _assert_same(ref, xy, cov, reason, "covariance_points", cam)
    xy, cov, valid, reason = covariance_map(cam, budget, 40, get_reason=True)
    _assert_same(ref, xy.reshape(-1, 2), cov.reshape(-1, 2, 2), reason.reshape(-1), "covariance_map", cam)
    # without the codes (the undistorted kernel then writes none) and with the flag: the same no-answer
    xy2, cov2, valid2, nl2 = covariance_map(cam, budget, 40, get_nonlinearity=True)
    np.testing.assert_array_equal(valid2, valid)
    assert np.isnan(xy2).all() and np.isnan(cov2).all() and np.isnan(nl2).all()
    for opencv in (False, True):
        if opencv:  # the general kernel too
            K = np.array([[1000.0, 0, 639.5], [0, 1000.0, 359.5], [0, 0, 1]])
            R = R_W_C(np.deg2rad(20.0), np.deg2rad(30.0), 0.0).T
            cam = OpenCVCamera(K, [-0.1, 0.01, 0, 0, 0], R, -R @ [0.0, 0.0, 10.0], (W_PX, H_PX))
            cam.params[P.HM] = 1e200
            ref = propagate(cam, budget, uv)
            xy, cov, valid, reason = covariance_map(cam, budget, 40, get_reason=True)
            _assert_same(ref, xy.reshape(-1, 2), cov.reshape(-1, 2, 2), reason.reshape(-1), "map (general)", cam)
            assert (ref.reason == status.OVERFLOW).sum() > 100


def test_overflow_framewise_agrees_with_numpy_reference():
    """The per-frame kernel and its numpy reference mark the same overflowed corners and centres."""
    cam = PanTiltCamera(focal_px=1000.0, image_size_px=(W_PX, H_PX), height_m=10.0, pan_deg=20.0, tilt_deg=30.0)
    uv = np.array([[[600.0, 500.0], [700.0, 500.0], [700.0, 600.0], [600.0, 600.0]],
                   [[600.0, 100.0], [700.0, 100.0], [700.0, 600.0], [600.0, 600.0]]])
    cam.params[P.HM] = 1e200
    ref = footprints_from_corners(cam, "bw-cube1", uv)
    est = FrameProcessor(cam, "bw-cube1").corners(uv)
    for e in (ref, est):
        assert (e.corner_reason[e.corner_reason != status.ABOVE_HORIZON] == status.OVERFLOW).all()
        assert not e.centre_valid.any() and not e.corner_usable.any()
        assert np.isnan(e.corners_xy_world_m).all() and np.isnan(e.centre_cov_m2).all()
        assert (e.largest_index == -1).all()
        assert (e.v2x["cpm_x_confidence"] == 4096).all()
    np.testing.assert_array_equal(est.corner_reason, ref.corner_reason)
    np.testing.assert_array_equal(est.centre_reason, ref.centre_reason)
    np.testing.assert_array_equal(est.centre_bad_corner, ref.centre_bad_corner)
    np.testing.assert_array_equal(est.v2x_codes, ref.v2x_codes)


def test_overflow_in_the_batch_lean_mode():
    """Without per-corner covariances (the batch's lean mode) overflowed rows are errors, never OK numbers."""
    from footprint_uq.batch import process_table

    cam = PanTiltCamera(focal_px=1000.0, image_size_px=(W_PX, H_PX), height_m=10.0, pan_deg=20.0, tilt_deg=30.0)
    cam.params[P.HM] = 1e200
    d = {"u_min_px": np.array([600.0, 100.0]), "v_min_px": np.array([500.0, 550.0]),
         "u_max_px": np.array([700.0, 300.0]), "v_max_px": np.array([600.0, 650.0])}
    with np.errstate(all="ignore"):
        t = process_table(cam, "bw-cube1", d)
    assert t.column("status").to_pylist() == ["error", "error"]
    for c in ("x_m", "y_m", "cov_xx_m2", "sigma_major_m"):
        assert np.isnan(t.column(c).to_numpy()).all(), c
    assert t.column("cpm_x_confidence").to_pylist() == [4096, 4096]
