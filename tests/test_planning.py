"""The site planner (footprint_uq.planning): site file, occlusion, fused requirement, optimiser, refinement.

The small site below has 48 candidate configurations (3 mounts x 2 lenses x 2 tilts x 4 pans) and
576 ground samples: small enough for an exhaustive search over every pair of cameras.
"""

from __future__ import annotations

import itertools
from pathlib import Path

import numpy as np
import pytest
import yaml
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from footprint_uq.errors import ConfigError, InputError
from footprint_uq.planning.coverage import (
    CameraConfig,
    build_camera,
    camera_information,
    evaluate_information,
    semi_major_from_info,
)
from footprint_uq.planning.geometry import ground_samples, occluded, points_in_polygon
from footprint_uq.planning.optimise import (
    Objective,
    candidate_grid,
    greedy,
    layout_information,
    milp_select,
    plan,
    precompute,
    refine,
)
from footprint_uq.planning.site import load_site, site_from_dict
from footprint_uq.products.fusion import fuse_by_id
from footprint_uq.uncertainty.ellipse import ellipse_axes
from footprint_uq.uncertainty.propagation import propagate


def small_site_dict(req_m: float = 0.5) -> dict:
    return {
        "resolution_m": 1.0,
        "zones": [{"name": "road", "polygon_m": [[-20, -6], [20, -6], [20, 6], [-20, 6]], "max_semi_major_m": req_m},
                  {"name": "crossing", "polygon_m": [[-4, -6], [4, -6], [4, 6], [-4, 6]],
                   "max_semi_major_m": req_m / 2, "weight": 3}],
        "occluders": [{"name": "kiosk", "polygon_m": [[8, 8], [12, 8], [12, 12], [8, 12]], "height_m": 4}],
        "mounts": [{"name": "a", "position_m": [-22, 9], "height_m": [6, 9]},
                   {"name": "b", "position_m": [22, 9], "height_m": [6, 9], "cost": 2},
                   {"name": "c", "position_m": [0, -10], "height_m": 7, "existing": True}],
        "cameras": [{"name": "hd", "image_size_px": [640, 360], "budget": "basler1", "cost": 1,
                     "lenses": [{"name": "n", "focal_px": 500},
                                {"name": "w", "focal_px": 350, "dist": [-0.1, 0.01, 0, 0, 0]}]}],
        "search": {"pan_step_deg": 90, "tilts_deg": [20, 35], "heights_per_mount": 1, "max_cameras": 2},
    }


@pytest.fixture(scope="module")
def small():
    """(site, samples, configs, coverage) of the small site with the 0.5 m requirement."""
    site = site_from_dict(small_site_dict(0.5))
    samples = ground_samples(site)
    configs = candidate_grid(site)
    return site, samples, configs, precompute(site, samples, configs)


def _exhaustive(cov, obj, k, max_cost=None):
    best, arg = -1.0, None
    for combo in itertools.combinations(range(len(cov.configs)), k):
        if len(set(cov.mount[list(combo)])) < k or (max_cost is not None and cov.cost[list(combo)].sum() > max_cost):
            continue
        v = obj.value([(cov.index[c], cov.info[c]) for c in combo])
        if v > best:
            best, arg = v, combo
    return best, arg


def _value(cov, obj, picks):
    return obj.value([(cov.index[c], cov.info[c]) for c in picks])


# -- site file ---------------------------------------------------------------------------------------------------
def test_site_file_round_trip(tmp_path):
    p = tmp_path / "site.yaml"
    p.write_text(yaml.safe_dump(small_site_dict()))
    site = load_site(p)
    assert [z.name for z in site.zones] == ["road", "crossing"]
    assert site.zones[1].weight == 3 and site.zones[1].max_semi_major_m == 0.25
    assert site.mount("c").height_range_m == (7.0, 7.0) and site.mount("c").existing
    assert site.cameras[0].lenses[1].dist == (-0.1, 0.01, 0.0, 0.0, 0.0)
    assert len(candidate_grid(site)) == 3 * 2 * 2 * 4


def test_site_file_latlon_matches_metres():
    pytest.importorskip("pyproj")
    from footprint_uq.products.geo import GeoReference

    d = small_site_dict()
    g = GeoReference(origin_lat_deg=48.15, origin_lon_deg=11.57)
    poly = np.array(d["zones"][0]["polygon_m"], dtype=float)
    lat, lon = g.to_wgs84(poly)
    d["origin"] = {"lat_deg": 48.15, "lon_deg": 11.57}
    d["zones"][0] = {**{k: v for k, v in d["zones"][0].items() if k != "polygon_m"},
                     "polygon_latlon": np.stack([lat, lon], -1).tolist()}
    la, lo = g.to_wgs84(np.array([[-22.0, 9.0]]))
    d["mounts"][0] = {**{k: v for k, v in d["mounts"][0].items() if k != "position_m"},
                      "position_latlon": [float(la[0]), float(lo[0])]}
    site = site_from_dict(d)
    np.testing.assert_allclose(site.zones[0].polygon_m, poly, atol=1e-6)
    np.testing.assert_allclose(site.mount("a").position_m, (-22.0, 9.0), atol=1e-6)


def _set(d, path, value):
    keys = path.split(".")
    for k in keys[:-1]:
        d = d[int(k)] if k.isdigit() else d[k]
    if value is _DEL:
        del d[keys[-1]]
    else:
        d[keys[-1]] = value


_DEL = object()


@pytest.mark.parametrize("path, value, field, expected", [
    ("zones", _DEL, "zones", "required"),
    ("zones.0.max_semi_major_m", -1, "zones[0].max_semi_major_m", "> 0"),
    ("zones.0.max_semi_major_mm", 1, "zones[0].max_semi_major_mm", "max_semi_major_m"),
    ("zones.1.polygon_m", [[0, 0], [1, 1]], "zones[1].polygon_m", "at least 3"),
    ("zones.1.polygon_m", [[0, 0], [1, 1], [2, 2]], "zones[1].polygon_m", "enclosing"),
    ("zones.1.name", "road", "zones[1].name", "not used"),
    ("zones.0.weight", 0, "zones[0].weight", "> 0"),
    ("occluders.0.height_m", "tall", "occluders[0].height_m", "a number"),
    ("mounts.0.height_m", [9, 6], "mounts[0].height_m", "min <= max"),
    ("mounts.1.position_m", [1, 2, 3], "mounts[1].position_m", "2 numbers"),
    ("mounts.2.existing", "yes", "mounts[2].existing", "true or false"),
    ("mounts.0.position_latlon", [48, 11], "mounts[0].position_m", "exactly one"),
    ("cameras.0.budget", "no-such-preset", "cameras[0].budget", "preset"),
    ("cameras.0.image_size_px", [640], "cameras[0].image_size_px", "[width, height]"),
    ("cameras.0.lenses.1.dist", [0.1, 0.2, 0.3], "cameras[0].lenses[1].dist", "distortion"),
    ("cameras.0.lenses", [], "cameras[0].lenses", "at least 1"),
    ("search.max_cameras", 0, "search.max_cameras", "integer >= 1"),
    ("search.tilts_deg", [20, 95], "search.tilts_deg[1]", "<= 89.5"),
    ("search.pan_step_deg", 0, "search.pan_step_deg", ">= 1.0"),
    ("search.heights_per_mount", 100000, "search", "candidate grid of at most"),
    ("zones.0.polygon_m", [[0, 0], [1e7, 0], [0, 5]], "zones[0].polygon_m", "magnitude <= 1e+06"),
    ("resolution_m", 0.001, "resolution_m", "cells over the site"),
])
def test_site_file_bad_input_names_the_field(tmp_path, path, value, field, expected):
    d = small_site_dict()
    _set(d, path, value)
    p = tmp_path / "bad site.yaml"
    p.write_text(yaml.safe_dump(d))
    with pytest.raises(ConfigError) as e:
        load_site(p)
    msg = str(e.value)
    assert "\n" not in msg and msg.startswith(f"{p}: {field}:") and expected in msg, msg


def test_site_file_latlon_needs_an_origin():
    d = small_site_dict()
    d["zones"][0]["polygon_latlon"] = [[48.0, 11.0], [48.001, 11.0], [48.001, 11.001]]
    del d["zones"][0]["polygon_m"]
    with pytest.raises(ConfigError, match=r"zones\[0\]\.polygon_latlon: .*origin"):
        site_from_dict(d)


def test_site_file_not_yaml(tmp_path):
    p = tmp_path / "s.yaml"
    p.write_text("zones: [unclosed\n")
    with pytest.raises(ConfigError, match=r"s.yaml: line 2, column 1: got .*valid YAML syntax"):
        load_site(p)


# -- geometry ----------------------------------------------------------------------------------------------------
def test_points_in_polygon_concave():
    L = np.array([[0, 0], [4, 0], [4, 1], [1, 1], [1, 4], [0, 4]], dtype=float)
    pts = np.array([[0.5, 0.5], [3, 0.5], [0.5, 3], [3, 3], [2, 2], [-1, 0.5]])
    assert points_in_polygon(pts, L).tolist() == [True, True, True, False, False, False]


class _Box:
    def __init__(self, x0, y0, x1, y1, h):
        self.polygon_m = np.array([[x0, y0], [x1, y0], [x1, y1], [x0, y1]], dtype=float)
        self.height_m = h


def test_occlusion_geometric():
    """Camera 10 m above the origin, a 5 m building over x in [10, 20], y in [-5, 5]."""
    b = [_Box(10, -5, 20, 5, 5.0)]
    pts = np.array([[30.0, 0.0],   # behind: the sight line crosses the wall x = 20 at 10/30 of its length, 3.3 m < 5 m
                    [15.0, 0.0],   # under the building
                    [8.0, 0.0],    # in front of it
                    [30.0, 20.0],  # beside it: the sight line misses the footprint
                    [21.0, 0.0]])  # just behind: crosses x = 20 at 1/21, 0.48 m
    assert occluded(pts, (0, 0, 10.0), b).tolist() == [True, True, False, False, True]
    # from 100 m the sight line to (30, 0) passes the wall x = 20 at 33 m, above the roof; (21, 0) at 4.8 m: blocked
    assert occluded(pts, (0, 0, 100.0), b).tolist() == [False, True, False, False, True]
    # a building taller than the camera blocks everything behind it
    assert occluded(pts, (0, 0, 4.0), [_Box(10, -5, 20, 5, 50.0)]).tolist() == [True, True, False, False, True]


def test_camera_information_leaves_out_occluded_samples():
    d = small_site_dict()
    d["occluders"] = [{"name": "wall", "polygon_m": [[-2, -7], [2, -7], [2, -6.5], [-2, -6.5]], "height_m": 6}]
    site = site_from_dict(d)
    s = ground_samples(site)
    cfg = CameraConfig("c", "hd", "n", 7.0, 0.0, 20.0)  # mount c at (0, -10), looking north over the wall
    cam = build_camera(site, cfg)
    idx_open, _ = camera_information(cam, "basler1", s.xy_world_m)
    idx, _ = camera_information(cam, "basler1", s.xy_world_m, site.occluders)
    hidden = np.setdiff1d(idx_open, idx)
    assert hidden.size > 20 and set(idx) <= set(idx_open)
    assert occluded(s.xy_world_m[hidden], cam.position_world_m, site.occluders).all()
    assert not occluded(s.xy_world_m[idx], cam.position_world_m, site.occluders).any()


# -- covariances -------------------------------------------------------------------------------------------------
def test_information_is_the_propagated_covariance(small):
    site, s, _, _ = small
    cam = build_camera(site, CameraConfig("a", "hd", "w", 6.0, 90.0, 20.0))
    idx, info = camera_information(cam, "basler1", s.xy_world_m)
    assert idx.size > 50
    pick = idx[:: max(1, idx.size // 7)]
    uv = cam.project_ground(s.xy_world_m[pick]).uv_px
    res = propagate(cam, "basler1", uv)
    I = np.linalg.inv(res.cov_m2)
    got = info[np.searchsorted(idx, pick)]
    np.testing.assert_allclose(got, np.stack([I[:, 0, 0], I[:, 0, 1], I[:, 1, 1]], -1), rtol=1e-7)
    np.testing.assert_allclose(res.xy_world_m, s.xy_world_m[pick], atol=1e-7)


def test_fused_requirement_matches_the_fusion_module(small):
    site, s, _, _ = small
    cams = [CameraConfig("a", "hd", "n", 6.0, 90.0, 20.0), CameraConfig("b", "hd", "w", 9.0, 270.0, 20.0)]
    infos = layout_information(site, s, cams)
    common = np.intersect1d(infos[0][0], infos[1][0])
    assert common.size > 30
    covs, ids = [], []
    for idx, info in infos:
        I = info[np.searchsorted(idx, common)]
        covs.append(np.linalg.inv(np.stack([np.stack([I[:, 0], I[:, 1]], -1), np.stack([I[:, 1], I[:, 2]], -1)], -2)))
        ids.append(common)
    fused = fuse_by_id(np.concatenate(ids), np.zeros((2 * common.size, 2)), np.concatenate(covs))
    ref_semi, _, _ = ellipse_axes(fused.cov_m2, confidence=0.95)
    ev = evaluate_information(site, s, infos)
    np.testing.assert_allclose(ev.semi_major_m[fused.object_id], ref_semi, rtol=1e-9)
    req = np.array([z.max_semi_major_m for z in site.zones])[s.zone[fused.object_id]]
    assert np.array_equal(ev.met[fused.object_id], ref_semi <= req)
    assert (ev.n_seen[common] == 2).all()
    # fusion helps: some samples are met only together
    single = [semi_major_from_info(i[np.searchsorted(x, common)]) for x, i in infos]
    assert np.any((ref_semi <= req) & (single[0] > req) & (single[1] > req))


# -- optimiser ---------------------------------------------------------------------------------------------------
@pytest.mark.parametrize("fusion", [True, False])
def test_milp_finds_the_exhaustive_optimum(small, fusion):
    site, s, _, cov = small
    obj = Objective.of(site, s, fusion=fusion)
    best, _ = _exhaustive(cov, obj, 2)
    picks = milp_select(cov, obj, 2)
    assert len(picks) <= 2 and len(set(cov.mount[picks])) == len(picks)
    assert _value(cov, obj, picks) == pytest.approx(best, abs=1e-9)
    assert best > 0


def test_milp_respects_the_cost_limit(small):
    site, s, _, cov = small
    obj = Objective.of(site, s)
    best, arg = _exhaustive(cov, obj, 2, max_cost=3.5)  # mount b costs 2 + camera 1: b and one more do not fit
    picks = milp_select(cov, obj, 2, max_cost=3.5)
    assert cov.cost[picks].sum() <= 3.5 and "b" not in {cov.configs[c].mount for c in picks}
    assert _value(cov, obj, picks) == pytest.approx(best, abs=1e-9)
    g = greedy(cov, obj, 2, max_cost=3.5)
    assert cov.cost[g].sum() <= 3.5 and 0 < _value(cov, obj, g) <= best


def test_greedy_single_camera_is_the_exhaustive_optimum_and_lazy_equals_full(small):
    site, s, _, cov = small
    for fusion in (True, False):
        obj = Objective.of(site, s, fusion=fusion)
        best1, _ = _exhaustive(cov, obj, 1)
        assert _value(cov, obj, greedy(cov, obj, 1, soft=False)) == pytest.approx(best1)
    obj = Objective.of(site, s, fusion=False)  # submodular: the lazy bound is exact
    assert greedy(cov, obj, 3, lazy=True) == greedy(cov, obj, 3, lazy=False)


def test_greedy_with_fusion_is_close_to_the_optimum_here(small):
    """No guarantee with fusion (not submodular); on this site the soft score reaches 95 % of the optimum
    where the met-area score alone stalls (no single camera meets the crossing's requirement)."""
    site, s, _, cov = small
    obj = Objective.of(site, s)
    best, _ = _exhaustive(cov, obj, 2)
    assert _value(cov, obj, greedy(cov, obj, 2)) >= 0.95 * best
    assert _value(cov, obj, greedy(cov, obj, 2, soft=False)) < 0.5 * best


def test_precompute_in_worker_processes_is_the_same(small):
    site, s, configs, cov = small
    par = precompute(site, s, configs, workers=2)
    for c in range(len(configs)):
        assert np.array_equal(par.index[c], cov.index[c])
        np.testing.assert_array_equal(par.info[c], cov.info[c])
    with pytest.raises(InputError, match="workers"):
        precompute(site, s, configs[:2], workers=0)


# -- refinement and the whole plan -------------------------------------------------------------------------------
def test_refinement_is_never_worse_and_reproducible(small):
    site, s, configs, _ = small
    obj = Objective.of(site, s)
    rng = np.random.default_rng(7)
    for _ in range(3):
        a, b = rng.choice(len(configs), 2, replace=False)
        start = [configs[a], configs[b]]
        out, v0, v1, n = refine(site, s, start, obj, seed=3, max_evals=25)
        assert v0 == pytest.approx(obj.value(layout_information(site, s, start)))
        assert v1 >= v0 and n <= 25
        assert v1 == pytest.approx(obj.value(layout_information(site, s, out)))
        for c in out:
            lo, hi = site.mount(c.mount).height_range_m
            assert lo <= c.height_m <= hi and 0 < c.tilt_deg < 90
    again = refine(site, s, start, obj, seed=3, max_evals=25)
    assert again[0] == out and again[2] == v1


def test_plan_end_to_end_is_reproducible():
    site = site_from_dict(small_site_dict(0.5))
    r1 = plan(site, seed=1, max_refine_evals=20)
    r2 = plan(site, seed=1, max_refine_evals=20)
    assert r1.configs == r2.configs and r1.value == r2.value
    assert r1.value >= r1.discrete_value > 0
    assert r1.evaluation.value == pytest.approx(r1.value)
    assert len({c.mount for c in r1.configs}) == len(r1.configs) <= 2
    with pytest.raises(InputError, match="method"):
        plan(site, method="annealing")


def test_the_site_file_of_the_docs_is_valid():
    """docs/planning.md's example site file loads (lat/lon included) and its lat/lon polygon lies near the origin."""
    pytest.importorskip("pyproj")
    text = (Path(__file__).resolve().parents[1] / "docs" / "planning.md").read_text(encoding="utf-8")
    block = text.split("```yaml\n", 1)[1].split("```", 1)[0]
    site = site_from_dict(yaml.safe_load(block))
    assert [z.name for z in site.zones] == ["lanes", "crossing"] and site.zones[1].weight == 3
    assert np.abs(site.zones[1].polygon_m).max() < 10 and len(candidate_grid(site)) == 2 * 2 * 2 * 3 * 12


def _slab_blocked(p, c, h_cam, x0, y0, x1, y1, H):
    """Independent reference for an axis-aligned box: Liang-Barsky clipping of the sight line p -> c."""
    d = (c[0] - p[0], c[1] - p[1])
    s_in, s_out = 0.0, 1.0
    for q0, dq, lo, hi in ((p[0], d[0], x0, x1), (p[1], d[1], y0, y1)):
        if dq == 0:
            if not lo <= q0 <= hi:
                return False
            continue
        a, b = (lo - q0) / dq, (hi - q0) / dq
        s_in, s_out = max(s_in, min(a, b)), min(s_out, max(a, b))
    return s_in <= s_out and s_in * h_cam < H


@settings(max_examples=300, deadline=None, derandomize=True)
@given(st.floats(-30, 30), st.floats(-30, 30), st.floats(1, 40), st.floats(-20, 20), st.floats(-20, 20),
       st.floats(0.5, 15), st.floats(0.5, 15), st.floats(0.5, 30), st.floats(0, 180))
def test_occlusion_matches_box_clipping_everywhere(px, py, h_cam, bx, by, w, d, H, rot_deg):
    """Property: for any box, point and camera height, in any orientation of the frame, the polygon test agrees
    with Liang-Barsky clipping of the sight line in the box's own frame (cases within 1e-6 of a tie skipped)."""
    x0, y0, x1, y1 = bx, by, bx + w, by + d
    c = (0.0, 0.0)
    ref = _slab_blocked((px, py), c, h_cam, x0, y0, x1, y1, H)
    near_tie = any(_slab_blocked((px, py), c, h_cam, x0 - e, y0 - e, x1 + e, y1 + e, H + f) != ref
                   for e in (-1e-6, 1e-6) for f in (-1e-6 * h_cam, 1e-6 * h_cam))
    assume(not near_tie)
    a = np.deg2rad(rot_deg)
    R = np.array([[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]])
    box = _Box(x0, y0, x1, y1, H)
    box.polygon_m = box.polygon_m @ R.T
    got = occluded((np.array([[px, py]]) @ R.T), (0.0, 0.0, h_cam), [box])[0]
    assert got == ref


def test_milp_refuses_a_grid_too_large_for_it(small, monkeypatch):
    from footprint_uq.planning import optimise

    site, s, _, cov = small
    monkeypatch.setattr(optimise, "MILP_MAX_WORK", 1000.0)
    with pytest.raises(InputError, match="method: .*milp.*greedy"):
        milp_select(cov, Objective.of(site, s), 2)


def test_milp_stopped_early_warns_and_plan_falls_back_to_greedy(small):
    site, s, _, cov = small
    with pytest.warns(RuntimeWarning, match="milp stopped before proving its optimum"):
        picks = milp_select(cov, Objective.of(site, s), 2, time_limit_s=1e-4)
    assert len(picks) <= 2
    r = plan(site, method="milp", time_limit_s=1e-4, refine_layout=False)
    greedy_only = plan(site, method="greedy", refine_layout=False)
    assert r.value >= greedy_only.value > 0
