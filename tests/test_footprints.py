"""Object footprints: the centre (vertex mean) and the area centroid with their Jacobians, corner/joint/centre
covariances, partial visibility."""

from __future__ import annotations

import numpy as np
import pytest

from footprint_uq import ErrorBudget, InputError, PanTiltCamera, propagate, propagate_joint, status
from footprint_uq import params as P
from footprint_uq.products.footprints import (
    DEGENERATE,
    box2d_contact_points,
    box3d_bottom_corners,
    footprint_centre,
    footprints_from_boxes2d,
    footprints_from_boxes3d,
    footprints_from_corners,
    polygon_centroid,
)
from footprint_uq.uncertainty.ellipse import ellipse_axes

BUDGET = ErrorBudget.preset("basler1")


@pytest.fixture
def cam():
    return PanTiltCamera(1400.0, (1920, 1080), 8.0, 30.0, 15.0, position_m=(2.0, -3.0))


def visible_boxes(camera, rng, n, *, v_range=(600, 1000), u_range=(300, 1600)):
    """n 3D car-sized boxes whose centres project inside the lower part of the image."""
    uv = np.column_stack([rng.uniform(*u_range, n), rng.uniform(*v_range, n)])
    xy = camera.backproject(uv).xy_world_m
    return np.column_stack([xy, np.full(n, 0.75), rng.uniform(3.5, 5.0, n), rng.uniform(1.6, 2.0, n),
                            np.full(n, 1.5), rng.uniform(-np.pi, np.pi, n)])


# -- centroid ---------------------------------------------------------------------------------------
def test_centroid_pinned_values():
    sq = np.array([[0.0, 0.0], [2.0, 0.0], [2.0, 2.0], [0.0, 2.0]])
    C, A = polygon_centroid(sq)
    assert np.allclose(C, [1.0, 1.0]) and A == pytest.approx(4.0)
    # trapezoid (0,0) (4,0) (3,2) (1,2): area 6, centroid x 2, y = h (b + 2a) / (3 (a + b)) = 2*(4+4)/(3*6)
    tr = np.array([[0.0, 0.0], [4.0, 0.0], [3.0, 2.0], [1.0, 2.0]])
    C, A = polygon_centroid(tr)
    assert A == pytest.approx(6.0)
    assert np.allclose(C, [2.0, 8.0 / 9.0], rtol=1e-14)
    assert not np.allclose(C, tr.mean(0))  # the vertex mean (2, 1) is not the area centroid
    # clockwise order: same centroid, negative area
    C2, A2 = polygon_centroid(tr[::-1])
    assert np.allclose(C2, C) and A2 == pytest.approx(-6.0)
    # K = 1, 2: the point, the midpoint
    assert np.allclose(polygon_centroid(tr[:1])[0], [0.0, 0.0])
    assert np.allclose(polygon_centroid(tr[:2])[0], [2.0, 0.0])


def test_centroid_far_from_origin_is_accurate():
    tr = np.array([[0.0, 0.0], [4.0, 0.0], [3.0, 2.0], [1.0, 2.0]])
    off = np.array([6.4e5, 5.3e6])  # UTM-like magnitudes
    C, _ = polygon_centroid(tr + off)
    assert np.allclose(C - off, [2.0, 8.0 / 9.0], atol=1e-9)


def test_centroid_degenerate_is_nan():
    line = np.array([[0.0, 0.0], [1.0, 1.0], [2.0, 2.0], [3.0, 3.0]])
    C, A, G = polygon_centroid(line, get_gradients=True)
    assert np.all(np.isnan(C)) and A == 0.0


def test_footprint_centre_pinned_values():
    """The reported centre is the vertex mean (K = 2 the midpoint, K = 1 the point), with the shoelace area;
    zero area (K >= 3) has no centre; far from the origin it stays exact."""
    tr = np.array([[0.0, 0.0], [4.0, 0.0], [3.0, 2.0], [1.0, 2.0]])
    C, A = footprint_centre(tr)
    assert np.allclose(C, [2.0, 1.0], rtol=1e-15) and A == pytest.approx(6.0)  # area centroid: (2, 8/9)
    C2, A2 = footprint_centre(tr[::-1])
    assert np.allclose(C2, C) and A2 == pytest.approx(-6.0)
    assert np.allclose(footprint_centre(tr[:1])[0], [0.0, 0.0]) and footprint_centre(tr[:2])[1] == 0.0
    assert np.allclose(footprint_centre(tr[:2])[0], [2.0, 0.0])
    off = np.array([6.4e5, 5.3e6])
    assert np.allclose(footprint_centre(tr + off)[0] - off, [2.0, 1.0], atol=1e-9)
    line = np.array([[0.0, 0.0], [1.0, 1.0], [2.0, 2.0], [3.0, 3.0]])
    C, A, G = footprint_centre(line, get_gradients=True)
    assert np.all(np.isnan(C)) and A == 0.0 and np.isfinite(G).all()
    # a parallelogram (every box's footprint): the same point as the area centroid
    par = np.array([[0.0, 0.0], [4.0, 1.0], [5.0, 3.0], [1.0, 2.0]])
    assert np.allclose(footprint_centre(par)[0], polygon_centroid(par)[0], rtol=1e-14)


@pytest.mark.parametrize("K", [1, 2, 3, 4, 6])
def test_footprint_centre_jacobian_vs_central_differences(K, rng, central_diff, rel_err):
    pts = rng.uniform(-50, 50, (7, K, 2))
    C, _, G = footprint_centre(pts, get_gradients=True)
    for i in range(7):
        fd = central_diff(lambda v: footprint_centre(v.reshape(K, 2))[0], pts[i].ravel(), np.full(2 * K, 1e-3))
        assert rel_err(fd, G[i]) < 1e-9


@pytest.mark.parametrize("K", [1, 2, 3, 4, 6])
def test_centroid_jacobian_vs_central_differences(K, rng, central_diff, rel_err):
    worst = 0.0
    for _ in range(20):
        ang = np.sort(rng.uniform(0, 2 * np.pi, K))  # convex polygon in order
        r = rng.uniform(1.0, 3.0, K)
        pts = np.column_stack([r * np.cos(ang), r * np.sin(ang)]) + rng.uniform(-50, 50, 2)
        C, _, G = polygon_centroid(pts, get_gradients=True)
        fd = central_diff(lambda v: polygon_centroid(v.reshape(K, 2))[0], pts.ravel(), np.full(2 * K, 1e-5))
        worst = max(worst, rel_err(fd, G))
    assert worst < 1e-7


# -- geometry of the inputs ------------------------------------------------------------------------
def test_box3d_corners_pinned_and_units():
    b = np.array([[10.0, 20.0, 0.75, 4.0, 2.0, 1.5, np.pi / 2]])
    c = box3d_bottom_corners(b)
    # yaw 90 deg: length along +y; rear-right corner (-l/2, -w/2) -> (10 + 1, 20 - 2)
    assert np.allclose(c[0, :, :2], [[11.0, 18.0], [11.0, 22.0], [9.0, 22.0], [9.0, 18.0]])
    assert np.allclose(c[0, :, 2], 0.0)
    bd = b.copy()
    bd[0, 6] = 90.0
    assert np.allclose(box3d_bottom_corners(bd, yaw_unit="deg"), c)
    raised = box3d_bottom_corners(b, bottom_on_ground=False)
    assert np.allclose(raised[0, :, 2], 0.0)  # z 0.75 - 1.5 / 2
    assert polygon_centroid(c[0, :, :2])[1] > 0  # counter-clockwise


def test_box2d_contact_points():
    b = np.array([[100.0, 200.0, 300.0, 500.0]])
    c1, A1 = box2d_contact_points(b, "bottom-centre")
    c2, A2 = box2d_contact_points(b, "bottom-corners")
    assert np.allclose(c1, [[[200.0, 500.0]]])
    assert np.allclose(c2, [[[100.0, 500.0], [300.0, 500.0]]])
    assert np.allclose((b @ A2.T).reshape(1, 2, 2), c2)


def test_box3d_round_trip_recovers_footprint(cam, rng):
    boxes = visible_boxes(cam, rng, 30)
    est = footprints_from_boxes3d(cam, BUDGET, boxes, allow_outside_image=True)
    truth = box3d_bottom_corners(boxes)[..., :2]
    ok = est.corner_reason != status.BEHIND_CAMERA
    assert ok.all()
    assert np.allclose(est.corners_xy_world_m, truth, atol=1e-8)
    assert np.allclose(est.centre_xy_world_m, boxes[:, :2], atol=1e-8)  # rectangle: vertex mean = centre


# -- covariances -----------------------------------------------------------------------------------
def test_corner_and_joint_covariances_match_propagation(cam, rng):
    boxes = visible_boxes(cam, rng, 10)
    est = footprints_from_boxes3d(cam, BUDGET, boxes, allow_outside_image=True)
    jt = propagate_joint(cam, BUDGET, est.corners_px)
    assert np.allclose(est.joint_cov_m2, jt.cov_m2, rtol=1e-12, atol=1e-15)
    pt = propagate(cam, BUDGET, est.corners_px)
    assert np.allclose(est.corners_cov_m2, pt.cov_m2, rtol=1e-12, atol=1e-15)
    # corners share the calibration error: strongly correlated
    c = est.joint_cov_m2[0]
    corr = c[1, 3] / np.sqrt(c[1, 1] * c[3, 3])
    assert corr > 0.5


def test_largest_point_is_the_largest_corner(cam, rng):
    boxes = visible_boxes(cam, rng, 20)
    est = footprints_from_boxes3d(cam, BUDGET, boxes, allow_outside_image=True)
    a, _, _ = ellipse_axes(est.corners_cov_m2)
    assert np.allclose(est.largest_semi_major_m, a.max(1), rtol=1e-12)
    assert np.array_equal(est.largest_index, a.argmax(1))
    assert np.allclose(est.largest_cov_m2, est.corners_cov_m2[np.arange(20), est.largest_index])
    # the paper's upper bound: the centre is never less certain than the largest corner here
    assert np.all(ellipse_axes(est.centre_cov_m2)[0] <= est.largest_semi_major_m * (1 + 1e-12))


def test_centre_covariance_is_jacobian_sandwich(cam, rng):
    boxes = visible_boxes(cam, rng, 5)
    est = footprints_from_boxes3d(cam, BUDGET, boxes, allow_outside_image=True)
    _, _, G = footprint_centre(est.corners_xy_world_m, get_gradients=True)
    want = G @ est.joint_cov_m2 @ np.swapaxes(G, -1, -2)
    assert np.allclose(est.centre_cov_m2, want, rtol=1e-12)


def _mc_centroid(camera, budget, corners_px, n, seed, det_chol=None):
    """Seeded Monte Carlo on the full model: shared parameters per sample, independent pixel noise per corner."""
    rng = np.random.default_rng(seed)
    Sp = budget.param_covariance()
    w, V = np.linalg.eigh(Sp)
    A = V * np.sqrt(np.clip(w, 0, None))
    dp = rng.standard_normal((n, P.N_PARAMS)) @ A.T
    K = corners_px.shape[0]
    s = np.sqrt(np.diag(budget.pixel_covariance()))
    noise = rng.standard_normal((n, K, 2)) * s
    if det_chol is not None:  # (2K, 2K) correlated detector noise
        noise = noise + (rng.standard_normal((n, 2 * K)) @ det_chol.T).reshape(n, K, 2)
    bp = camera.backproject_with(camera.params + dp[:, None, :], corners_px + noise)
    assert bp.valid.all()
    C, _ = footprint_centre(bp.xy_world_m)
    return np.cov(C.T)


@pytest.mark.parametrize("model", ["pantilt", "opencv"])
def test_centre_covariance_vs_monte_carlo(model, rng, random_opencv_camera):
    if model == "pantilt":
        camera = PanTiltCamera(1400.0, (1920, 1080), 8.0, 30.0, 15.0)
        budget = BUDGET
    else:
        camera = random_opencv_camera(np.random.default_rng(7), distortion="mild")
        budget = BUDGET.replace(pan_deg=0.05, tilt_deg=0.05, roll_deg=0.05)
    boxes = visible_boxes(camera, rng, 3, v_range=(700, 950), u_range=(600, 1300))
    est = footprints_from_boxes3d(camera, budget, boxes, allow_outside_image=True)
    assert est.centre_valid.all()
    for i in range(3):
        mc = _mc_centroid(camera, budget, est.corners_px[i], 20000, seed=11 + i)
        lin = est.centre_cov_m2[i]
        # 20000 samples: variance standard error ~1 %; allow 6 % on the ellipse axes
        a_lin, b_lin, _ = ellipse_axes(lin)
        a_mc, b_mc, _ = ellipse_axes(mc)
        assert a_lin == pytest.approx(a_mc, rel=0.06)
        assert b_lin == pytest.approx(b_mc, rel=0.06)
        assert np.abs(lin - mc).max() < 0.06 * a_mc**2


def test_detector_covariance_forms_agree_and_add(cam, rng):
    boxes = visible_boxes(cam, rng, 4)
    base = footprints_from_boxes3d(cam, BUDGET, boxes, allow_outside_image=True)
    S = np.array([[4.0, 1.0], [1.0, 2.0]])
    per_det = np.broadcast_to(S, (4, 2, 2))
    per_corner = np.broadcast_to(S, (4, 4, 2, 2))
    full = np.broadcast_to(np.kron(np.eye(4), S), (4, 8, 8))
    e1 = footprints_from_boxes3d(cam, BUDGET, boxes, pixel_cov_px2=per_det, allow_outside_image=True)
    e2 = footprints_from_boxes3d(cam, BUDGET, boxes, pixel_cov_px2=per_corner, allow_outside_image=True)
    e3 = footprints_from_boxes3d(cam, BUDGET, boxes, pixel_cov_px2=full, allow_outside_image=True)
    for e in (e2, e3):
        assert np.allclose(e.joint_cov_m2, e1.joint_cov_m2, rtol=1e-12)
    Juv = cam.backproject(base.corners_px, get_gradients=True).dxy_duv
    extra = Juv @ S @ np.swapaxes(Juv, -1, -2)
    assert np.allclose(e1.corners_cov_m2 - base.corners_cov_m2, extra, rtol=1e-9, atol=1e-15)
    assert np.all(ellipse_axes(e1.centre_cov_m2)[0] > ellipse_axes(base.centre_cov_m2)[0])


def test_box_covariance_couples_bottom_corners(cam):
    box = np.array([[800.0, 500.0, 1000.0, 800.0]])
    sig = np.array([[2.0, 2.0, 3.0, 5.0]])  # v_max sigma 5 px
    est = footprints_from_boxes2d(cam, BUDGET, box, contact="bottom-corners", box_cov_px2=sig)
    base = footprints_from_boxes2d(cam, BUDGET, box, contact="bottom-corners")
    bp = cam.backproject(est.corners_px, get_gradients=True)
    J0, J1 = bp.dxy_duv[0, 0], bp.dxy_duv[0, 1]
    # corner 0 = (u_min, v_max), corner 1 = (u_max, v_max): shared v_max variance 25 px^2
    cross = J0 @ np.array([[0.0, 0.0], [0.0, 25.0]]) @ J1.T
    d = est.joint_cov_m2[0] - base.joint_cov_m2[0]
    assert np.allclose(d[0:2, 2:4], cross, rtol=1e-9)
    assert np.allclose(d[0:2, 0:2], J0 @ np.diag([4.0, 25.0]) @ J0.T, rtol=1e-9)
    # the centre of two corners is their midpoint
    assert np.allclose(est.centre_xy_world_m, est.corners_xy_world_m.mean(1))
    # Monte Carlo with the correlated box noise
    A = np.array([[1.0, 0, 0, 0], [0, 0, 0, 1.0], [0, 0, 1.0, 0], [0, 0, 0, 1.0]])
    L = A @ np.diag(sig[0])
    mc = _mc_centroid(cam, BUDGET, est.corners_px[0], 20000, seed=3, det_chol=L)
    assert ellipse_axes(est.centre_cov_m2[0])[0] == pytest.approx(ellipse_axes(mc)[0], rel=0.05)


def test_bottom_centre_is_single_point(cam):
    box = np.array([[800.0, 500.0, 1000.0, 800.0], [100.0, 400.0, 300.0, 700.0]])
    est = footprints_from_boxes2d(cam, BUDGET, box, contact="bottom-centre")
    pt = propagate(cam, BUDGET, np.array([[900.0, 800.0], [200.0, 700.0]]))
    assert est.n_corners == 1
    assert np.allclose(est.centre_xy_world_m, pt.xy_world_m)
    assert np.allclose(est.centre_cov_m2, pt.cov_m2, rtol=1e-12)
    assert np.allclose(est.largest_semi_major_m, ellipse_axes(pt.cov_m2)[0])
    assert np.all(est.area_m2 == 0.0)


# -- partial visibility -----------------------------------------------------------------------------
def test_partial_visibility_flags_and_keeps_what_can_be_computed(cam):
    hv = float(cam.horizon_v_px(960.0))
    corners = np.array([
        [[900.0, 900.0], [1000.0, 900.0], [1000.0, 800.0], [900.0, 800.0]],  # all fine
        [[900.0, 900.0], [1000.0, 900.0], [1000.0, hv - 50.0], [900.0, 800.0]],  # corner 2 above horizon
        [[-40.0, 900.0], [100.0, 900.0], [100.0, 800.0], [-40.0, 800.0]],  # corners 0, 3 outside the image
        [[np.nan, 900.0], [100.0, 900.0], [100.0, 800.0], [50.0, 800.0]],  # not finite
    ])
    est = footprints_from_corners(cam, BUDGET, corners)
    R = est.corner_reason
    assert R[0].tolist() == [0, 0, 0, 0]
    assert R[1, 2] == status.ABOVE_HORIZON and np.all(np.isnan(est.corners_xy_world_m[1, 2]))
    assert R[2].tolist() == [status.OUTSIDE_IMAGE, 0, 0, status.OUTSIDE_IMAGE]
    assert np.all(np.isfinite(est.corners_xy_world_m[2]))  # computed, flagged, not usable
    assert R[3, 0] == status.NOT_FINITE
    assert est.centre_valid.tolist() == [True, False, False, False]
    assert est.centre_reason.tolist() == [0, status.ABOVE_HORIZON, status.OUTSIDE_IMAGE, status.NOT_FINITE]
    text = est.centre_reason_text()
    assert text[0] == "ok" and text[1].startswith("corner 2 of 4: above horizon")
    assert text[2].startswith("corner 0 of 4: pixel outside the image")
    assert np.all(np.isnan(est.centre_xy_world_m[1:])) and np.all(np.isnan(est.centre_cov_m2[1:]))
    # the largest point is still reported over the usable corners
    a, _, _ = ellipse_axes(est.corners_cov_m2)
    for i in range(4):
        use = est.corner_usable[i]
        assert est.largest_semi_major_m[i] == pytest.approx(np.nanmax(np.where(use, a[i], np.nan)))
        assert use[est.largest_index[i]]
    # V2X fields of a missing centre are "unavailable"
    assert est.v2x["cpm_x_confidence"][1] == 4096 and est.v2x["j2735_semi_major"][1] == 255
    # outside-image corners may be allowed explicitly
    est2 = footprints_from_corners(cam, BUDGET, corners, allow_outside_image=True)
    assert est2.centre_valid.tolist() == [True, False, True, False]
    assert est2.corner_reason[2, 0] == status.OUTSIDE_IMAGE  # the flag is kept


def test_no_usable_corner_and_degenerate_polygon(cam):
    hv = float(cam.horizon_v_px(960.0))
    corners = np.array([
        [[900.0, hv - 10], [1000.0, hv - 10], [1000.0, hv - 20], [900.0, hv - 20]],
        [[900.0, 900.0], [1000.0, 900.0], [1100.0, 900.0], [950.0, 900.0]],  # one image row: zero area
    ])
    est = footprints_from_corners(cam, BUDGET, corners)
    assert est.largest_index[0] == -1 and np.isnan(est.largest_semi_major_m[0])
    assert est.centre_reason[1] == DEGENERATE and est.centre_bad_corner[1] == -1
    assert "zero area" in est.centre_reason_text()[1]


def test_behind_camera_3d_corners(cam):
    boxes = np.array([[2.0, -30.0, 0.75, 4.0, 2.0, 1.5, 0.0]])  # behind a camera looking north-east
    est = footprints_from_boxes3d(cam, BUDGET, boxes)
    assert np.all(est.corner_reason == status.BEHIND_CAMERA)
    assert not est.centre_valid[0]


# -- shapes and bad input ------------------------------------------------------------------------------
def test_batch_shapes(cam, rng):
    for n in (1, 7):
        boxes = visible_boxes(cam, rng, n)
        est = footprints_from_boxes3d(cam, BUDGET, boxes)
        assert len(est) == n
        assert est.corners_xy_world_m.shape == (n, 4, 2) and est.joint_cov_m2.shape == (n, 8, 8)
        assert est.centre_cov_m2.shape == (n, 2, 2) and est.v2x_codes.shape == (n, 7)
        assert all(v.shape == (n,) for v in est.v2x.values())
    single = footprints_from_boxes3d(cam, BUDGET, visible_boxes(cam, rng, 3))
    part = footprints_from_boxes3d(cam, BUDGET, visible_boxes(cam, np.random.default_rng(20240611), 3)[:1])
    assert single.centre_cov_m2.shape[0] == 3 and part.centre_cov_m2.shape[0] == 1


@pytest.mark.parametrize("call, field", [
    (lambda c: footprints_from_corners(c, BUDGET, np.zeros((3, 2))), "corners_px"),
    (lambda c: footprints_from_boxes2d(c, BUDGET, np.zeros((2, 3))), "boxes_px"),
    (lambda c: footprints_from_boxes2d(c, BUDGET, np.array([[10.0, 10.0, 5.0, 20.0]])), "boxes_px[0]"),
    (lambda c: footprints_from_boxes2d(c, BUDGET, np.array([[1.0, 1, 2, 2]]), contact="middle"), "contact"),
    (lambda c: footprints_from_boxes3d(c, BUDGET, np.zeros((2, 6))), "boxes_world"),
    (lambda c: footprints_from_boxes3d(c, BUDGET, np.array([[0, 20, 0, -1.0, 2, 1, 0]])), "boxes_world[0]"),
    (lambda c: footprints_from_boxes3d(c, BUDGET, np.array([[0, 20, 0, 1.0, 2, 1, 0]]), yaw_unit="grad"),
     "yaw_unit"),
    (lambda c: footprints_from_corners(c, BUDGET, np.full((1, 4, 2), 900.0),
                                       pixel_cov_px2=np.array([[[1.0, 0], [0, -1.0]]])), "pixel_cov_px2"),
    (lambda c: footprints_from_corners(c, BUDGET, np.full((1, 4, 2), 900.0), pixel_cov_px2=np.eye(3)[None]),
     "pixel_cov_px2"),
    (lambda c: footprints_from_boxes2d(c, BUDGET, np.array([[1.0, 1, 2, 2]]), box_cov_px2=np.ones((1, 3))),
     "box_cov_px2"),
])
def test_bad_input_names_the_field(cam, call, field):
    with pytest.raises(InputError) as e:
        call(cam)
    assert str(e.value).startswith(field)


def test_object_rows_ellipse_is_the_centre_covariances_also_after_an_overflow():
    """The kernel's per-object ellipse rows (the service's records read them) equal ellipse_axes of the centre
    covariance, and a centre that an overflowing corner invalidates loses its ellipse there too."""
    from footprint_uq.fast.footprint_kernels import OBJ_ROW
    from footprint_uq.products.footprint_estimate import mark_overflow as _mark_overflow
    from footprint_uq.products.footprints import FrameProcessor

    cam = PanTiltCamera(focal_px=1400.0, image_size_px=(1920, 1080), height_m=8.0, pan_deg=10.0, tilt_deg=20.0)
    rng = np.random.default_rng(4)
    boxes = np.column_stack([rng.uniform(-15, 15, 30), rng.uniform(10, 80, 30), np.full(30, 0.8),
                             rng.uniform(3.5, 5, 30), rng.uniform(1.6, 2, 30), np.full(30, 1.5),
                             rng.uniform(-3, 3, 30)])
    est = FrameProcessor(cam, "basler1").boxes3d(boxes)
    rows = [est.object_rows[OBJ_ROW[k]] for k in ("sigma_major_m", "sigma_minor_m", "orientation_deg")]
    for got, want in zip(rows, ellipse_axes(est.centre_cov_m2), strict=True):
        np.testing.assert_allclose(got, want, rtol=1e-12, atol=1e-12)
    assert est.centre_valid[7]
    est.corners_cov_m2[7, 2] = np.inf  # a corner whose covariance overflowed
    est = _mark_overflow(est)
    assert not est.centre_valid[7] and est.centre_reason[7] == status.OVERFLOW
    assert all(np.isnan(r[7]) for r in rows) and all(np.isfinite(r[8]) for r in rows)
