"""Uncertainty maps: agreement with propagate, GSD against finite differences, masking, files, figures."""

from __future__ import annotations

import json
import warnings

import numpy as np
import pytest

from footprint_uq import ErrorBudget, InputError, OpenCVCamera, PanTiltCamera, ellipse_axes, propagate, status
from footprint_uq.products.covariance import covariance_map
from footprint_uq.products.maps import UncertaintyMap, ground_sampling_distance, uncertainty_map

BUDGET = ErrorBudget.preset("bw-bullet1").replace(ground_height_m=0.05, ground_slope_deg=0.5, roll_deg=0.01)


@pytest.fixture(scope="module")
def cam():
    # small image so that step 1 stays fast; horizon inside the image
    return PanTiltCamera(focal_px=300.0, image_size_px=(160, 120), height_m=6.0, pan_deg=-40.0, tilt_deg=8.0,
                         roll_deg=3.0, position_m=(5.0, -2.0))


@pytest.fixture(scope="module")
def cam_cv():
    K = [[310.0, 0.4, 81.0], [0.0, 305.0, 58.0], [0.0, 0.0, 1.0]]
    pt = PanTiltCamera(300.0, (160, 120), 6.0, 25.0, 18.0, -2.0, (1.0, 2.0))
    T = pt.T_cam_world
    return OpenCVCamera(K, [-0.12, 0.03, 1e-3, -5e-4, 0.0], T[:3, :3], T[:3, 3], (160, 120))


@pytest.mark.parametrize("step", [1, 7])
def test_reference_path_equals_propagate(cam, step):
    m = uncertainty_map(cam, BUDGET, step, use_kernel=False)
    uv = cam.pixel_grid(step)
    est = propagate(cam, BUDGET, uv)
    assert m.uv_px.shape == uv.shape and m.shape == uv.shape[:2]
    np.testing.assert_array_equal(m.uv_px, uv)
    np.testing.assert_array_equal(m.valid, est.valid)
    np.testing.assert_array_equal(m.reason, est.reason)
    assert 0 < m.valid.mean() < 1  # both sky and ground in this image
    np.testing.assert_allclose(m.xy_world_m, est.xy_world_m, rtol=1e-14, equal_nan=True)
    np.testing.assert_allclose(m.cov_m2, est.cov_m2, rtol=1e-14, equal_nan=True)
    a, b, ang = ellipse_axes(est.cov_m2)
    np.testing.assert_allclose(m.semi_major_m, a, rtol=1e-14, equal_nan=True)
    np.testing.assert_allclose(m.semi_minor_m, b, rtol=1e-14, equal_nan=True)
    np.testing.assert_allclose(m.orientation_deg, ang, rtol=1e-14, equal_nan=True)


def test_default_path_equals_reference(cam, cam_cv):
    """Whatever path is used by default (fused kernel when present) agrees with propagate, without fallback."""
    # a distorted camera whose horizon crosses the image: grazing rays reach thousands of kilometres
    T = PanTiltCamera(300.0, (160, 120), 6.0, 25.0, 6.0, 1.5).T_cam_world
    cam_sky = OpenCVCamera([[305.0, 0.2, 79.0], [0.0, 301.0, 61.0], [0.0, 0.0, 1.0]], [-0.25, 0.06, 1e-3, -5e-4, 0.0],
                           T[:3, :3], T[:3, 3], (160, 120))
    for c, step in ((cam, 5), (cam_cv, 5), (cam_sky, 1)):
        ref = uncertainty_map(c, BUDGET, step, use_kernel=False)
        with warnings.catch_warnings():
            warnings.simplefilter("error", RuntimeWarning)
            m = uncertainty_map(c, BUDGET, step)
        np.testing.assert_array_equal(m.valid, ref.valid)
        np.testing.assert_array_equal(m.reason, ref.reason)
        v = ref.valid
        np.testing.assert_allclose(m.xy_world_m[v], ref.xy_world_m[v], rtol=1e-9, atol=1e-9)
        scale = np.abs(ref.cov_m2[v]).max(axis=(-2, -1), keepdims=True)
        assert np.max(np.abs(m.cov_m2[v] - ref.cov_m2[v]) / scale) < 1e-8
        assert np.all(np.isnan(m.cov_m2[~v]))
        # the linearity layer: the reference's numbers, NaN (and not linear_ok) where there is no ground point
        np.testing.assert_allclose(m.nonlinearity[v], ref.nonlinearity[v], rtol=1e-9, atol=1e-12)
        assert np.all(np.isnan(m.nonlinearity[~v])) and not m.linear_ok[~v].any()
        np.testing.assert_array_equal(m.linear_ok, ref.linear_ok)


def test_kernel_guard_falls_back_on_disagreement(cam, monkeypatch):
    """A kernel returning wrong numbers is detected, reported and replaced by the reference path."""
    import footprint_uq.products.maps as maps_mod

    def broken(camera, budget, step_px=1, *, out=None, get_nonlinearity=False):
        est = propagate(camera, budget, camera.pixel_grid(step_px))
        cov = est.cov_m2.copy()
        cov[est.valid.nonzero()[0][-1], :] *= 1.01  # one row of pixels 1 % off
        return (est.xy_world_m, cov, est.valid) + ((est.nonlinearity,) if get_nonlinearity else ())

    monkeypatch.setattr(maps_mod, "covariance_map", broken)
    ref = uncertainty_map(cam, BUDGET, 4, use_kernel=False)
    with pytest.warns(RuntimeWarning, match="disagrees with the reference path"):
        m = uncertainty_map(cam, BUDGET, 4)
    np.testing.assert_array_equal(m.cov_m2, ref.cov_m2)


def test_pixel_jacobian_equals_backproject(cam, cam_cv):
    from footprint_uq.products.maps import pixel_jacobian

    for c in (cam, cam_cv):
        uv = c.pixel_grid(6)
        bp = c.backproject(uv, get_gradients=True)
        J, valid = pixel_jacobian(c, uv)
        np.testing.assert_array_equal(valid, bp.valid)
        np.testing.assert_allclose(J, bp.dxy_duv, rtol=1e-12, atol=0, equal_nan=True)
        flat = np.concatenate([uv.reshape(-1, 2), [[np.nan, 3.0]]], 0)
        xy, J2, valid2, reason = pixel_jacobian(c, flat, full=True)
        ref = c.backproject(flat)
        np.testing.assert_array_equal(reason, ref.reason)
        assert reason[-1] == status.NOT_FINITE and (c is cam_cv or (reason == status.ABOVE_HORIZON).any())
        np.testing.assert_allclose(xy, ref.xy_world_m, rtol=1e-12, equal_nan=True)
        np.testing.assert_array_equal(J2[:-1], J.reshape(-1, 2, 2))


def _fd_jacobian(camera, uv, h=2e-4):
    J = np.empty(uv.shape[:-1] + (2, 2))
    for k in range(2):
        d = np.zeros(2)
        d[k] = h
        J[..., :, k] = (camera.backproject(uv + d).xy_world_m - camera.backproject(uv - d).xy_world_m) / (2 * h)
    return J


@pytest.mark.parametrize("which", ["pantilt", "opencv"])
def test_gsd_against_finite_differences(which, cam, cam_cv):
    c = cam if which == "pantilt" else cam_cv
    # up to 1 km: beyond, pixels graze the horizon and central differences lose accuracy (error ~ h^2 / s^3)
    m = uncertainty_map(c, BUDGET, 3, use_kernel=False, max_range_m=1000.0)
    v = m.valid
    uv = m.uv_px[v]
    J = _fd_jacobian(c, uv)
    # independent evaluation of the definition
    d = m.xy_world_m[v] - c.params[13:15]
    e_r = d / np.linalg.norm(d, axis=-1, keepdims=True)
    e_c = np.stack([-e_r[:, 1], e_r[:, 0]], -1)
    a, b = J[:, :, 0], J[:, :, 1]
    gr = np.abs(np.einsum("ni,ni->n", a, e_r)) + np.abs(np.einsum("ni,ni->n", b, e_r))
    gc = np.abs(np.einsum("ni,ni->n", a, e_c)) + np.abs(np.einsum("ni,ni->n", b, e_c))
    area = np.abs(np.linalg.det(J))
    for got, want in ((m.gsd_range_m[v], gr), (m.gsd_cross_m[v], gc), (m.footprint_area_m2[v], area)):
        rel = np.abs(got - want) / np.abs(want)
        assert rel.max() < 1e-5, rel.max()
    np.testing.assert_allclose(m.range_m[v], np.linalg.norm(d, axis=-1), rtol=1e-12)
    assert np.all(np.isnan(m.gsd_range_m[~v])) and np.all(np.isnan(m.gsd_cross_m[~v]))


def test_gsd_hand_checked_forward_camera():
    """At the principal point: along-range GSD = h / (f sin^2 tilt), across = h / (f sin tilt)."""
    h, f, tilt = 7.0, 1000.0, 15.0
    c = PanTiltCamera(f, (201, 161), h, 123.0, tilt, 0.0, (3.0, 4.0), principal_point_px=(100.0, 80.0))
    bp = c.backproject(np.array([100.0, 80.0]), get_gradients=True)
    gr, gc, area, rng = ground_sampling_distance(c, bp.xy_world_m, bp.dxy_duv)
    s = np.sin(np.radians(tilt))
    assert gr == pytest.approx(h / (f * s * s), rel=1e-12)
    assert gc == pytest.approx(h / (f * s), rel=1e-12)
    assert area == pytest.approx(h * h / (f * f * s**3), rel=1e-12)
    assert rng == pytest.approx(h / np.tan(np.radians(tilt)), rel=1e-12)


def test_gsd_nadir_camera_uses_heading_below_the_camera():
    h, f = 10.0, 500.0
    c = PanTiltCamera(f, (101, 81), h, 30.0, 90.0, 0.0, principal_point_px=(50.0, 40.0))
    bp = c.backproject(np.array([50.0, 40.0]), get_gradients=True)
    gr, gc, area, rng = ground_sampling_distance(c, bp.xy_world_m, bp.dxy_duv)
    assert rng < 1e-9
    assert gr == pytest.approx(h / f, rel=1e-9) and gc == pytest.approx(h / f, rel=1e-9)
    # the whole footprint of a nadir camera is a (W h/f) x (H h/f) rectangle
    m = uncertainty_map(c, "basler1", 1)
    assert m.valid.all()
    total = m.summary(thresholds_m=(1e9,))["below_threshold"][0]["ground_area_m2"]
    assert total == pytest.approx(101 * 81 * (h / f) ** 2, rel=1e-9)


def test_max_range_masks_with_reason(cam):
    full = uncertainty_map(cam, BUDGET, 4, use_kernel=False)
    r = 40.0
    m = uncertainty_map(cam, BUDGET, 4, max_range_m=r, use_kernel=False)
    far = full.valid & (full.range_m > r)
    assert far.any() and (full.valid & ~far).any()
    np.testing.assert_array_equal(m.valid, full.valid & ~far)
    assert np.all(m.reason[far] == status.BEYOND_RANGE)
    assert np.all(m.reason[~full.valid] == full.reason[~full.valid])
    for arr in (m.xy_world_m, m.cov_m2, m.semi_major_m, m.gsd_range_m, m.range_m):
        assert np.all(np.isnan(arr[far]))
    np.testing.assert_array_equal(m.cov_m2[m.valid], full.cov_m2[m.valid])
    s = m.summary()
    assert s["range_m_max"] <= r
    assert s["reason_counts"][status.REASONS[status.BEYOND_RANGE]] == int(far.sum())


def test_summary_consistent(cam):
    m = uncertainty_map(cam, BUDGET, 4)
    s = m.summary(confidence=0.95)
    a95 = m.semi_axes(0.95)[0][m.valid]
    assert s["semi_major_m_median"] == pytest.approx(np.median(a95))
    assert s["fraction_valid"] == pytest.approx(m.valid.mean())
    for t in s["below_threshold"]:
        sel = m.valid & (m.semi_axes(0.95)[0] < t["semi_major_below_m"])
        assert t["fraction_of_image"] == pytest.approx(sel.mean())
        assert t["ground_area_m2"] == pytest.approx((m.footprint_area_m2[sel] * 16).sum())
    json.dumps(s, allow_nan=False)


def test_npz_round_trip(tmp_path, cam, cam_cv):
    for c in (cam, cam_cv):
        m = uncertainty_map(c, BUDGET, 9, max_range_m=60)
        p = m.save_npz(tmp_path / "sub" / "m.npz")
        back = UncertaintyMap.load_npz(p)
        for name in ("uv_px", "xy_world_m", "cov_m2", "valid", "reason", "semi_major_m", "gsd_range_m",
                     "gsd_cross_m", "footprint_area_m2", "range_m", "orientation_deg"):
            np.testing.assert_array_equal(getattr(back, name), getattr(m, name))
        assert back.step_px == 9 and back.max_range_m == 60
        np.testing.assert_array_equal(back.nonlinearity, m.nonlinearity)
        np.testing.assert_array_equal(back.linear_ok, m.linear_ok)
        assert back.linear_threshold == m.linear_threshold
        np.testing.assert_array_equal(back.camera.params, c.params)
        np.testing.assert_array_equal(back.budget.param_covariance(), BUDGET.param_covariance())
        with np.load(p) as z:
            meta = json.loads(str(z["metadata_json"]))
        assert "e_range" in meta["gsd_definition"]


def test_bad_input(cam):
    for step in (0, -2, 1.5, "a", float("inf"), float("nan"), None):
        with pytest.raises(InputError, match="step_px"):
            uncertainty_map(cam, BUDGET, step)
        with pytest.raises(InputError, match="step_px"):
            covariance_map(cam, BUDGET, step)
    with pytest.raises(InputError, match="max_range_m"):
        uncertainty_map(cam, BUDGET, 4, max_range_m=-1)
    with pytest.raises(InputError, match="budget"):
        uncertainty_map(cam, "no-such-preset", 4)


def test_figures(tmp_path, cam):
    from footprint_uq import viz

    m = uncertainty_map(cam, BUDGET, 2, max_range_m=80)
    fig = viz.plot_image_map(m, confidence=0.95)
    ax = fig.axes[0]
    img = ax.images[0].get_array()
    want = np.ma.masked_invalid(np.where(m.valid, m.semi_axes(0.95)[0], np.nan))
    np.testing.assert_array_equal(img.mask, want.mask)
    np.testing.assert_allclose(img.compressed(), want.compressed())
    assert "2.448" in fig.axes[1].get_ylabel()  # colourbar says which multiple of sigma
    for name, f in (("img", fig), ("ground", viz.plot_ground_map(m)), ("gsd", viz.plot_gsd_maps(m)),
                    ("prof", viz.plot_range_profile([m]))):
        p = viz.save_figure(f, tmp_path / f"{name}.png", dpi=60)
        assert p.stat().st_size > 5000
        assert p.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_linearity_layer_masks_and_summary(cam):
    """linear_ok = valid and nonlinearity <= threshold; max_range masks the layer too; the summary counts it."""
    m = uncertainty_map(cam, "bw-cube1@deg", 2, max_range_m=80, linear_threshold=0.02)
    beyond = m.reason == status.BEYOND_RANGE
    assert beyond.any() and np.all(np.isnan(m.nonlinearity[~m.valid]))
    with np.errstate(invalid="ignore"):
        np.testing.assert_array_equal(m.linear_ok, m.valid & (m.nonlinearity <= 0.02))
    s = m.summary()
    assert s["linear_threshold"] == 0.02
    assert s["fraction_linear_ok"] == pytest.approx(m.linear_ok[m.valid].mean())
    assert 0.0 < s["fraction_linear_ok"] < 1.0  # the flag trips inside 80 m with degree-read angles
    bad = m.valid & ~m.linear_ok
    assert s["range_m_min_not_linear_ok"] == pytest.approx(m.range_m[bad].min())
    off = uncertainty_map(cam, "bw-cube1@deg", 2, max_range_m=80, linearity=False)
    assert off.nonlinearity is None and off.linear_ok is None and off.summary()["fraction_linear_ok"] is None
    np.testing.assert_array_equal(off.cov_m2, m.cov_m2)
    with pytest.raises(InputError, match="linear_threshold"):
        uncertainty_map(cam, BUDGET, 4, linear_threshold=0.0)


def test_figures_show_the_linearity_flag(tmp_path, cam):
    """The heat map hatches the valid pixels that are not linear_ok and draws the threshold's contour; the
    nonlinearity figure shows the layer, masked exactly where there is no ground point."""
    from matplotlib.contour import ContourSet

    from footprint_uq import viz

    thr = 0.05
    m = uncertainty_map(cam, "bw-cube1@deg", 2, linear_threshold=thr)
    assert (m.valid & ~m.linear_ok).any() and m.linear_ok.any()
    for fig in (viz.plot_image_map(m), viz.plot_ground_map(m)):
        sets = [c for c in fig.axes[0].collections if isinstance(c, ContourSet)]
        lines = [c for c in sets if list(c.levels) == [thr] and not c.filled]
        hatched = [c for c in sets if c.filled and any(h for h in (c.hatches or []))]
        assert len(lines) == 1 and len(hatched) == 1
        labels = fig.axes[0].get_legend().get_texts()
        assert any("not linear_ok" in t.get_text() for t in labels)
    fig = viz.plot_nonlinearity_map(m)
    img = fig.axes[0].images[0].get_array()
    np.testing.assert_array_equal(img.mask, ~m.valid)
    np.testing.assert_allclose(img.compressed(), np.clip(m.nonlinearity[m.valid], 1e-4 * 0.999, None))
    sets = [c for c in fig.axes[0].collections if isinstance(c, ContourSet)]
    assert [list(c.levels) for c in sets] == [[thr]]
    # without the flag: no hatch, no threshold contour
    off = viz.plot_image_map(uncertainty_map(cam, "bw-cube1@deg", 2, linearity=False))
    assert not [c for c in off.axes[0].collections if isinstance(c, ContourSet) and list(c.levels) == [thr]]
    with pytest.raises(InputError, match="nonlinearity"):
        viz.plot_nonlinearity_map(uncertainty_map(cam, BUDGET, 4, linearity=False))
    p = viz.save_figure(fig, tmp_path / "nl.png", dpi=60)
    assert p.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_report_helpers(tmp_path):
    import base64

    from footprint_uq.viz.report import html_page, html_table, img_tag, write_html

    t = html_table([{"a": "<b>", "b": float("nan"), "c": None, "d": 0.123456789, "e": True}], floatfmt=".3g")
    assert "&lt;b&gt;" in t and "<b>" not in t
    # a missing number (None or NaN) is a dash unless the column says what it means: never "NaN" (issue 24)
    assert "NaN" not in t and t.count("<td>&ndash;</td>") == 2 and "<td>0.123</td>" in t and "<td>yes</td>" in t
    t = html_table([{"b": float("nan")}], missing={"b": "no ground point"})
    assert "<td>no ground point</td>" in t
    png = b"\x89PNG\r\n\x1a\n" + b"0" * 10
    tag = img_tag(png, "a <caption>")
    uri = tag.split('src="')[1].split('"')[0]
    assert base64.b64decode(uri.split(",", 1)[1]) == png
    assert "a &lt;caption&gt;" in tag
    page = html_page("T & T", [t, tag])
    assert page.startswith("<!DOCTYPE html>") and "<title>T &amp; T</title>" in page
    p = write_html(tmp_path / "x" / "r.html", page)
    assert p.read_text(encoding="utf-8") == page


def test_returned_reason_is_never_the_internal_scratch():
    """covariance_map reuses a per-thread status buffer only when the codes are not returned: a returned
    ``reason`` is the caller's own array, untouched by later maps (of this or another size)."""

    cam = PanTiltCamera(800.0, (64, 48), 6.0, 0.0, 0.5)  # the horizon crosses the image
    cam2 = PanTiltCamera(800.0, (64, 48), 6.0, 0.0, 1.5)  # other codes: more of the image sees the ground
    *_, r1 = covariance_map(cam, "basler1", get_reason=True)
    keep = r1.copy()
    covariance_map(cam2, "basler1")  # writes the scratch
    covariance_map(cam2, "basler1", step_px=2)
    *_, r2 = covariance_map(cam2, "basler1", get_reason=True)
    assert not np.shares_memory(r1, r2)
    np.testing.assert_array_equal(r1, keep)
    assert (r1 == status.ABOVE_HORIZON).any() and (r1 == status.OK).any()
    assert not np.array_equal(r1, r2)
