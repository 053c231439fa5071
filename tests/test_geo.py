"""Geo reference: true north, WGS84 (pyproj) and GeoJSON output."""

from __future__ import annotations

import json

import numpy as np
import pytest

from footprint_uq import ErrorBudget, InputError, PanTiltCamera
from footprint_uq.products.footprints import footprints_from_boxes3d, footprints_from_corners
from footprint_uq.products.geo import GeoReference, footprints_geojson, write_geojson
from footprint_uq.products.v2x import cpm_fields, j2735_fields

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
