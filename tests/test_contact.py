"""The contact model (footprint_uq.products.contact): Monte Carlo of rendered boxes, Jacobians against
central differences, the size priors and bad input, and the real Rope3D frame."""

from __future__ import annotations

import copy

import numpy as np
import pytest

from footprint_uq import params as P
from footprint_uq.cameras import general
from footprint_uq.cameras.opencv import OpenCVCamera
from footprint_uq.cameras.pantilt import PanTiltCamera
from footprint_uq.errors import ConfigError, InputError
from footprint_uq.io.dataset_files import camera_from_rope3d
from footprint_uq.products import contact as C

CAM = PanTiltCamera(2000.0, (1920, 1080), 8.0, 30.0, 14.0, 0.5, (5.0, -3.0))


def _render_boxes(cam, rng, n, cls, *, edge_sigma_px=2.0, v_range=(380.0, 1000.0)):
    """Truth footprint centres and the noisy bounding boxes of their rendered cuboids."""
    priors = C.load_size_priors()[0]
    uv = np.column_stack([rng.uniform(250, 1670, n), rng.uniform(*v_range, n)])
    centre = cam.backproject(uv).xy_world_m
    size = np.clip(priors[cls].mean_m + priors[cls].sigma_m * rng.standard_normal((n, 3)), 0.05, None)
    yaw = rng.uniform(0, 2 * np.pi, n)
    uvc = general.project(cam.params, C._corners(cam.params, centre, size, yaw)).uv_px
    boxes = np.column_stack([uvc[..., 0].min(1), uvc[..., 1].min(1), uvc[..., 0].max(1), uvc[..., 1].max(1)])
    return centre, boxes + rng.normal(0, edge_sigma_px, boxes.shape), yaw


def test_monte_carlo_of_rendered_boxes_bias_removed_and_95_percent_coverage():
    """Cars at 20-110 m, unknown yaw, size from the prior, 2 px noise on every box edge."""
    rng = np.random.default_rng(20)
    n, s = 300, 2.0
    truth, boxes, _ = _render_boxes(CAM, rng, n, "car", edge_sigma_px=s)
    cov_uv = np.diag([s**2 / 2, s**2])  # the bottom-centre pixel: mean of two edges in u, one edge in v
    res = C.footprint_centre(CAM, {}, boxes, ["car"] * n, cov_uv_px2=cov_uv, box_sigma_px=s)
    bc = C.bottom_centre(CAM, {}, boxes, ["car"] * n, cov_uv_px2=cov_uv)
    assert res.valid.all()
    d, d_bc = truth - res.xy_world_m, truth - bc.xy_world_m
    sigma = np.sqrt(np.median(np.trace(res.cov_object_m2, axis1=1, axis2=2) / 2))
    assert np.linalg.norm(d_bc.mean(0)) > 4 * sigma               # the bottom centre is biased ...
    se = d.std(0) / np.sqrt(n)
    assert np.all(np.abs(d.mean(0)) < np.maximum(3 * se, 0.1 * sigma)), (d.mean(0), se, sigma)  # ... removed
    nees = np.einsum("na,na->n", d, np.linalg.solve(res.cov_object_m2, d[..., None])[..., 0])
    assert 0.93 <= np.mean(nees <= -2 * np.log(0.05)) <= 0.97
    assert np.median(np.linalg.norm(d, axis=1)) < 0.25 * np.median(np.linalg.norm(d_bc, axis=1))


def test_a_known_yaw_narrows_the_estimate():
    rng = np.random.default_rng(3)
    truth, boxes, yaw = _render_boxes(CAM, rng, 40, "car", edge_sigma_px=1.0)
    kw = {"cov_uv_px2": np.diag([0.5, 1.0]), "box_sigma_px": 1.0}
    free = C.footprint_centre(CAM, {}, boxes, ["car"] * 40, **kw)
    known = C.footprint_centre(CAM, {}, boxes, ["car"] * 40, yaw_rad=yaw, yaw_sigma_rad=0.02, **kw)
    tr = lambda r: np.trace(r.cov_object_m2, axis1=1, axis2=2)  # noqa: E731
    assert np.median(tr(known)) < np.median(tr(free))
    assert np.median(np.linalg.norm(truth - known.xy_world_m, axis=1)) < \
        np.median(np.linalg.norm(truth - free.xy_world_m, axis=1))


def _camera_with(cam, p):
    c = copy.copy(cam)
    c.params = p
    return c


@pytest.mark.parametrize("yaw", [None, 0.7])
def test_jacobian_against_central_differences(yaw, monkeypatch):
    """dxy_dp of the footprint centre (implicit function theorem through every Newton node, the Kalman
    update and the yaw weights) against seeded central differences, on a camera with distortion (8 yaw
    nodes instead of 36 to keep the 44 evaluations quick: the derivative code is the same)."""
    monkeypatch.setattr(C, "YAW_NODES_UNKNOWN", 8)
    rng = np.random.default_rng(7)
    cam = OpenCVCamera(np.array([[1800.0, 0.5, 950.0], [0, 1790.0, 545.0], [0, 0, 1]]),
                       np.array([-0.05, 0.01, 1e-4, -2e-4, 0.0]), *_pose(), (1920, 1080), 0.0)
    cam.params[P.GSX], cam.params[P.GSY], cam.params[P.GDZ] = 0.01, -0.02, 0.05
    _, boxes, _ = _render_boxes(cam, rng, 3, "van", edge_sigma_px=0.0, v_range=(500, 900))
    y = None if yaw is None else np.full(3, yaw)
    res = C.footprint_centre(cam, {}, boxes, ["van"] * 3, yaw_rad=y)
    assert res.valid.all()
    num = np.zeros_like(res.dxy_dp)
    for j in range(P.N_PARAMS):
        h = 1e-6 * max(abs(cam.params[j]), 1e-2 if j >= P.K1 else 1.0)
        e = np.zeros(P.N_PARAMS)
        e[j] = h
        xp = C.footprint_centre(_camera_with(cam, cam.params + e), {}, boxes, ["van"] * 3, yaw_rad=y).xy_world_m
        xm = C.footprint_centre(_camera_with(cam, cam.params - e), {}, boxes, ["van"] * 3, yaw_rad=y).xy_world_m
        num[..., j] = (xp - xm) / (2 * h)
    scale = np.abs(num).max(-1, keepdims=True)
    np.testing.assert_allclose(res.dxy_dp, num, rtol=1e-4, atol=1e-5 * scale.max())


def _pose():
    """R, t of a camera 7 m up, looking north 13 deg down (world z up)."""
    ref = PanTiltCamera(1800.0, (1920, 1080), 7.0, 0.0, 13.0)
    T = ref.T_cam_world
    return T[:3, :3], T[:3, 3]


def test_pixel_jacobian_matches_central_differences_of_the_box():
    """The pixel part of cov_object_m2 is J_uv S J_uv^T: J_uv against moving the bottom-centre pixel."""
    rng = np.random.default_rng(9)
    _, boxes, _ = _render_boxes(CAM, rng, 2, "car", edge_sigma_px=0.0)
    base = C.footprint_centre(CAM, {}, boxes, ["car"] * 2)
    h = 1e-4
    for k, shift in enumerate(([h, 0, h, 0], [0, 0, 0, h])):  # u of the bottom centre (width kept), v_max
        s = np.array(shift)
        fd = (C.footprint_centre(CAM, {}, boxes + s, ["car"] * 2).xy_world_m
              - C.footprint_centre(CAM, {}, boxes - s, ["car"] * 2).xy_world_m) / (2 * h)
        S = np.zeros((2, 2))
        S[k, k] = 1.0
        got = C.footprint_centre(CAM, {}, boxes, ["car"] * 2, cov_uv_px2=S).cov_object_m2 - base.cov_object_m2
        np.testing.assert_allclose(got, fd[:, :, None] * fd[:, None, :], rtol=1e-4, atol=1e-12)


def test_bottom_centre_by_name_is_the_back_projected_bottom_edge_and_totals_add_up():
    boxes = np.array([[900.0, 500.0, 1000.0, 620.0], [100.0, 300.0, 180.0, 350.0]])
    budget = {"pan_deg": 0.1, "height_m": 0.2, "imaging_px": [1.0, 1.0]}
    r = C.CONTACT_MODELS["bottom-centre"](CAM, budget, boxes, ["car", "car"])
    np.testing.assert_allclose(r.xy_world_m, CAM.backproject([[950.0, 620.0], [140.0, 350.0]]).xy_world_m)
    for model in C.CONTACT_MODELS.values():
        r = model(CAM, budget, boxes, ["car", "pedestrian"])
        from footprint_uq.uncertainty.budget import load_budget

        S = load_budget(budget).param_covariance()
        np.testing.assert_allclose(r.cov_m2, r.dxy_dp @ S @ np.swapaxes(r.dxy_dp, 1, 2) + r.cov_object_m2,
                                   rtol=1e-12)
        assert r.status.dtype == np.int8 and r.valid.all()


def test_unknown_classes_fallback_or_error_and_user_priors(tmp_path):
    boxes = np.array([[900.0, 500.0, 1000.0, 620.0]])
    other = C.footprint_centre(CAM, {}, boxes, ["hovercraft"])            # the documented fallback prior
    same = C.footprint_centre(CAM, {}, boxes, ["other"])
    np.testing.assert_allclose(other.xy_world_m, same.xy_world_m)
    with pytest.raises(InputError, match=r"classes\[1\].*hovercraft"):
        C.footprint_centre(CAM, {}, np.repeat(boxes, 2, 0), ["car", "hovercraft"], unknown_class="error")
    alias = C.footprint_centre(CAM, {}, boxes, [" Person "])
    ped = C.footprint_centre(CAM, {}, boxes, ["pedestrian"])
    np.testing.assert_allclose(alias.xy_world_m, ped.xy_world_m)
    f = tmp_path / "priors.yaml"
    f.write_text("classes:\n  car: {length_m: [12.0, 0.5], width_m: [2.5, 0.1], height_m: [3.0, 0.2]}\n")
    big = C.footprint_centre(CAM, {}, boxes, ["car"], size_priors=f)
    small = C.footprint_centre(CAM, {}, boxes, ["car"])
    assert np.linalg.norm(big.xy_world_m - small.xy_world_m) > 0.5
    f.write_text("classes:\n  car: {length_m: [4.0, -1.0], width_m: [2, 0.1], height_m: [1.5, 0.1]}\n")
    with pytest.raises(ConfigError, match="classes.car"):
        C.footprint_centre(CAM, {}, boxes, ["car"], size_priors=f)


@pytest.mark.parametrize("kw, field", [
    ({"yaw_rad": [0.1, 0.2]}, "yaw_rad"), ({"yaw_sigma_rad": -1.0}, "yaw_sigma_rad"),
    ({"box_sigma_px": 0.0}, "box_sigma_px"), ({"unknown_class": "guess"}, "unknown_class"),
    ({"cov_uv_px2": np.ones((3, 2, 2))}, "cov_uv_px2"),
])
def test_bad_input_is_a_one_line_error(kw, field):
    with pytest.raises(InputError) as e:
        C.footprint_centre(CAM, {}, [[900.0, 500.0, 1000.0, 620.0]], ["car"], **kw)
    assert e.value.field.startswith(field) and "\n" not in str(e.value)


def test_a_box_cut_by_the_image_border_says_nothing_by_its_width():
    boxes = np.array([[0.0, 500.0, 120.0, 620.0], [1800.0, 500.0, 1919.0, 600.0]])
    cut = C.footprint_centre(CAM, {}, boxes, ["car"] * 2)
    blind = C.footprint_centre(CAM, {}, boxes, ["car"] * 2, box_sigma_px=1e5)  # width noise swamps it
    np.testing.assert_allclose(cut.xy_world_m, blind.xy_world_m, atol=1e-3)
    inside = C.footprint_centre(CAM, {}, boxes + [[5.0, 0, 5.0, 0], [-5.0, 0, -5.0, 0]], ["car"] * 2)
    assert np.abs(inside.xy_world_m - blind.xy_world_m).max() > 0.01  # the width is used off the border


def test_a_box_above_the_horizon_is_invalid_not_a_number():
    r = C.footprint_centre(CAM, {}, [[900.0, -400.0, 1000.0, -300.0], [900.0, 500.0, 1000.0, 620.0]], ["car"] * 2)
    assert list(r.valid) == [False, True] and np.isnan(r.xy_world_m[0]).all() and r.status[0] != 0


# ---------------------------------------------------------------------------------------------
# the real frame
# ---------------------------------------------------------------------------------------------
def _rope3d(folder):
    """Camera, classes, 2-D boxes, labelled bottom centres (world, with their height above the plane),
    yaw and truncation of the Rope3D demo frame; labels without a 3-D box (location 0 0 0) dropped."""
    cam = camera_from_rope3d(next((folder / "calib").iterdir()), image_size_px=(1920, 1080))
    rows = [ln.split() for ln in next((folder / "label_2").iterdir()).read_text().splitlines() if ln.strip()]
    cls = np.array([r[0] for r in rows])
    v = np.array([[float(x) for x in r[1:]] for r in rows])
    has = np.any(v[:, 10:13] != 0, axis=1)
    T = cam.T_world_cam
    xyz = v[:, 10:13] @ T[:3, :3].T + T[:3, 3]
    ry = v[:, 13]
    head = np.stack([np.cos(ry), np.zeros_like(ry), -np.sin(ry)], 1) @ T[:3, :3].T  # KITTI: ry about camera y
    yaw = np.arctan2(head[:, 1], head[:, 0])
    return cam, cls[has], v[has, 3:7], xyz[has], yaw[has], v[has, 0]


def test_rope3d_contact_model_removes_most_of_the_bottom_centre_error(shared_data):
    """Each object on its own labelled ground height (the plane's misfit, up to 0.4 m under far objects,
    is a calibration error, measured below): the contact model cuts the median error by more than half."""
    cam, cls, boxes, xyz, yaw, trunc = _rope3d(shared_data("rope3d-demo"))
    assert len(cls) == 44
    T = cam.T_cam_world
    err = {"bottom": [], "contact": [], "contact+yaw": []}
    for i in range(len(cls)):
        ci = OpenCVCamera(cam.K, None, T[:3, :3], T[:3, 3], (1920, 1080), float(xyz[i, 2]))
        args = (ci, {}, boxes[i:i + 1], cls[i:i + 1])
        for k, r in (("bottom", C.bottom_centre(*args)), ("contact", C.footprint_centre(*args)),
                     ("contact+yaw", C.footprint_centre(*args, yaw_rad=yaw[i:i + 1]))):
            err[k].append(np.linalg.norm(r.xy_world_m[0] - xyz[i, :2]))
    med = {k: float(np.median(v)) for k, v in err.items()}
    assert med["contact"] < 0.5 * med["bottom"] and med["contact+yaw"] < 0.5 * med["bottom"], med
    whole = trunc == 0
    p95 = {k: float(np.percentile(np.array(v)[whole], 95)) for k, v in err.items()}
    assert p95["contact"] < 0.5 * p95["bottom"], p95
    # on the file's single ground plane the plane's misfit dominates: the contact model still does not
    # make the median worse (the numbers: docs/uncertainty-model.md, section 3c)
    flat = [np.median(np.linalg.norm(f(cam, {}, boxes, cls).xy_world_m - xyz[:, :2], axis=1))
            for f in (C.bottom_centre, C.footprint_centre)]
    assert flat[1] <= flat[0]


# ---------------------------------------------------------------------------------------------
# the compiled node solver against the numpy reference
# ---------------------------------------------------------------------------------------------
def _distorted_camera():
    cam = OpenCVCamera(np.array([[1800.0, 0.5, 950.0], [0, 1790.0, 545.0], [0, 0, 1]]),
                       np.array([-0.05, 0.01, 1e-4, -2e-4, 0.0]), *_pose(), (1920, 1080), 0.0)
    cam.params[P.GSX], cam.params[P.GSY], cam.params[P.GDZ] = 0.01, -0.02, 0.05
    return cam


@pytest.mark.parametrize("which", ["pantilt", "distorted"])
def test_compiled_solver_agrees_with_the_numpy_reference(which, monkeypatch):
    """footprint_centre with the compiled node solver and posterior (the default) and with the numpy
    reference (``_solve_nodes_reference``, ``_posterior_reference``): every output to 1e-9 relative,
    validity and codes equal; mixed classes, known and unknown yaws, a box cut by the border, a box above
    the horizon."""
    monkeypatch.setattr(C, "YAW_NODES_UNKNOWN", 12)
    cam = CAM if which == "pantilt" else _distorted_camera()
    rng = np.random.default_rng(11)
    _, boxes, yaw = _render_boxes(cam, rng, 12, "car", v_range=(450, 950))
    boxes = np.vstack([boxes, [[0.0, 500.0, 120.0, 620.0], [900.0, -400.0, 1000.0, -300.0]]])
    cls = ["car", "van", "truck", "bus", "pedestrian", "cyclist"] * 2 + ["car", "car"]
    yaw = np.concatenate([yaw, [np.nan, 0.3]])
    yaw[::3] = np.nan
    kw = {"yaw_rad": yaw, "cov_uv_px2": np.diag([1.0, 2.0])}
    fast = C.footprint_centre(cam, {"pan_deg": 0.1, "height_m": 0.1}, boxes, cls, **kw)
    monkeypatch.setattr(C, "_solve_nodes", C._solve_nodes_reference)
    monkeypatch.setattr(C, "_posterior", C._posterior_reference)
    ref = C.footprint_centre(cam, {"pan_deg": 0.1, "height_m": 0.1}, boxes, cls, **kw)
    assert fast.valid[:-1].all() and not fast.valid[-1]
    np.testing.assert_array_equal(fast.valid, ref.valid)
    np.testing.assert_array_equal(fast.status, ref.status)
    for f in ("xy_world_m", "cov_m2", "cov_object_m2", "dxy_dp"):
        a, b = getattr(fast, f), getattr(ref, f)
        np.testing.assert_array_equal(np.isnan(a), np.isnan(b))
        scale = np.abs(np.nan_to_num(b)).reshape(len(b), -1).max(1).reshape((-1,) + (1,) * (b.ndim - 1))
        err = np.nanmax(np.abs(a - b) / np.where(scale > 0, scale, 1.0))
        assert err < 1e-9, (f, err)


def test_one_bottom_centre_for_products_and_validation_with_flags_and_linearity():
    """validation.pairs uses the contact module's bottom_centre and CONTACT_MODELS (one implementation); a box
    whose bottom centre lies below the image keeps its numbers flagged OUTSIDE_IMAGE (in both models), and
    the bottom-centre point's linearity flag equals propagate's."""
    from footprint_uq import status
    from footprint_uq.uncertainty.propagation import propagate
    from footprint_uq.validation import pairs

    assert pairs.bottom_centre is C.bottom_centre and pairs.CONTACT_MODELS is C.CONTACT_MODELS
    boxes = np.array([[900.0, 500.0, 1000.0, 620.0], [900.0, 1000.0, 1000.0, 1100.0]])
    budget = {"pan_deg": 0.1, "tilt_deg": 0.05, "height_m": 0.2, "imaging_px": [1.0, 1.0]}
    for model in C.CONTACT_MODELS.values():
        r = model(CAM, budget, boxes, ["car", "car"])
        assert r.valid.all() and list(r.status) == [status.OK, status.OUTSIDE_IMAGE]
        assert np.isfinite(r.xy_world_m).all()
    cuv = np.diag([2.0, 3.0])
    nl = C.bottom_centre_nonlinearity(CAM, budget, boxes, cuv)
    ref = propagate(CAM, budget, [[950.0, 620.0], [950.0, 1100.0]], pixel_cov_px2=cuv, linearity=True)
    np.testing.assert_allclose(nl, ref.nonlinearity, rtol=1e-7)
    assert np.isnan(C.bottom_centre_nonlinearity(CAM, budget, boxes, cuv, valid=[True, False])[1])
