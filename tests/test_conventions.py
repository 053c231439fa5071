"""docs/conventions.md: every number of the worked example is recomputed through the library.

The page holds a fenced block between ``<!-- worked-example:begin -->`` and
``<!-- worked-example:end -->`` with lines ``name = value``.  Each value is
compared with :func:`worked_example` at the precision printed (half a unit of
the last printed digit), and every name must be known: the page cannot print a
number that this test does not check.  Regenerate the block with
``python tests/test_conventions.py`` after a deliberate change.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

from footprint_uq import PanTiltCamera, chi2_scale, ellipse_axes, propagate
from footprint_uq.cameras.pantilt import paper_xy
from footprint_uq.cameras.rotation import R_G_P, R_P_C, R_W_C, R_W_G
from footprint_uq.uncertainty.ellipse import heading_deg

DOC = Path(__file__).resolve().parents[1] / "docs" / "conventions.md"

# the example camera and pixel (stated in the page's prose as well)
CAM = {"focal_px": 1400.0, "image_size_px": (1920, 1080), "height_m": 8.0, "pan_deg": 30.0, "tilt_deg": 20.0,
       "roll_deg": 0.0, "position_m": (10.0, 20.0)}
UV = (1200.0, 800.0)
BUDGET = "basler1"


def worked_example() -> dict:
    """name -> value (float or nested list), computed with the library."""
    cam = PanTiltCamera(**CAM)
    f = cam.focal_px
    cx, cy = cam.principal_point_px
    u, v = UV
    h = cam.height_m
    alpha, theta, phi = np.deg2rad([CAM["pan_deg"], CAM["tilt_deg"], CAM["roll_deg"]])
    out: dict = {}
    out["cx_px"], out["cy_px"] = cx, cy
    c, r = u - cx, v - cy
    out["c_px"], out["r_px"] = c, r
    ray_C = np.array([c / f, r / f, 1.0])
    out["ray_C"] = ray_C
    ray_P = R_P_C @ ray_C
    out["ray_P"] = ray_P
    out["R_G_P"] = R_G_P(alpha, theta, phi)
    ray_G = out["R_G_P"] @ ray_P
    out["ray_G"] = ray_G
    lam = h / ray_G[2]  # ray_P has x = 1: lam is the depth along the boresight
    out["depth_m"] = lam
    out["D_m"] = lam * np.linalg.norm(ray_P)  # the paper's D
    out["P_G_m"] = lam * ray_G  # (X, Y, Z = h)
    X, Y, ok = paper_xy(f, c, r, h, alpha, theta)
    assert ok
    out["paper_XY_m"] = np.array([X, Y])
    out["R_W_C"] = R_W_C(alpha, theta, phi)
    out["ray_W"] = out["R_W_C"] @ ray_C
    bp = cam.backproject(np.array(UV), get_gradients=True)
    assert bp.valid
    out["xy_world_m"] = bp.xy_world_m
    R = out["R_W_C"].T
    C = cam.position_world_m
    t = -R @ C
    out["R_cam_world"] = R
    out["t_cam_world_m"] = t
    x_world = np.array([bp.xy_world_m[0], bp.xy_world_m[1], 0.0])
    out["x_cam_m"] = R @ x_world + t
    out["uv_reprojected_px"] = cam.project(x_world).uv_px
    out["dxy_duv_m_per_px"] = bp.dxy_duv
    est = propagate(cam, BUDGET, np.array(UV))
    out["cov_m2"] = est.cov_m2
    a, b, ang = ellipse_axes(est.cov_m2)
    out["sigma_major_m"], out["sigma_minor_m"], out["orientation_deg"] = a, b, ang
    out["major_axis_bearing_deg"] = heading_deg(ang)
    out["chi2_scale_95"] = chi2_scale(0.95)
    out["semi_major_95_m"] = ellipse_axes(est.cov_m2, confidence=0.95)[0]
    # roll: the same camera rolled by +5 deg
    cam5 = PanTiltCamera(**{**CAM, "roll_deg": 5.0})
    hv = cam5.horizon_v_px(np.array([-0.5, 1919.5]))
    out["roll5_horizon_v_left_px"], out["roll5_horizon_v_right_px"] = hv
    out["roll5_xy_world_m"] = cam5.backproject(np.array(UV)).xy_world_m
    return {k: np.asarray(v, dtype=np.float64) for k, v in out.items()}


# -- formatting / parsing of the block ----------------------------------------------------------
_DECIMALS = {"R_G_P": 6, "R_W_C": 6, "R_cam_world": 6, "cov_m2": 6, "chi2_scale_95": 4}


def _fmt(name, value) -> str:
    d = _DECIMALS.get(name, 6 if np.all(np.abs(value) < 100) else 4)
    if value.ndim == 0:
        return f"{value:.{d}f}"
    return "[" + ", ".join(_fmt(name, x) for x in value) + "]"


def render_block() -> str:
    return "\n".join(f"{k:<26} = {_fmt(k, v)}" for k, v in worked_example().items())


_NUM = re.compile(r"-?\d+(?:\.(\d+))?(?:[eE][-+]?\d+)?")


def parse_block(text: str) -> dict:
    m = re.search(r"<!-- worked-example:begin -->\s*```text\n(.*?)```\s*<!-- worked-example:end -->", text, re.S)
    assert m, "docs/conventions.md lacks the worked-example block"
    out = {}
    for line in m.group(1).splitlines():
        line = line.split("#", 1)[0].strip()
        if not line:
            continue
        name, _, val = line.partition("=")
        nums = [(float(t.group(0)), len(t.group(1) or "")) for t in _NUM.finditer(val)]
        out[name.strip()] = nums
    return out


def test_block_matches_library():
    printed = parse_block(DOC.read_text(encoding="utf-8"))
    ref = worked_example()
    assert set(printed) == set(ref), f"unchecked or missing names: {set(printed) ^ set(ref)}"
    for name, nums in printed.items():
        want = ref[name].ravel()
        assert len(nums) == want.size, name
        for (got, dec), w in zip(nums, want, strict=True):
            assert abs(got - w) <= 0.5 * 10.0 ** (-dec) * (1 + 1e-9) + 1e-12, (name, got, w)


def test_closed_form_equals_general_path():
    ex = worked_example()
    # the paper's (X north, Y east) and the world point (x east, y north)
    X, Y = ex["paper_XY_m"]
    np.testing.assert_allclose(ex["P_G_m"][:2], [X, Y], rtol=1e-12)
    np.testing.assert_allclose(ex["P_G_m"][2], CAM["height_m"], rtol=1e-12)
    np.testing.assert_allclose(ex["xy_world_m"], [CAM["position_m"][0] + Y, CAM["position_m"][1] + X], rtol=1e-12)
    # the ray in W is the ray in G with (north, east, down) -> (east, north, up)
    np.testing.assert_allclose(ex["ray_W"], R_W_G @ ex["ray_G"], rtol=1e-12)
    # OpenCV: x_cam = R x_world + t is the ray scaled to the depth
    np.testing.assert_allclose(ex["x_cam_m"], ex["depth_m"] * ex["ray_C"], rtol=1e-12)
    np.testing.assert_allclose(ex["uv_reprojected_px"], UV, atol=1e-9)


def test_hand_checked_values():
    ex = worked_example()
    assert ex["c_px"] == 240.5 and ex["r_px"] == 260.5
    # pan 30 deg, tilt 20 deg: the boresight in W is (sin 30 cos 20, cos 30 cos 20, -sin 20)
    a, t = np.deg2rad(30.0), np.deg2rad(20.0)
    np.testing.assert_allclose(ex["R_W_C"][:, 2], [np.sin(a) * np.cos(t), np.cos(a) * np.cos(t), -np.sin(t)],
                               atol=1e-15)
    # image columns (x_C) point to the right of the heading: (cos 30, -sin 30, 0)
    np.testing.assert_allclose(ex["R_W_C"][:, 0], [np.cos(a), -np.sin(a), 0.0], atol=1e-15)
    assert ex["chi2_scale_95"] == pytest.approx(np.sqrt(-2 * np.log(0.05)), rel=1e-15)
    assert ex["chi2_scale_95"] == pytest.approx(2.4477, abs=5e-5)


def test_roll_sign_stated_in_the_page():
    """Positive roll: the camera turns clockwise seen from behind, the scene turns counter-clockwise in the image."""
    ex = worked_example()
    assert ex["roll5_horizon_v_right_px"] < ex["roll5_horizon_v_left_px"]  # right end of the horizon is higher
    slope_deg = np.degrees(np.arctan2(ex["roll5_horizon_v_left_px"] - ex["roll5_horizon_v_right_px"], 1920.0))
    assert slope_deg == pytest.approx(5.0, abs=0.3)
    text = DOC.read_text(encoding="utf-8")
    assert "counter-clockwise in the image" in text


if __name__ == "__main__":  # print the block for docs/conventions.md
    print(render_block())
