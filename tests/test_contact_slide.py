"""The sliding contact of 2-D boxes (issue 36, part 4; tracking/contact_slide.py, docs/motion-fit.md section 6):
the contact's Jacobian and slide vs seeded central differences, pinned values, the size-prior term vs Monte
Carlo, and the hooks of `objects --tracks` and `serve --tracks`."""

from __future__ import annotations

import copy

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from footprint_uq import params as P
from footprint_uq.products.contact import class_size_priors
from footprint_uq.tracking import TrackOutput
from footprint_uq.tracking.contact_slide import (
    SIZE_NODES,
    ContactSlide,
    contact_point,
    slide_along_path,
    slide_covariance,
    slide_moments,
    slide_moments_reference,
    slide_velocity,
)
from footprint_uq.tracking.synthetic import default_camera

CAM = default_camera()


def _random_boxes(rng, n):
    c = np.column_stack([rng.uniform(-15, 15, n), rng.uniform(18, 50, n)])
    size = np.column_stack([rng.uniform(3.5, 12, n), rng.uniform(1.6, 2.6, n), rng.uniform(1.4, 3.5, n)])
    return c, size, rng.uniform(-np.pi, np.pi, n)


def test_contact_jacobian_matches_central_differences():
    rng = np.random.default_rng(3)
    c, size, yaw = _random_boxes(rng, 40)
    g, J, ok = contact_point(CAM, c, size, yaw)
    assert ok.all()
    h = 1e-4
    fd = np.empty_like(J)
    for j in range(2):
        e = np.zeros(2)
        e[j] = h
        fd[:, :, j] = (contact_point(CAM, c + e, size, yaw)[0] - contact_point(CAM, c - e, size, yaw)[0]) / (2 * h)
    # (a box whose extreme corner changes within +-h has a kink there: none at these seeded points)
    np.testing.assert_allclose(J, fd, atol=1e-6)
    assert np.abs(J - np.eye(2)).max() > 1e-3  # the contact does not move with the centre


def test_slide_matches_the_contacts_motion_along_the_path():
    """u = (dg/dc - I) v equals the central difference of the rendered contact along a straight path."""
    rng = np.random.default_rng(4)
    c, size, _ = _random_boxes(rng, 30)
    course = rng.uniform(-np.pi, np.pi, 30)
    v = 10.0 * np.column_stack([np.cos(course), np.sin(course)])
    u, ok = slide_velocity(CAM, c, v, size)
    assert ok.all()
    dt = 1e-5
    g1 = contact_point(CAM, c + dt * v, size, course)[0]
    g0 = contact_point(CAM, c - dt * v, size, course)[0]
    np.testing.assert_allclose(u, (g1 - g0) / (2 * dt) - v, atol=1e-5)


def test_slide_along_the_path_equals_the_closed_form():
    """The on-line form (a central difference of the rendered contact along the path, no derivatives) equals the
    closed form away from the kinks where an extreme corner changes."""
    rng = np.random.default_rng(6)
    c, size, _ = _random_boxes(rng, 50)
    course = rng.uniform(-np.pi, np.pi, 50)
    v = rng.uniform(1, 20, (50, 1)) * np.column_stack([np.cos(course), np.sin(course)])
    u, ok = slide_velocity(CAM, c, v, size)
    u2, ok2 = slide_along_path(CAM, c, v, size)
    assert ok.all() and ok2.all()
    np.testing.assert_allclose(u2, u, atol=2e-5)


def test_slide_pinned_on_the_diagonal_path():
    """The bench's diagonal path (docs/motion-fit.md, section 6) at its start: a car's contact slides at 0.991 m/s,
    a 12 m truck's at 1.931 m/s (the bench's frame differences of the noise-free render: up to 0.97 / 1.89 m/s).
    Hand-checked: the camera is level-rolled and looks north, so a box's lowest row is its nearest corner's
    northing, which moves with the vehicle: the slide has no north component; it is a westward lag."""
    v = 10.0 / np.sqrt(2.0) * np.ones((2, 2))
    u, ok = slide_velocity(CAM, np.array([[-12.0, 20.0]] * 2), v, np.array([[4.5, 1.8, 1.5], [12.0, 2.5, 3.5]]))
    assert ok.all()
    np.testing.assert_allclose(u[:, 1], 0.0, atol=1e-9)
    np.testing.assert_allclose(u[:, 0], [-0.9909, -1.9314], atol=5e-4)
    u0, _ = slide_velocity(CAM, np.array([[-12.0, 20.0]]), np.zeros((1, 2)), np.array([[4.5, 1.8, 1.5]]))
    np.testing.assert_allclose(u0, 0.0, atol=1e-12)  # standing: no slide


def test_slide_covariance_is_the_size_priors_second_moment():
    """The term over the unscented size nodes vs a seeded Monte Carlo over the size prior (car and truck), and
    its centre: the contact of the centre it finds is the given contact (to second order)."""
    rng = np.random.default_rng(5)
    v = np.array([[7.07, 7.07], [7.07, 7.07]])
    mean, sig = class_size_priors(["car", "truck"], 2)
    c_true = np.array([[-12.0, 20.0], [-6.0, 24.0]])
    x = contact_point(CAM, c_true, mean, np.full(2, np.pi / 4))[0]
    M = slide_covariance(CAM, x, v, mean, sig)
    m, M2 = slide_moments(CAM, x, v, mean, sig)
    np.testing.assert_array_equal(M, M2)
    for i in range(2):
        sizes = mean[i] + rng.standard_normal((20000, 3)) * sig[i]
        u, ok = slide_velocity(CAM, np.repeat(c_true[i:i + 1], 20000, 0), np.repeat(v[i:i + 1], 20000, 0), sizes)
        mc = np.einsum("ki,kj->ij", u[ok], u[ok]) / ok.sum()
        np.testing.assert_allclose(M[i], mc, rtol=0.05, atol=1e-3)
        np.testing.assert_allclose(m[i], u[ok].mean(0), rtol=0.03, atol=1e-3)
    # zero spread: the term is u u^T of the prior's mean size at the centre
    M0 = slide_covariance(CAM, x, v, mean, np.zeros_like(sig))
    u, _ = slide_velocity(CAM, c_true, v, mean)
    np.testing.assert_allclose(M0, np.einsum("ni,nj->nij", u, u), rtol=2e-3, atol=1e-6)
    assert SIZE_NODES.shape == (6, 3)


def _camera_with(**changes):
    """The default camera with parameters changed by name (a lens, skew, a sloped ground: every branch of the
    compiled term)."""
    cam = copy.copy(CAM)
    p = np.array(CAM.params, dtype=np.float64)
    for name, value in changes.items():
        p[P.PARAM_NAMES.index(name)] = value
    cam.params = p
    return cam


CAMERAS = {"plain": CAM, "lens, skew, sloped ground": _camera_with(k1=-0.12, k2=0.03, p1=4e-4, skew_px=1.5,
                                                                     ground_slope_x=0.03, ground_slope_y=-0.02,
                                                                     ground_dz_m=0.2, roll_rad=0.04)}
CLASSES = ["car", "truck", "bus", "pedestrian", "cyclist", "van", None, "no such class"]


@settings(max_examples=40, deadline=None, derandomize=True)
@given(st.sampled_from(sorted(CAMERAS)), st.integers(1, 6), st.integers(0, 2**32 - 1))
def test_compiled_moments_equal_the_closed_form(camera, n, seed):
    """The compiled term (fast/slide_kernels) equals the numpy closed form to rounding over positions, velocities
    and classes (seeded Hypothesis sweep; a lens, skew and a sloped ground take the kernel's other branches).  (The
    central difference along the path differs from both where an extreme corner changes within its step: checked
    away from such kinks in test_slide_along_the_path_equals_the_closed_form.)"""
    cam = CAMERAS[camera]
    rng = np.random.default_rng(seed)
    xy = np.column_stack([rng.uniform(-15, 15, n), rng.uniform(15, 60, n)])
    course, speed = rng.uniform(-np.pi, np.pi, n), rng.uniform(0.0, 25.0, n)
    v = speed[:, None] * np.column_stack([np.cos(course), np.sin(course)])
    mean, sig = class_size_priors([CLASSES[i] or "" for i in rng.integers(0, len(CLASSES), n)], n)
    m, M = slide_moments(cam, xy, v, mean, sig)
    mr, Mr = slide_moments_reference(cam, xy, v, mean, sig)
    assert np.isfinite(M).all() and np.isfinite(m).all()
    scale = np.abs(Mr).max((1, 2))[:, None, None]
    np.testing.assert_allclose(M, Mr, rtol=0, atol=1e-9 * scale.max() + 1e-13)
    np.testing.assert_allclose(m, mr, rtol=0, atol=1e-9 * np.sqrt(scale.max()) + 1e-12)


def test_compiled_moments_nan_where_nothing_renders():
    """A contact behind the camera (its box does not render) or without a velocity: NaN, the other rows
    unchanged."""
    xy = np.array([[0.0, 30.0], [0.0, -30.0], [0.0, 30.0]])
    v = np.array([[5.0, 5.0], [5.0, 5.0], [np.nan, np.nan]])
    mean, sig = class_size_priors(["car"] * 3, 3)
    m, M = slide_moments(CAM, xy, v, mean, sig)
    assert np.isfinite(M[0]).all() and np.isnan(M[1:]).all() and np.isnan(m[1:]).all()
    np.testing.assert_array_equal(M[0], slide_moments(CAM, xy[:1], v[:1], mean[:1], sig[:1])[1][0])


def _output(xy, v):
    n = xy.shape[0]
    out = TrackOutput.untracked(n)
    out.track_id[:] = np.arange(n)
    out.xy_m[:], out.v_mps[:] = xy, v
    out.cov_v_m2ps2[:] = 0.04 * np.eye(2)
    return out


def test_apply_adds_the_term_where_a_velocity_is_reported():
    slide = ContactSlide(CAM)
    xy = np.array([[-12.0, 18.0], [-12.0, 18.0], [-12.0, 18.0], [0.0, 30.0]])
    v = np.array([[7.0, 7.0], [7.0, 7.0], [7.0, 7.0], [np.nan, np.nan]])
    out = slide.apply(_output(xy, v), ["truck", "car", None, "car"])
    extra = out.cov_v_m2ps2 - 0.04 * np.eye(2)
    assert extra[0, 0, 0] > extra[1, 0, 0] > 0.1  # a truck slides more than a car
    assert 0 < extra[2, 0, 0] < extra[1, 0, 0]  # no class: the fallback prior (2 +- 1.5 m)
    assert (extra[3] == 0).all()  # no velocity: untouched
    assert np.all(np.linalg.eigvalsh(extra[:3]) >= -1e-12)


def test_for_camera_refuses_a_camera_that_cannot_render_a_box():
    class Flat:  # a camera without the parametric model (as a homography camera)
        pass

    assert ContactSlide.for_camera(Flat()) is None
    assert isinstance(ContactSlide.for_camera(CAM), ContactSlide)


def _boxes_of_a_diagonal_truck(n_frames=45):
    """2-D boxes of a 12 m truck driving diagonally past the default camera (bench/contact_velocity_bias.py)."""
    from footprint_uq.cameras import general

    t = np.arange(n_frames) / 30.0
    v = 10.0 / np.sqrt(2.0) * np.ones(2)
    centre = np.array([-12.0, 20.0]) + t[:, None] * v
    c, s = np.cos(np.pi / 4), np.sin(np.pi / 4)
    dx, dy = np.array([1, 1, -1, -1]) * 6.0, np.array([1, -1, -1, 1]) * 1.25
    pts = np.zeros((n_frames, 8, 3))
    for k, z in enumerate((0.0, 3.5)):
        pts[:, 4 * k:4 * k + 4, 0] = centre[:, :1] + c * dx - s * dy
        pts[:, 4 * k:4 * k + 4, 1] = centre[:, 1:] + s * dx + c * dy
        pts[:, 4 * k:4 * k + 4, 2] = z
    uv = general.project(CAM.params, pts.reshape(-1, 3), domain=CAM.lens_domain).uv_px.reshape(n_frames, 8, 2)
    return t, np.column_stack([uv[..., 0].min(1), uv[..., 1].min(1), uv[..., 0].max(1), uv[..., 1].max(1)])


@pytest.mark.parametrize("where", ["service", "batch"])
def test_tracks_of_2d_boxes_carry_the_term(where, monkeypatch):
    """`serve --tracks` and `objects --tracks` report the velocity sigma with the term (larger than without it);
    3-D boxes never get it."""
    from footprint_uq.tracking import contact_slide

    t, boxes = _boxes_of_a_diagonal_truck()

    def sigma(with_term: bool) -> float:
        if not with_term:
            monkeypatch.setattr(contact_slide.ContactSlide, "for_camera", classmethod(lambda cls, cam, sp=None: None))
        else:
            monkeypatch.undo()
        if where == "service":
            from footprint_uq.service.core import Service

            svc = Service(CAM, "basler1@deg", camera_id="cam1", tracks=True, messages=False)
            rec = None
            for k, (tk, b) in enumerate(zip(t, boxes, strict=True)):
                rec = svc.process_frame({"camera_id": "cam1", "frame": k, "timestamp_s": float(tk), "detections": [
                    {"object_id": 1, "class": "truck", **dict(zip(("u_min_px", "v_min_px", "u_max_px", "v_max_px"),
                                                                  map(float, b), strict=True))}]})
            return float(rec["objects"][0]["sigma_speed_mps"])
        import pyarrow as pa

        from footprint_uq.batch.process import process_table

        tab = pa.table({"timestamp_s": t, "object_id": ["a"] * len(t), "class": ["truck"] * len(t),
                        "u_min_px": boxes[:, 0], "v_min_px": boxes[:, 1], "u_max_px": boxes[:, 2],
                        "v_max_px": boxes[:, 3]})
        out = process_table(CAM, "basler1@deg", tab, tracks=True)
        return float(out.column("sigma_speed_mps").to_numpy()[-1])

    without, with_term = sigma(False), sigma(True)
    assert with_term > 1.1 * without, (without, with_term)


def _nodes_rendered(cam, xy, v, mean, sig):
    """Per contact, how many of the six size nodes render in the numpy reference (its centre by the same one
    fixed-point step): the cases of partly rendered nodes below are checked to be such."""
    from footprint_uq.products.contact import rendered_bottom_centre

    yaw = np.arctan2(v[:, 1], v[:, 0])
    g0 = cam.backproject(rendered_bottom_centre(cam, xy, mean, yaw, gradients=False)[0]).xy_world_m
    sizes = np.clip(mean[:, None, :] + SIZE_NODES[None] * sig[:, None, :], 0.02, None)
    _, ok = slide_velocity(cam, np.repeat((2.0 * xy - g0)[:, None], 6, 1), np.repeat(v[:, None], 6, 1), sizes)
    return ok.sum(1)


@pytest.mark.parametrize("camera", sorted(CAMERAS))
def test_compiled_moments_where_some_nodes_do_not_render(camera):
    """Long trucks close below the camera: the longest nodes' rear corners are behind it (or, with the lens,
    outside its domain), the others render; the compiled term averages over the same nodes as the reference."""
    cam = CAMERAS[camera]
    y = np.linspace(-3.0, 12.0, 61)
    xy = np.column_stack([np.full_like(y, 0.5), y])
    v = np.tile([0.3, 8.0], (y.size, 1))
    mean, sig = class_size_priors(["truck"] * y.size, y.size)
    sig = sig * np.array([6.0, 1.0, 1.0])
    k = _nodes_rendered(cam, xy, v, mean, sig)
    assert ((k > 0) & (k < 6)).sum() >= 3 and (k == 0).any() and (k == 6).any(), k
    m, M = slide_moments(cam, xy, v, mean, sig)
    mr, Mr = slide_moments_reference(cam, xy, v, mean, sig)
    np.testing.assert_array_equal(np.isnan(M), np.isnan(Mr))
    f = np.isfinite(Mr).all((1, 2))
    scale = np.abs(Mr[f]).max()
    np.testing.assert_allclose(M[f], Mr[f], rtol=0, atol=1e-9 * scale)
    np.testing.assert_allclose(m[f], mr[f], rtol=0, atol=1e-9 * np.sqrt(scale))


@pytest.mark.parametrize("camera", sorted(CAMERAS))
def test_compiled_moments_of_standing_objects(camera):
    """v = 0 (either sign of zero): the course is taken as 0 (the reference's atan2(0, 0)), no slide -- the
    moments are exactly zero, not NaN -- and the other rows of the frame are unchanged by them."""
    cam = CAMERAS[camera]
    xy = np.array([[-4.0, 25.0], [3.0, 40.0], [0.0, 18.0], [6.0, 30.0]])
    v = np.array([[0.0, 0.0], [-0.0, 0.0], [-0.0, -0.0], [4.0, -3.0]])
    mean, sig = class_size_priors(["car", "truck", "pedestrian", "bus"], 4)
    m, M = slide_moments(cam, xy, v, mean, sig)
    mr, Mr = slide_moments_reference(cam, xy, v, mean, sig)
    assert (m[:3] == 0).all() and (M[:3] == 0).all()
    assert np.isfinite(M[3]).all() and np.abs(M[3]).max() > 1e-4
    np.testing.assert_allclose(M, Mr, rtol=0, atol=1e-9 * np.abs(Mr).max())
    np.testing.assert_allclose(m, mr, rtol=0, atol=1e-9 * np.sqrt(np.abs(Mr).max()))
    np.testing.assert_array_equal(M[3], slide_moments(cam, xy[3:], v[3:], mean[3:], sig[3:])[1][0])


def test_kernel_course_from_the_velocity():
    """The kernel's course as ``v / |v|``: ``(1, 0)`` standing (atan2(0, 0) = 0), the unit vector otherwise (no
    overflow or underflow of |v|: to 6e-15 at a subnormal speed), NaN for a NaN velocity."""
    from footprint_uq.fast.slide_kernels import _heading

    assert _heading(0.0, 0.0) == (1.0, 0.0) and _heading(-0.0, -0.0) == (1.0, 0.0)
    for vx, vy in [(3.0, 4.0), (-3.0, 4.0), (0.0, -2.0), (1e-310, -1e-310), (1e300, 1e300), (-7.0, 0.0)]:
        c, s = _heading(vx, vy)
        yaw = np.arctan2(vy, vx)
        assert abs(c - np.cos(yaw)) < 1e-12 and abs(s - np.sin(yaw)) < 1e-12, (vx, vy, c, s)  # (subnormal |v|: 6e-15)
    assert all(np.isnan(_heading(np.nan, 1.0))) and all(np.isnan(_heading(1.0, np.nan)))


def test_covariance_zero_only_without_a_velocity():
    """`ContactSlide.covariance`: a row without a velocity or position gets zero, a row whose box does not render
    (behind the camera) keeps NaN (not reported with a covariance), the others the compiled moments."""
    slide = ContactSlide(CAM)
    xy = np.array([[0.0, 30.0], [0.0, -30.0], [0.0, 30.0], [np.nan, 30.0], [-5.0, 22.0]])
    v = np.array([[5.0, 5.0], [5.0, 5.0], [np.nan, 1.0], [2.0, 2.0], [0.0, 9.0]])
    M = slide.covariance(_output(xy, v), ["car"] * 5)
    mean, sig = class_size_priors(["car"] * 5, 5)
    ref = slide_moments(CAM, xy, v, mean, sig)[1]
    np.testing.assert_array_equal(M[[0, 4]], ref[[0, 4]])
    assert np.isnan(M[1]).all() and (M[2:4] == 0).all()
    M2 = slide.covariance(_output(xy[[0, 4]], v[[0, 4]]), ["car"] * 2)   # (no NaN row: nothing masked)
    np.testing.assert_array_equal(M2, ref[[0, 4]])


def test_priors_of_one_class_frames_follow_the_class_and_the_count():
    """The priors of a one-class frame are kept for the next frame of that class and size only."""
    slide = ContactSlide(CAM)
    for classes in (["car"] * 3, ["car"] * 3, ["truck"] * 3, ["truck"] * 5, ["car"] * 5, ["car", "truck", None],
                    ["car"] * 5, [None] * 2, []):
        mean, sig = slide._priors(classes, len(classes))
        rm, rs = class_size_priors([c or "" for c in classes], len(classes))
        np.testing.assert_array_equal(mean, rm)
        np.testing.assert_array_equal(sig, rs)


def _mixed_contacts(rng, n):
    """``n`` contacts of every kind the tracker hands the slide term, in seeded random order: moving (any course,
    0-25 m/s), behind the camera (the box does not render), a NaN velocity (both or one component), standing
    (``+-0``), and long trucks close below the camera whose longest nodes do not render (the others do).  Returns
    ``xy (n, 2)``, ``v (n, 2)``, ``size_mean``, ``size_sigma`` (n, 3) and the kinds (n,)."""
    kind = rng.integers(0, 6, n)
    xy = np.column_stack([rng.uniform(-15, 15, n), rng.uniform(15, 60, n)])
    course, speed = rng.uniform(-np.pi, np.pi, n), rng.uniform(0.0, 25.0, n)
    v = speed[:, None] * np.column_stack([np.cos(course), np.sin(course)])
    mean, sig = class_size_priors([CLASSES[i] or "" for i in rng.integers(0, len(CLASSES), n)], n)
    xy[kind == 1, 1] = -rng.uniform(5.0, 40.0, (kind == 1).sum())
    v[kind == 2] = np.nan
    v[kind == 3] = rng.choice([0.0, -0.0], ((kind == 3).sum(), 2))
    v[kind == 4, rng.integers(0, 2)] = np.nan
    trucks = kind == 5
    xy[trucks] = np.column_stack([np.full(trucks.sum(), 0.5), rng.uniform(-3.0, 12.0, trucks.sum())])
    v[trucks] = [0.3, 8.0]
    mean[trucks], sig[trucks] = class_size_priors(["truck"], 1)[0], class_size_priors(["truck"], 1)[1] * [6, 1, 1]
    return xy, v, mean, sig, kind


@pytest.mark.parametrize("camera", sorted(CAMERAS))
@pytest.mark.parametrize("n", [0, 1, 7, 8, 9, 63, 64, 65, 100, 129])
def test_columnar_kernel_equals_the_reference_at_every_frame_size(camera, n):
    """The pinhole's columnar kernel (blocks of 64 objects, passes over whole vectors of 8) and the lens's object
    by object kernel equal the numpy closed form to rounding on frames of every size around the vector width and
    the block (0, 1, 7, 8, 9, 63-65, 100, 129 objects) with every kind of contact (:func:`_mixed_contacts`): NaN
    exactly where the reference has NaN, and each object's moments those of the object alone (no lane or block
    leaks into another)."""
    cam = CAMERAS[camera]
    rng = np.random.default_rng(1000 + n)
    xy, v, mean, sig, kind = _mixed_contacts(rng, n)
    m, M = slide_moments(cam, xy, v, mean, sig)
    mr, Mr = slide_moments_reference(cam, xy, v, mean, sig)
    assert M.shape == (n, 2, 2) and m.shape == (n, 2)
    np.testing.assert_array_equal(np.isnan(M), np.isnan(Mr))
    np.testing.assert_array_equal(np.isnan(m), np.isnan(mr))
    assert np.isnan(M[(kind == 1) | (kind == 2) | (kind == 4)]).all()
    assert (M[kind == 3] == 0).all() and (m[kind == 3] == 0).all()
    f = np.isfinite(Mr).all((1, 2))
    scale = np.abs(Mr[f]).max((1, 2), initial=0.0)[:, None, None]
    np.testing.assert_allclose(M[f], Mr[f], rtol=0, atol=1e-9 * scale.max(initial=0.0) + 1e-13)
    np.testing.assert_allclose(m[f], mr[f], rtol=0, atol=1e-9 * np.sqrt(scale.max(initial=0.0)) + 1e-12)
    for i in rng.choice(n, min(n, 12), replace=False):
        mi, Mi = slide_moments(cam, xy[i:i + 1], v[i:i + 1], mean[i:i + 1], sig[i:i + 1])
        np.testing.assert_allclose(Mi[0], M[i], rtol=1e-13, atol=1e-15)
        np.testing.assert_allclose(mi[0], m[i], rtol=1e-13, atol=1e-15)
    if n >= 63:  # (the sweep reaches the cases it names)
        k = _nodes_rendered(cam, xy, v, mean, sig)
        assert ((k > 0) & (k < 6)).any() and (k == 0).any() and (k == 6).any(), k


@pytest.mark.parametrize("camera", sorted(CAMERAS))
def test_kernels_take_any_number_of_nodes(camera):
    """The kernels' node count is their argument's: the six nodes twice give the moments of the six (to
    rounding), one node of the mean size gives ``u u^T`` of the mean box."""
    from footprint_uq.fast import slide_kernels
    from footprint_uq.tracking.contact_slide import kernel_camera

    cam = CAMERAS[camera]
    xy, v, mean, sig, _ = _mixed_contacts(np.random.default_rng(8), 70)
    consts = kernel_camera(cam)

    def moments(nodes):
        m, M = np.empty((70, 2)), np.empty((70, 2, 2))
        slide_kernels.slide_moments(*consts, xy, v, mean, sig, np.ascontiguousarray(nodes, dtype=np.float64), m, M)
        return m, M

    m6, M6 = moments(SIZE_NODES)
    m12, M12 = moments(np.vstack([SIZE_NODES, SIZE_NODES]))
    np.testing.assert_allclose(M12, M6, rtol=1e-14, atol=1e-15)
    np.testing.assert_allclose(m12, m6, rtol=1e-14, atol=1e-15)
    m1, M1 = moments(np.zeros((1, 3)))
    ok = np.isfinite(m1).all(1)
    assert ok.sum() > 20
    np.testing.assert_allclose(M1[ok], np.einsum("ni,nj->nij", m1[ok], m1[ok]), rtol=1e-14, atol=1e-15)


def test_columnar_passes_are_vectorised():
    """The kernels' passes (the pinhole's, and the lens's render and update) compile to packed vector divisions
    (AVX2 ``ymm`` or AVX-512 ``zmm``): a branch, a library call or an aliasing doubt left in a pass would keep it
    scalar (~10x the time, ``bench/bench_slide.py``).  Compiled afresh (numba does not show the code of a cached
    kernel)."""
    import llvmlite.binding as llvm
    import numba as nb
    from numba import types

    from footprint_uq.fast import slide_kernels as sk

    if "+avx2" not in llvm.get_host_cpu_features().flatten():
        pytest.skip("the host has no AVX2")
    cam = types.UniTuple(types.float64, 22)
    col = types.float64[::1]
    for name, sig in [("_render_block", (col, cam, types.int64)), ("_block_start", (col, cam, types.int64)),
                      ("_block_centre", (col, cam, types.int64)),
                      ("_block_node", (col, cam, types.float64, types.float64, types.float64, types.int64)),
                      ("_render_block_lens", (col, cam, types.UniTuple(types.float64, 8), types.float64,
                                              types.float64, types.int64)),
                      ("_block_update_lens", (col, cam, types.boolean[::1], types.int64))]:
        fresh = nb.njit(sig, error_model="numpy", fastmath={"contract"})(getattr(sk, name).py_func)
        asm = fresh.inspect_asm(fresh.signatures[0])
        assert any("vdivpd" in line and ("%zmm" in line or "%ymm" in line) for line in asm.splitlines()), name


def _tracker_output(rng, cam_name, n):
    """A :class:`TrackOutput` of ``n`` mixed contacts (:func:`_mixed_contacts`) as the tracker hands it: its
    ``cov_v_m2ps2`` random, NaN where no velocity, some entries ``-0.0``; and the objects' classes."""
    xy, v, _, _, _ = _mixed_contacts(rng, n)
    out = _output(xy, v)
    a = rng.normal(0.0, 0.3, (n, 2, 2))
    out.cov_v_m2ps2[:] = a @ a.transpose(0, 2, 1)
    out.cov_v_m2ps2[~np.isfinite(v).all(1)] = np.nan
    out.cov_v_m2ps2[rng.random((n, 2, 2)) < 0.05] = -0.0
    classes = [CLASSES[i] for i in rng.integers(0, len(CLASSES), n)]
    return out, classes


@pytest.mark.parametrize("camera", sorted(CAMERAS))
@pytest.mark.parametrize("n", [0, 1, 7, 8, 9, 63, 64, 65, 100, 129])
def test_apply_is_the_sum_of_cov_v_and_the_term(camera, n):
    """`ContactSlide.apply` (one compiled call: moments, the zero term without a velocity, the sum) gives the
    numpy sum of the tracker's ``cov_v`` and `ContactSlide.covariance` -- the bytes where the term is zero or NaN
    (-0.0 and NaN included), to 1e-12 of the object's largest entry elsewhere -- (the moments kernel and the mask
    in numpy), on frames of every kind of contact and
    size around the vector width and the block; every other field is the input's own array, the input is not
    changed."""
    slide = ContactSlide(CAMERAS[camera])
    out, classes = _tracker_output(np.random.default_rng(2000 + n), camera, n)
    before = out.cov_v_m2ps2.copy()
    got = slide.apply(out, classes)
    term = slide.covariance(out, classes)
    want = out.cov_v_m2ps2 + term
    assert got.cov_v_m2ps2.shape == (n, 2, 2)
    # Where the term is zero or NaN: the bytes (-0.0 kept, NaN where no velocity).  Elsewhere to 1e-12 of the
    # object's largest entry: `apply`'s kernel and the moments kernel are compiled apart, with FMA contraction
    # allowed, and whether LLVM fuses across a callee (the lens's `core.undistort_vec`: its Newton steps) depends on
    # whether that callee was compiled in the same process or loaded from numba's cache -- a fresh `pytest -n 2`
    # run showed differences of 6-126 ulp (~3e-14 relative) on the lens cameras; one process gives equal bytes.
    exact = (term == 0.0) | np.isnan(want)
    assert got.cov_v_m2ps2[exact].tobytes() == want[exact].tobytes()
    scale = np.broadcast_to(np.nanmax(np.abs(want), axis=(1, 2), initial=0.0)[:, None, None], want.shape)
    assert (np.abs(got.cov_v_m2ps2 - want)[~exact] <= 1e-12 * scale[~exact]).all()
    assert out.cov_v_m2ps2.tobytes() == before.tobytes() and got.cov_v_m2ps2 is not out.cov_v_m2ps2
    assert all(getattr(got, f) is getattr(out, f) for f in TrackOutput._fields[:-1])
    if n >= 63:  # (the frame has rows of each case: a term, a zero term, NaN)
        term = want - out.cov_v_m2ps2
        assert (term == 0).all((1, 2)).any() and np.isnan(want).all((1, 2)).any() and (term > 0.0).any()


def test_apply_takes_any_layout_and_names_a_wrong_shape():
    """Rows not as the tracker gives them (strided, read-only, float32, a list) are copied as the kernel takes
    them -- the same result; a field of the wrong shape is refused by name (the kernel reads one row per
    object)."""
    from footprint_uq.errors import InputError

    slide = ContactSlide(CAM)
    out, classes = _tracker_output(np.random.default_rng(11), "plain", 20)
    want = slide.apply(out, classes).cov_v_m2ps2
    wide = np.zeros((20, 4))
    wide[:, ::2] = out.xy_m
    ro = out.v_mps.copy()
    ro.flags.writeable = False
    odd = out._replace(xy_m=wide[:, ::2], v_mps=ro, cov_v_m2ps2=out.cov_v_m2ps2.tolist())
    assert slide.apply(odd, classes).cov_v_m2ps2.tobytes() == want.tobytes()
    f32 = out._replace(xy_m=out.xy_m.astype(np.float32))
    np.testing.assert_array_equal(slide.apply(f32, classes).cov_v_m2ps2,
                                  out.cov_v_m2ps2 + slide.covariance(f32, classes))
    for field, bad in (("xy_m", out.xy_m[:19]), ("v_mps", out.v_mps.reshape(-1)),
                       ("cov_v_m2ps2", out.cov_v_m2ps2[:, 0])):
        with pytest.raises(InputError, match=f"out.{field}"):
            slide.apply(out._replace(**{field: bad}), classes)


def test_a_tracked_service_loads_the_slide_kernel_before_its_first_frame():
    """The tracked service's warm frames call the term's compiled entry with the real frames' signature (a cold or
    second signature would compile in the first frame, ~seconds)."""
    from footprint_uq.fast import slide_kernels
    from footprint_uq.service.core import Service

    svc = Service(CAM, "basler1", camera_id="cam1", tracks=True, record="compact")
    kernel = slide_kernels.ADDED_KERNELS[False]
    before = set(kernel.signatures)
    assert before
    t, boxes = _boxes_of_a_diagonal_truck(3)
    for k in range(3):
        box = dict(zip(("u_min_px", "v_min_px", "u_max_px", "v_max_px"), map(float, boxes[k]), strict=True))
        svc.process_frame({"camera_id": "cam1", "frame": k, "timestamp_s": 1.7e9 + float(t[k]),
                           "detections": [{"object_id": 1, "class": "truck", **box}]})
    assert set(kernel.signatures) == before


WIDE_LENS = _camera_with(k1=-0.25, p2=0.02)   # (the lens's domain: a ring of normalised radius 1.08-1.24)


def _wide_contacts(rng, n):
    """Contacts across and beside the view of :data:`WIDE_LENS` (corners of their boxes in its domain's ring,
    beyond it, behind the camera), any course, cars to long trucks."""
    xy = np.column_stack([rng.uniform(-45.0, 45.0, n), rng.uniform(-2.0, 40.0, n)])
    course, speed = rng.uniform(-np.pi, np.pi, n), rng.uniform(0.0, 25.0, n)
    v = speed[:, None] * np.column_stack([np.cos(course), np.sin(course)])
    mean, sig = class_size_priors([("car", "truck", "bus", "pedestrian")[i] for i in rng.integers(0, 4, n)], n)
    return xy, v, mean, sig * rng.uniform(1.0, 4.0, (n, 1))


def test_lens_render_pass_is_the_object_by_object_render():
    """The lens's columnar render (`_render_block_lens`, branch-free: the domain as its outer radius, the objects
    with a corner in the ring between its radii flagged) then `_render_doubts` (those rendered again by `_render`,
    the domain's table) equal `_render` object by object: the bottom-centre pixel, its rate, whether it renders,
    the start of the undistortion -- over boxes of which some have corners in the ring (flagged), beyond it
    and behind the camera."""
    from footprint_uq.fast import slide_kernels as sk
    from footprint_uq.tracking.contact_slide import kernel_camera

    prm, R, dom, _ = kernel_camera(WIDE_LENS)
    cam = sk._camera_scalars(prm, R)
    k = prm[5:13].copy()
    rng = np.random.default_rng(21)
    B = sk._BLOCK
    S = np.full(sk._NCOL_LENS * B, np.nan)
    xy, v, mean, _ = _wide_contacts(rng, B)
    for j in range(B):
        q = sk._offset(prm, R, xy[j, 0], xy[j, 1])
        cs, sn = np.cos(rng.uniform(-np.pi, np.pi)), 0.0
        sn = np.sqrt(1.0 - cs * cs) * rng.choice([-1.0, 1.0])
        a = 0.5 * mean[j, 0] * (R[0] * cs + R[1] * sn)
        b = 0.5 * mean[j, 1] * (R[1] * cs - R[0] * sn)
        h = mean[j, 2] * R[2]
        d = R.T @ np.array([v[j, 0], v[j, 1], 0.0])
        for col, val in zip((sk._Q0, sk._OL0, sk._OW0, sk._OH0, sk._D0), (q, a, b, h, d), strict=True):
            S[col * B + j:(col + 3) * B + j:B] = val
    in2, lim2 = dom[3], max(dom[3], dom[4])
    kt = tuple(float(c) for c in k)
    sk._render_block_lens(S, cam, kt, lim2, in2, B)
    flagged = S[sk._DBT * B:(sk._DBT + 1) * B] != 0.0
    sk._render_doubts(S, prm, dom, k, B)
    ok = np.zeros(B, bool)

    def col(c, j):
        return tuple(float(S[(c + i) * B + j]) for i in range(3))

    for j in range(B):
        u, vv, du, dv, okj, x0, y0 = sk._render(prm, dom, True, k, col(sk._Q0, j), col(sk._OL0, j),
                                                 col(sk._OW0, j), col(sk._OH0, j), *col(sk._D0, j))
        ok[j] = okj
        assert (S[sk._OK * B + j] != 0.0) == okj, j
        if okj:
            got = [S[c * B + j] for c in (sk._U, sk._V, sk._DU, sk._DV, sk._X0, sk._Y0)]
            np.testing.assert_allclose(got, [u, vv, du, dv, x0, y0], rtol=1e-12, atol=1e-9)
    assert flagged.sum() >= 3 and ok.sum() >= 10 and (~ok).sum() >= 3, (flagged.sum(), ok.sum())
    assert (ok & flagged).any() and (~ok & flagged).any()


@pytest.mark.parametrize("n", [1, 9, 64, 65, 129])
def test_lens_kernel_equals_the_reference_where_the_domain_ring_is_reached(n):
    """The lens's columnar kernel against the numpy closed form on contacts whose boxes reach the lens's domain
    ring (some nodes render, others not): NaN where the reference has NaN, the moments to rounding."""
    rng = np.random.default_rng(3000 + n)
    xy, v, mean, sig = _wide_contacts(rng, n)
    m, M = slide_moments(WIDE_LENS, xy, v, mean, sig)
    mr, Mr = slide_moments_reference(WIDE_LENS, xy, v, mean, sig)
    np.testing.assert_array_equal(np.isnan(M), np.isnan(Mr))
    f = np.isfinite(Mr).all((1, 2))
    scale = np.abs(Mr[f]).max(initial=0.0)
    np.testing.assert_allclose(M[f], Mr[f], rtol=0, atol=1e-9 * scale + 1e-13)
    np.testing.assert_allclose(m[f], mr[f], rtol=0, atol=1e-9 * np.sqrt(scale) + 1e-12)
    if n >= 64:
        k = _nodes_rendered(WIDE_LENS, xy, v, mean, sig)
        assert ((k > 0) & (k < 6)).any() and (k == 0).any() and (k == 6).any(), k
