"""A camera's perception region (products/perception_region.py): where its 95 % ellipse's semi-major axis is at
most a limit, as a polygon of at most 16 vertices (the CPM's PolygonalShape).

Checked against the numpy reference path (``propagate``, not the kernel the region is computed with): every point
inside the polygon meets the limit, every point farther outside than the reported gap does not; a nadir camera with
pixel noise only (ground covariance (h/f)^2 sigma^2 I everywhere, by hand) gives its whole footprint or nothing.
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from matplotlib.path import Path as MplPath

from footprint_uq import PanTiltCamera, ellipse_axes, propagate
from footprint_uq.errors import InputError
from footprint_uq.products.perception_region import (
    CPM_MAX_POLYGON_VERTICES,
    perception_region,
    polygon_east_north_cm,
)
from footprint_uq.uncertainty.budget import ErrorBudget
from footprint_uq.uncertainty.ellipse import chi2_scale

CAM = PanTiltCamera(focal_px=1400.0, image_size_px=(1920, 1080), height_m=8.0, pan_deg=30.0, tilt_deg=20.0)


def _semi_major_reference(cam, budget, xy):
    """95 % semi-major axis by the reference path (inf where the camera does not see the point)."""
    pr = cam.project_ground(xy)
    W, H = cam.image_size_px
    uv = pr.uv_px
    seen = pr.valid & (uv[:, 0] >= 0) & (uv[:, 0] <= W) & (uv[:, 1] >= 0) & (uv[:, 1] <= H)
    out = np.full(len(xy), np.inf)
    if np.any(seen):
        est = propagate(cam, budget, uv[seen])
        a, _, _ = ellipse_axes(est.cov_m2, confidence=0.95)
        out[seen] = np.where(est.valid, a, np.inf)
    return out


def _samples(poly, rng, n, grow_m):
    lo, hi = poly.min(0) - grow_m, poly.max(0) + grow_m
    return lo + (hi - lo) * rng.random((n, 2))


def _dist_to_polygon(p, poly):
    a, b = poly, np.roll(poly, -1, 0)
    ab = b - a
    t = np.clip(np.einsum("nmk,mk->nm", p[:, None] - a[None], ab) / np.einsum("mk,mk->m", ab, ab), 0, 1)
    return np.min(np.linalg.norm(p[:, None] - (a[None] + t[..., None] * ab[None]), axis=-1), axis=1)


@pytest.mark.parametrize("limit_m", [1.0, 2.0])
def test_inside_meets_the_limit_and_far_outside_does_not(limit_m):
    r = perception_region(CAM, "basler1", max_semi_major_m=limit_m)
    poly = r.polygon_xy_world_m
    assert 3 <= len(poly) <= CPM_MAX_POLYGON_VERTICES
    assert r.area_m2 > 0 and 0.85 <= r.coverage <= 1.0 + 1e-9
    assert r.max_semi_major_inside_m <= limit_m
    p = _samples(poly, np.random.default_rng(7), 6000, grow_m=10.0)
    inside = MplPath(poly).contains_points(p)
    a = _semi_major_reference(CAM, "basler1", p)
    assert inside.sum() > 300
    assert np.all(a[inside] <= limit_m * (1 + 1e-9)), np.max(a[inside])
    far = ~inside & (_dist_to_polygon(p, poly) > r.outside_gap_m + 1.5 * r.cell_m)
    assert far.sum() > 300
    assert np.all(a[far] > limit_m), "a point beyond the reported gap meets the limit"


def test_nadir_camera_with_pixel_noise_only_by_hand():
    """Looking straight down, ground = h/f x (pixel - principal point): cov = (h/f)^2 sigma^2 I everywhere, so the
    region is the whole footprint (8 m x 6 m) when k95 h sigma / f is within the limit, else empty."""
    cam = PanTiltCamera(focal_px=1000.0, image_size_px=(800, 600), height_m=10.0, pan_deg=0.0, tilt_deg=90.0)
    budget = ErrorBudget(imaging_px=(1.0, 1.0))
    semi = chi2_scale(0.95) * 10.0 * 1.0 / 1000.0  # 0.02448 m
    assert perception_region(cam, budget, max_semi_major_m=0.98 * semi) is None
    r = perception_region(cam, budget, max_semi_major_m=1.02 * semi)
    assert r is not None and r.max_semi_major_inside_m == pytest.approx(semi, rel=1e-6)
    assert 0.95 * 48.0 <= r.area_m2 <= 48.0
    centre = cam.backproject(np.array([[399.5, 299.5]])).xy_world_m[0]  # under the camera (pixel centres)
    half = np.abs(r.polygon_xy_world_m - centre).max(0)
    assert sorted(half) == pytest.approx([3.0, 4.0], abs=0.1)


def test_no_pixel_meets_the_limit_is_none_and_bad_arguments_are_named():
    assert perception_region(CAM, "basler1", max_semi_major_m=0.05) is None
    for kw, field in [({"max_semi_major_m": float("nan")}, "max_semi_major_m"),
                      ({"max_semi_major_m": -1.0}, "max_semi_major_m"),
                      ({"confidence": 1.0}, "confidence"), ({"max_vertices": 2}, "max_vertices"),
                      ({"cell_m": float("inf")}, "cell_m")]:
        with pytest.raises(InputError, match=field):
            perception_region(CAM, "basler1", **kw)


def test_east_north_offsets_follow_the_site_bearing():
    poly = np.array([[1.0, 2.0], [3.0, 2.0], [3.0, 5.0]])
    assert polygon_east_north_cm(poly, [1.0, 2.0]).tolist() == [[0, 0], [200, 0], [200, 300]]
    # world +y pointing east (bearing 90 deg): +y -> east, +x -> south
    assert polygon_east_north_cm(poly, [1.0, 2.0], 90.0).tolist() == [[0, 0], [0, -200], [300, -200]]


@settings(max_examples=12, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(height_m=st.floats(4.0, 20.0), tilt_deg=st.floats(10.0, 60.0), pan_deg=st.floats(-180.0, 180.0),
       limit_m=st.floats(0.3, 4.0))
def test_any_camera_gives_a_cpm_polygon_inside_its_region(height_m, tilt_deg, pan_deg, limit_m):
    cam = PanTiltCamera(focal_px=1400.0, image_size_px=(1920, 1080), height_m=height_m, pan_deg=pan_deg,
                        tilt_deg=tilt_deg)
    r = perception_region(cam, "basler1", max_semi_major_m=limit_m, max_cells=200)
    if r is None:
        return
    poly = r.polygon_xy_world_m
    assert 3 <= len(poly) <= CPM_MAX_POLYGON_VERTICES and r.area_m2 > 0
    p = _samples(poly, np.random.default_rng(1), 1500, grow_m=0.0)
    inside = MplPath(poly).contains_points(p)
    assert np.all(_semi_major_reference(cam, "basler1", p[inside]) <= limit_m * (1 + 1e-9))


def test_a_concave_region_gets_a_polygon_inside_it(monkeypatch):
    """A five-pointed star of a region (semi-major = r / R(theta), R = 10 (1 + 0.4 cos 5 theta)): 16 vertices cannot
    follow it, and a simplified outline cuts across its notches unless the fit erodes and checks; the polygon must
    stay inside anyway (a dense check of the analytic field)."""
    import footprint_uq.products.perception_region as pr

    def field(xy):
        xy = np.asarray(xy, dtype=float)
        r, th = np.hypot(xy[..., 0], xy[..., 1]), np.arctan2(xy[..., 1], xy[..., 0])
        return r / (10.0 * (1.0 + 0.4 * np.cos(5.0 * th)))

    monkeypatch.setattr(pr, "semi_major_at", lambda camera, budget, xy, confidence=0.95: field(xy))
    monkeypatch.setattr(pr, "_ground_bounds", lambda *a, **k: (-15.0, -15.0, 15.0, 15.0))
    r = pr.perception_region(CAM, "basler1", max_semi_major_m=1.0, max_cells=300)
    poly = r.polygon_xy_world_m
    assert len(poly) <= 16 and r.erosion_cells >= 1
    g = np.stack(np.meshgrid(np.linspace(-15, 15, 601), np.linspace(-15, 15, 601)), -1).reshape(-1, 2)
    inside = MplPath(poly).contains_points(g)
    assert inside.sum() > 1000 and np.all(field(g[inside]) <= 1.0)
    edge = np.concatenate([a + np.linspace(0, 1, 200)[:, None] * (b - a) for a, b in zip(poly, np.roll(poly, -1, 0),
                                                                                          strict=True)])
    assert np.all(field(edge) <= 1.0)
