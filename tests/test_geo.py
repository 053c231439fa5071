"""Geo reference: true north, WGS84 (pyproj) and GeoJSON output."""

from __future__ import annotations

import json

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from footprint_uq import ErrorBudget, InputError, PanTiltCamera
from footprint_uq.batch.process import process_file, process_table
from footprint_uq.products.footprints import footprints_from_boxes3d, footprints_from_corners
from footprint_uq.products.geo import GeoReference, footprints_geojson, write_geojson
from footprint_uq.products.v2x import cpm_fields, j2735_fields
from footprint_uq.uncertainty.ellipse import chi2_scale, ellipse_axes, ellipse_ring

pyproj = pytest.importorskip("pyproj")


def test_heading_offset_rotation_pinned():
    g = GeoReference(heading_offset_deg=90.0)  # world +y points east
    assert np.allclose(g.world_to_enu([[0.0, 1.0], [1.0, 0.0]]), [[1.0, 0.0], [0.0, -1.0]])
    g = GeoReference(heading_offset_deg=30.0, origin_world_m=(10.0, 5.0))
    en = g.world_to_enu([[10.0, 7.0]])  # 2 m along world +y = bearing 30 deg
    assert np.allclose(en, [[2 * np.sin(np.pi / 6), 2 * np.cos(np.pi / 6)]])
    assert np.allclose(g.enu_to_world(en), [[10.0, 7.0]])
    # an axis along world x (orientation 0 deg) has bearing 90 + 30
    assert g.bearing_deg(0.0) == pytest.approx(120.0)
    C = np.array([[4.0, 0.0], [0.0, 1.0]])
    assert np.allclose(np.linalg.eigvalsh(g.cov_to_enu(C)), [1.0, 4.0])


def test_wgs84_pinned_at_the_equator():
    g = GeoReference(origin_lat_deg=0.0, origin_lon_deg=0.0)
    lat, lon = g.to_wgs84([[0.0, 1000.0], [0.0, 0.0]])
    # WGS84 meridian arc at the equator: 110574.27 m per degree
    assert lat[0] == pytest.approx(1000.0 / 110574.27, rel=1e-6) and abs(lon[0]) < 1e-12
    assert lat[1] == pytest.approx(0.0, abs=1e-12)


def test_wgs84_distances_and_bearings_match_geodesics(rng):
    g = GeoReference(heading_offset_deg=-25.0, origin_lat_deg=42.2807, origin_lon_deg=-83.7430,
                     origin_world_m=(3.0, -4.0))
    xy = rng.uniform(-500, 500, (50, 2))
    lat, lon = g.to_wgs84(xy)
    geod = pyproj.Geod(ellps="WGS84")
    az, _, dist = geod.inv(np.full(50, g.origin_lon_deg), np.full(50, g.origin_lat_deg), lon, lat)
    en = g.world_to_enu(xy)
    assert np.allclose(dist, np.hypot(en[:, 0], en[:, 1]), rtol=1e-6)
    assert np.allclose(np.mod(az, 360.0), np.mod(np.degrees(np.arctan2(en[:, 0], en[:, 1])), 360.0), atol=1e-6)
    assert np.allclose(g.from_wgs84(lat, lon), xy, atol=1e-6)
    lat_n, lon_n = g.to_wgs84([[np.nan, 1.0]])
    assert np.isnan(lat_n[0]) and np.isnan(lon_n[0])


def test_geojson_feature_collection(tmp_path):
    cam = PanTiltCamera(1400.0, (1920, 1080), 8.0, 30.0, 15.0)
    hv = float(cam.horizon_v_px(960.0))
    boxes = np.array([[5.0, 25.0, 0.75, 4.5, 1.8, 1.5, 0.3], [0.0, 30.0, 0.7, 4.0, 2.0, 1.4, 1.0]])
    g = GeoReference(heading_offset_deg=12.0, origin_lat_deg=48.1, origin_lon_deg=11.6)
    est = footprints_from_boxes3d(cam, "basler1", boxes, heading_offset_deg=12.0)
    fc = footprints_geojson(est, g, object_ids=np.array([7, 8]), properties=[{"class": "car"}, {"class": "van"}])
    assert fc["type"] == "FeatureCollection" and len(fc["features"]) == 6
    assert [f["properties"]["role"] for f in fc["features"]] == ["footprint", "centroid", "ellipse"] * 2
    poly, pt = fc["features"][0], fc["features"][1]
    assert poly["geometry"]["type"] == "Polygon" and pt["geometry"]["type"] == "Point"
    ring = np.array(poly["geometry"]["coordinates"][0])
    assert ring.shape == (5, 2) and np.array_equal(ring[0], ring[-1])
    x, y = ring[:-1, 0], ring[:-1, 1]
    assert np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y) > 0  # counter-clockwise (RFC 7946)
    p = poly["properties"]
    assert p["object_id"] == 7 and p["class"] == "car" and p["role"] == "footprint"
    assert pt["properties"]["role"] == "centroid"
    want = {**cpm_fields(est.centre_cov_m2, 12.0), **j2735_fields(est.centre_cov_m2, 12.0)}
    for k, v in want.items():
        assert p[k] == int(v[0])
    lat, lon = g.to_wgs84(est.centre_xy_world_m[:1])
    assert pt["geometry"]["coordinates"] == pytest.approx([lon[0], lat[0]])
    assert p["semi_major_95pct_m"] == pytest.approx(2.4477 * p["semi_major_1sigma_m"], rel=1e-4)
    assert 0.0 <= p["orientation_deg_from_north"] < 180.0
    # an object with a corner above the horizon: null geometry, reasons, no NaN in the JSON
    corners = np.array([[[900.0, 900.0], [1000.0, 900.0], [1000.0, hv - 50.0], [900.0, 800.0]]])
    bad = footprints_from_corners(cam, "basler1", corners)
    fc2 = footprints_geojson(bad, g)
    assert fc2["features"][0]["geometry"] is None and fc2["features"][1]["geometry"] is None
    assert fc2["features"][0]["properties"]["corner_reasons"][2].startswith("above horizon")
    assert fc2["features"][0]["properties"]["cpm_x_confidence"] == 4096
    path = write_geojson(tmp_path / "f.geojson", fc2)
    assert json.loads(path.read_text())["features"][0]["properties"]["semi_major_1sigma_m"] is None


def test_bad_input():
    with pytest.raises(InputError, match="^origin_lat_deg"):
        GeoReference(origin_lat_deg=95.0, origin_lon_deg=0.0)
    with pytest.raises(InputError, match="both or neither"):
        GeoReference(origin_lat_deg=45.0)
    with pytest.raises(InputError, match="^GeoReference"):
        GeoReference(heading_offset_deg=10.0).to_wgs84([[0.0, 0.0]])
    with pytest.raises(InputError, match="^heading_offset_deg"):
        GeoReference(heading_offset_deg=float("nan"))
    est = footprints_from_corners(PanTiltCamera(1400.0, (1920, 1080), 8.0, 30.0, 15.0), ErrorBudget(),
                                  np.full((1, 4, 2), 900.0) + np.array([[0, 0], [10, 0], [10, 10], [0, 10]]))
    with pytest.raises(InputError, match="^object_ids"):
        footprints_geojson(est, GeoReference(0.0, 1.0, 2.0), object_ids=[1, 2])


# -- the 95 % ellipses as polygons ---------------------------------------------------------------------------
def _quad(ring, centre, cov):
    """``d^T C^-1 d`` of every vertex (the squared Mahalanobis radius)."""
    d = np.asarray(ring) - np.asarray(centre)
    return np.einsum("...i,...ij,...j->...", d, np.linalg.inv(cov), d)


def _signed_area(x, y):
    return 0.5 * np.sum(x[:-1] * y[1:] - x[1:] * y[:-1])


def test_ellipse_ring_pinned():
    """diag(4, 1) at (1, 2), 95 %: the first vertex is the major axis' end (1 + 2k, 2), a quarter turn later the
    minor axis' end (1, 2 + k), counter-clockwise; closed; the polygon's area within 0.2 % of pi a b."""
    k = chi2_scale(0.95)
    r = ellipse_ring([1.0, 2.0], np.diag([4.0, 1.0]), confidence=0.95, n=64)
    assert r.shape == (65, 2) and np.array_equal(r[0], r[-1])
    assert r[0] == pytest.approx([1.0 + 2.0 * k, 2.0], abs=1e-15) and r[16] == pytest.approx([1.0, 2.0 + k], abs=1e-14)
    area = _signed_area(r[:, 0], r[:, 1])
    assert 0 < np.pi * 2 * k * k - area < 2e-3 * np.pi * 2 * k * k
    with pytest.raises(InputError, match="^n"):
        ellipse_ring([0.0, 0.0], np.eye(2), n=4)


@settings(max_examples=80, deadline=None)
@given(sx=st.floats(1e-2, 1e2), sy=st.floats(1e-2, 1e2), rho=st.floats(-0.99, 0.99), p=st.floats(0.05, 0.999),
       cx=st.floats(-1e3, 1e3), cy=st.floats(-1e3, 1e3))
def test_ellipse_ring_vertices_on_the_ellipse(sx, sy, rho, p, cx, cy):
    # metre-scale sigmas within a km of the origin; beyond a condition number of 1e6 the 2x2 eigen-decomposition
    # itself loses ~eps * cond (ellipse_axes)
    cov = np.array([[sx * sx, rho * sx * sy], [rho * sx * sy, sy * sy]])
    lo, hi = np.linalg.eigvalsh(cov)
    assume(hi < 1e6 * lo)
    r = ellipse_ring([cx, cy], cov, confidence=p, n=32)
    k2 = chi2_scale(p) ** 2
    np.testing.assert_allclose(_quad(r, [cx, cy], cov), k2, rtol=1e-9)
    assert np.array_equal(r[0], r[-1]) and _signed_area(r[:, 0] - cx, r[:, 1] - cy) > 0
    a, b, _ = ellipse_axes(cov, confidence=p)
    d = np.hypot(r[:, 0] - cx, r[:, 1] - cy)
    assert d.max() == pytest.approx(a, rel=1e-9) and d.min() >= b * (1 - 1e-9)


def _ellipse_features_check(feats, georef, centres, covs, confidence):
    """RFC 7946 rings (closed, counter-clockwise, [lon, lat]) holding exactly the ring of the world frame (whose
    vertices lie on the ellipse to 1e-9: test_ellipse_ring_vertices_on_the_ellipse) put on WGS84; back in the
    world frame (the projection's round trip) within 1e-8 m of it."""
    lat0, lon0 = georef.origin_lat_deg, georef.origin_lon_deg
    for f, c, cov in zip(feats, centres, covs, strict=True):
        assert f["geometry"]["type"] == "Polygon" and len(f["geometry"]["coordinates"]) == 1
        ring = np.array(f["geometry"]["coordinates"][0])
        assert ring.shape == (65, 2) and np.array_equal(ring[0], ring[-1])
        assert np.all(np.abs(ring[:, 0] - lon0) < 0.01) and np.all(np.abs(ring[:, 1] - lat0) < 0.01)  # lon, lat
        assert _signed_area((ring[:, 0] - lon0) * np.cos(np.radians(lat0)), ring[:, 1] - lat0) > 0
        exact = ellipse_ring(c, cov, confidence=confidence, n=64)
        np.testing.assert_allclose(_quad(exact, c, cov), chi2_scale(confidence) ** 2, rtol=1e-9)
        lat, lon = georef.to_wgs84(exact)
        assert np.array_equal(ring[:-1], np.stack([lon, lat], -1)[:-1])
        assert np.abs(georef.from_wgs84(ring[:, 1], ring[:, 0]) - exact).max() < 1e-8


def test_batch_geojson_ellipse_polygons(tmp_path):
    cam = PanTiltCamera(1400.0, (1920, 1080), 8.0, 30.0, 15.0)
    rng = np.random.default_rng(5)
    n = 12
    d, a = rng.uniform(15.0, 60.0, n), np.deg2rad(30.0 + rng.uniform(-20.0, 20.0, n))
    uv = cam.project(np.stack([d * np.sin(a), d * np.cos(a), np.zeros(n)], 1)).uv_px
    boxes = {"u_min_px": uv[:, 0] - 20, "v_min_px": uv[:, 1] - 40, "u_max_px": uv[:, 0] + 20, "v_max_px": uv[:, 1]}
    boxes["v_max_px"][3] = np.nan  # an error row: no ellipse
    pq.write_table(pa.table(boxes), tmp_path / "d.parquet")
    g = GeoReference(heading_offset_deg=25.0, origin_lat_deg=48.15, origin_lon_deg=11.58)
    out = tmp_path / "o.geojson"
    process_file(cam, "basler1", tmp_path / "d.parquet", out, progress=False, origin_lat_deg=48.15,
                 origin_lon_deg=11.58, heading_offset_deg=25.0, confidence=0.9)
    feats = [f for f in json.loads(out.read_text())["features"] if f["properties"]["role"] == "ellipse"]
    assert [f["properties"]["row"] for f in feats] == [i for i in range(n) if i != 3]
    assert all(f["properties"]["ellipse_confidence"] == 0.9 for f in feats)
    ref = process_table(cam, "basler1", boxes)
    rows = [f["properties"]["row"] for f in feats]
    col = {c: ref.column(c).to_numpy()[rows] for c in ("x_m", "y_m", "cov_xx_m2", "cov_xy_m2", "cov_yy_m2")}
    centres = np.stack([col["x_m"], col["y_m"]], -1)
    covs = np.stack([np.stack([col["cov_xx_m2"], col["cov_xy_m2"]], -1),
                     np.stack([col["cov_xy_m2"], col["cov_yy_m2"]], -1)], -2)
    _ellipse_features_check(feats, g, centres, covs, 0.9)


def test_footprints_geojson_ellipse_polygons():
    cam = PanTiltCamera(1400.0, (1920, 1080), 8.0, 30.0, 15.0)
    boxes = np.array([[5.0, 25.0, 0.75, 4.5, 1.8, 1.5, 0.3], [0.0, 30.0, 0.7, 4.0, 2.0, 1.4, 1.0]])
    g = GeoReference(heading_offset_deg=12.0, origin_lat_deg=48.1, origin_lon_deg=11.6)
    est = footprints_from_boxes3d(cam, "basler1", boxes, heading_offset_deg=12.0)
    fc = footprints_geojson(est, g)
    feats = [f for f in fc["features"] if f["properties"]["role"] == "ellipse"]
    assert len(feats) == 2 and feats[0]["properties"]["ellipse_confidence"] == 0.95
    _ellipse_features_check(feats, g, est.centre_xy_world_m, est.centre_cov_m2, 0.95)
    assert len(footprints_geojson(est, g, ellipse_polygons=False)["features"]) == 4
