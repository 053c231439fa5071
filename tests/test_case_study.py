"""Case study: per-frame analysis consistent with the API, per-source contributions, statements, report, CLI."""

from __future__ import annotations

import json
import re

import numpy as np
import pandas as pd
import pytest

from footprint_uq.products.footprints import footprints_from_boxes3d
from footprint_uq.scenario import AXIS_SYSTEMS, CaseStudyConfig, analyse, axis_components, build_scene
from footprint_uq.scenario.case_study import FootprintHeatmap, footprint_heatmap
from footprint_uq.uncertainty.budget import load_budget

SMALL = {"trajectory": {"frame_rate_hz": 2.0}, "heatmap": {"step_m": 4.0}}


@pytest.fixture(scope="module")
def result():
    return analyse(build_scene())


@pytest.fixture(scope="module")
def small_report(tmp_path_factory):
    from footprint_uq.viz.case_study_run import run_case_study

    out = tmp_path_factory.mktemp("case_study")
    paths = run_case_study(out, config=CaseStudyConfig.from_dict(SMALL), dpi=60)
    return out, paths


def test_table_shape_and_keys(result):
    t = result.table
    n = len(result.scene)
    assert len(t) == 2 * 3 * n
    assert t.groupby(["camera", "camera_type"]).size().eq(n).all()
    for col in ("box_x_m", "box_cam_z_m", "bbox_u_min_px", "corner3_sigma_y_m", "largest_semi_major_m",
                "centre_sigma_x_m", "centre_semi_major_95_m", "centre_sigma_X_camera_m", "centre_sigma_Y_range_m",
                "contrib_height_m2", "box_corner7_u_px", "v2x_cpm_x_confidence"):
        assert col in t.columns, col


def test_table_consistent_with_footprint_api(result):
    """Every CSV number for a frame is what the public API gives for that frame alone."""
    t = result.table
    scene = result.scene
    for cam_name, ct, k in (("camera1", "bw-cube1", 0), ("camera2", "basler1", 50), ("camera1", "bw-bullet1", 80)):
        cam = scene.cameras[cam_name]
        fp = footprints_from_boxes3d(cam, ct, scene.boxes_world[k:k + 1])
        row = t[(t.camera == cam_name) & (t.camera_type == ct) & (t.frame == k)].iloc[0]
        C = fp.centre_cov_m2[0]
        assert row.centre_sigma_x_m == pytest.approx(np.sqrt(C[0, 0]), rel=1e-12)
        assert row.centre_sigma_y_m == pytest.approx(np.sqrt(C[1, 1]), rel=1e-12)
        assert row.centre_cov_xy_m2 == pytest.approx(C[0, 1], rel=1e-10)
        assert row.centre_x_m == pytest.approx(fp.centre_xy_world_m[0, 0], rel=1e-12)
        assert row.largest_index == fp.largest_index[0]
        assert row.largest_semi_major_m == pytest.approx(fp.largest_semi_major_m[0], rel=1e-12)
        for j in range(4):
            assert row[f"corner{j}_u_px"] == pytest.approx(fp.corners_px[0, j, 0], rel=1e-12)
            assert row[f"corner{j}_sigma_x_m"] == pytest.approx(np.sqrt(fp.corners_cov_m2[0, j, 0, 0]), rel=1e-12)
        # 95 % semi-major = 2.4477 sigma (2-D chi-square), not 1.96
        assert row.centre_semi_major_95_m / row.centre_semi_major_m == pytest.approx(2.447746830680816, rel=1e-9)
        # box in the camera frame: z is the depth along the boresight, and projects to the image
        xyz = np.array([row.box_x_m, row.box_y_m, row.box_z_m])
        T = cam.T_cam_world
        np.testing.assert_allclose([row.box_cam_x_m, row.box_cam_y_m, row.box_cam_z_m], T[:3, :3] @ xyz + T[:3, 3],
                                   rtol=1e-12)


def test_contributions_add_up_and_match_single_source_budgets(result):
    scene = result.scene
    cam = scene.cameras["camera1"]
    full = load_budget("basler1")
    contrib = result.contributions[("camera1", "basler1")]
    fp = result.footprints[("camera1", "basler1")]
    total = sum(contrib.values())
    np.testing.assert_allclose(total, fp.centre_cov_m2, rtol=1e-9, atol=1e-15)
    # a budget with only the height error gives exactly the "height" contribution
    only_h = load_budget({"height_m": full.height_m})
    fp_h = footprints_from_boxes3d(cam, only_h, scene.boxes_world)
    np.testing.assert_allclose(contrib["height"], fp_h.centre_cov_m2, rtol=1e-9, atol=1e-15)
    only_img = load_budget({"imaging_px": list(full.imaging_px)})
    fp_i = footprints_from_boxes3d(cam, only_img, scene.boxes_world)
    np.testing.assert_allclose(contrib["imaging"], fp_i.centre_cov_m2, rtol=1e-9, atol=1e-20)
    # the CSV traces are these matrices' traces
    r = result.rows("camera1", "basler1")
    np.testing.assert_allclose(r["contrib_height_m2"], np.trace(contrib["height"], axis1=1, axis2=2), rtol=1e-12)


def test_axis_components_hand_checked():
    from footprint_uq import PanTiltCamera

    cov = np.array([[4.0, 1.0], [1.0, 9.0]])  # x east, y north
    cam = PanTiltCamera(1000, (1920, 1080), 8.0, 0.0, 20.0)  # looking north
    sx, sy = axis_components(cov, "world", cam)
    assert (sx, sy) == (2.0, 3.0)
    assert axis_components(cov, "north-east", cam) == (3.0, 2.0)
    assert axis_components(cov, "camera", cam) == pytest.approx((3.0, 2.0))  # along = north, across = east
    cam_e = PanTiltCamera(1000, (1920, 1080), 8.0, 90.0, 20.0)  # looking east
    assert axis_components(cov, "camera", cam_e) == pytest.approx((2.0, 3.0))
    cam45 = PanTiltCamera(1000, (1920, 1080), 8.0, 45.0, 20.0)
    a, c = axis_components(cov, "camera", cam45)
    assert a**2 == pytest.approx((4 + 9 + 2) / 2) and c**2 == pytest.approx((4 + 9 - 2) / 2)
    # range: along the line of sight from the camera foot
    assert axis_components(cov, "range", cam, np.array([0.0, 10.0])) == pytest.approx((3.0, 2.0))


def test_axis_components_preserve_trace(result):
    r = result.rows("camera2", "bw-cube1")
    tr = r.centre_sigma_x_m**2 + r.centre_sigma_y_m**2
    for system in (*AXIS_SYSTEMS, "range"):
        np.testing.assert_allclose(r[f"centre_sigma_X_{system}_m"] ** 2 + r[f"centre_sigma_Y_{system}_m"] ** 2, tr,
                                   rtol=1e-10)


def test_statements_follow_the_line_of_sight(result):
    """Camera 1 stands at the north-east corner looking south-west: the line of sight turns from
    north-south (approach) to east-west (exit), crossing 45 deg near the junction centre; the
    ellipse follows it, so with X = north the paper's sequence appears, with X = east it is reversed."""
    st = {(s["camera"], s["camera_type"], s["axes"]): s for s in result.statements()}
    for ct in result.type_names:
        ne = st[("camera1", ct, "north-east")]
        assert ne["holds"] and ne["crossing_in_junction"]
        x, y = ne["first_X_to_Y_crossing_xy_m"]
        assert abs(x) < 3.0 and abs(y) < 3.0
        w = st[("camera1", ct, "world")]
        assert not w["holds"] and w["share_X_gt_Y_entry"] == 0.0
    cr = result.crossings("camera1", "basler1", "north-east")
    assert len(cr) == 1 and cr[0]["direction"] == "X>Y to Y>X"


def test_crossings_interpolation_hand_made(result):
    from footprint_uq.scenario.case_study import _crossings

    r = pd.DataFrame({"t_s": [0.0, 1.0, 2.0, 3.0], "box_x_m": [0.0, 1.0, 2.0, 3.0], "box_y_m": 0.0,
                      "segment": [0, 1, 1, 2]})
    out = _crossings(r, np.array([1.0, 0.5, -0.5, np.nan]), result.scene.layout)
    assert len(out) == 1 and out[0]["t_s"] == pytest.approx(1.5) and out[0]["x_m"] == pytest.approx(1.5)
    # no interpolation across a gap
    assert _crossings(r, np.array([1.0, np.nan, -0.5, -1.0]), result.scene.layout) == []


def test_lane_width_statements(result):
    rows = result.lane_width_statements()
    cube = [s for s in rows if s["camera_type"] == "bw-cube1"]
    assert all(s["is_largest_type"] for s in cube)
    k = 2.447746830680816
    assert cube[1]["value_m"] == pytest.approx(cube[0]["value_m"] * k)
    assert cube[2]["value_m"] == pytest.approx(cube[0]["value_m"] * 2 * k)
    for s in rows:
        assert s["close"] == (1 / 1.5 <= s["value_m"] / 3.5 <= 1.5)


def test_heatmap_matches_single_box(result):
    cam = result.scene.cameras["camera1"]
    hm = footprint_heatmap(cam, "basler1", (-10, -10, 10, 10), step_m=5.0, yaw_deg=0.0)
    assert isinstance(hm, FootprintHeatmap) and hm.semi_major_m.shape == (5, 5)
    fp = footprints_from_boxes3d(cam, "basler1", np.array([[5.0, -5.0, 0.75, 4.8, 1.9, 1.5, 0.0]]))
    from footprint_uq import ellipse_axes

    assert hm.semi_major_m[1, 3] == pytest.approx(ellipse_axes(fp.centre_cov_m2)[0][0], rel=1e-12)
    # behind the camera: not in view -> NaN
    hm2 = footprint_heatmap(cam, "basler1", (20, 20, 30, 30), step_m=5.0)
    assert np.isnan(hm2.semi_major_m).all()


def test_report_written_with_every_figure(small_report):
    out, paths = small_report
    res = paths["result"]
    kinds = ("view", "birdseye", "sigma", "contributions", "heatmap")
    expected = {f"{c}_{k}" for c in res.camera_names for k in kinds}
    assert set(paths["figures"]) == expected
    for p in paths["figures"].values():
        data = p.read_bytes()
        assert data[:8] == b"\x89PNG\r\n\x1a\n" and len(data) > 10_000
    html = paths["report"].read_text()
    assert html.count('src="data:image/png;base64,') == len(expected) + 1  # the first view also leads the page
    assert html.index('<section class="lead">') < html.index("<h2>") and "How to read the verdicts" in html
    # self-contained: no external resources
    assert not re.search(r'(src|href)\s*=\s*"(https?:)?//', html)
    assert "<script" not in html.lower()
    # the verdicts in the text are the computed ones
    st = [s for s in res.statements() if s["camera"] == "camera1" and s["axes"] == "north-east"]
    verdict = "<b>reproduced</b>" if all(s["holds"] for s in st) else "not reproduced"
    assert f"camera1, X = north, Y = east: {verdict}" in html
    summary = json.loads(paths["summary"].read_text())
    assert len(summary["summary"]) == 6 and len(summary["xy_statements"]) == 18
    # the paper's statements with their verdicts, and the link to the reproduction page
    from footprint_uq.scenario.claims import evaluate_claims

    claims = evaluate_claims(res)
    assert [c["id"] for c in summary["claims"]] == ["xy_sequence", "lane_width", "ranking", "farthest_corner"]
    for c in claims:
        assert f"<b>{c['verdict']}</b>" in html
    assert [c["verdict"] for c in summary["claims"]] == [c["verdict"] for c in claims]
    if paths.get("reproduction") is not None:
        assert 'href="paper-reproduction.md"' in html and paths["reproduction"].is_file()


def test_csv_round_trip(small_report):
    out, paths = small_report
    res = paths["result"]
    back = pd.read_csv(paths["csv"])
    assert list(back.columns) == list(res.table.columns)
    num = res.table.select_dtypes("number").columns
    np.testing.assert_allclose(back[num].to_numpy(float), res.table[num].to_numpy(float), rtol=1e-8, atol=1e-12)


def _cli():
    from footprint_uq.cli.main import main

    return main


def test_cli_case_study_on_a_recording(tmp_path):
    """The command end to end, on a recording of our own (small) scenario: same numbers as the generator."""
    from click.testing import CliRunner

    from footprint_uq.integrations.carla.bridge import scene_to_recording

    cfg = CaseStudyConfig.from_dict(SMALL)
    scene = build_scene(cfg)
    rec = scene_to_recording(scene, tmp_path / "small.jsonl")
    res = CliRunner().invoke(_cli(), ["case-study", "--out", str(tmp_path / "out"), "--recording", str(rec),
                                      "--camera-type", "basler1", "--dpi", "50"])
    assert res.exit_code == 0, res.output
    assert (tmp_path / "out" / "report.html").exists()
    assert len(list((tmp_path / "out").glob("*.png"))) == 10
    assert "report:" in res.output
    back = pd.read_csv(tmp_path / "out" / "case_study_frames.csv")
    ref = analyse(scene, ["basler1"]).table
    np.testing.assert_allclose(back["centre_sigma_x_m"], ref["centre_sigma_x_m"], rtol=1e-8)
    np.testing.assert_allclose(back["contrib_height_m2"], ref["contrib_height_m2"], rtol=1e-8)


def test_cli_case_study_bad_config(tmp_path):
    import subprocess
    import sys

    cfg = tmp_path / "cfg.json"
    cfg.write_text(json.dumps({"trajectory": {"speed_kmh": 30}}))
    code = "import sys; from footprint_uq.cli.main import main; main(sys.argv[1:])"
    p = subprocess.run([sys.executable, "-c", code, "case-study", "--out", str(tmp_path / "o"), "--config", str(cfg)],
                       capture_output=True, text=True, timeout=120)
    assert p.returncode == 2
    lines = p.stderr.strip().splitlines()
    assert len(lines) == 1 and "speed_kmh" in lines[0]


def test_contributions_with_correlated_sources_have_cross_terms():
    from footprint_uq.scenario.case_study import centre_contributions

    scene = build_scene(CaseStudyConfig.from_dict(SMALL))
    cam = scene.cameras["camera1"]
    budget = load_budget({"height_m": 0.2, "imaging_px": [0.1, 0.1],
                          "covariance": {"names": ["height_m", "tilt_deg"],
                                         "matrix": [[0.04, 0.8 * 0.2 * 0.05], [0.8 * 0.2 * 0.05, 0.0025]]}})
    fp = footprints_from_boxes3d(cam, budget, scene.boxes_world)
    c = centre_contributions(cam, budget, fp)
    assert {"height", "tilt", "imaging", "cross_terms"} <= set(c)
    np.testing.assert_allclose(sum(c.values()), fp.centre_cov_m2, rtol=1e-9, atol=1e-15)
    assert np.abs(c["cross_terms"]).max() > 1e-3 * np.abs(fp.centre_cov_m2).max()


def test_nothing_in_view_is_reported_not_invented(tmp_path):
    import warnings

    from footprint_uq.viz.case_study import write_case_study_report

    cfg = CaseStudyConfig.from_dict({**SMALL, "camera_types": ["basler1"],
                                     "cameras": [{"name": "away", "position_m": [9, 9], "pan_deg": 45}]})
    res = analyse(build_scene(cfg), cfg.camera_types)
    assert not res.table["centre_valid"].any()
    assert res.table["centre_sigma_x_m"].isna().all() and res.table["contrib_height_m2"].isna().all()
    assert not any(s["holds"] for s in res.statements())
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)
        paths = write_case_study_report(res, tmp_path, heatmap=cfg.heatmap, dpi=40)
    assert "not testable" in paths["report"].read_text()


def test_linearity_flag_columns(result):
    from footprint_uq.uncertainty.propagation import nonlinearity

    r = result.rows("camera2", "bw-cube1")
    cam = result.scene.cameras["camera2"]
    i = int(np.flatnonzero(r.centre_valid.to_numpy())[0])
    uv = np.array([[r.loc[i, f"corner{k}_u_px"], r.loc[i, f"corner{k}_v_px"]] for k in range(4)])
    nl = nonlinearity(cam, result.budgets["bw-cube1"], uv)
    np.testing.assert_allclose([r.loc[i, f"corner{k}_nonlinearity"] for k in range(4)], nl, rtol=1e-12)
    assert r.loc[i, "footprint_nonlinearity_max"] == pytest.approx(nl.max(), rel=1e-12)
    assert bool(r.loc[i, "footprint_linear_ok"]) == bool(nl.max() <= 0.05)
    # frames whose centre is not available are never flagged linear
    assert not r.footprint_linear_ok[~r.centre_valid].any()
    s = {(x["camera"], x["camera_type"]): x for x in result.summary()}
    assert s[("camera2", "bw-cube1")]["frames_not_linear_ok"] == int(
        np.sum(r.centre_valid & ~r.footprint_linear_ok))


def test_camera_names_from_data_never_leave_the_output_folder(tmp_path):
    """A camera name with '/' and '..' (from a recording) is percent-encoded in the figure names."""
    from footprint_uq.viz.case_study import write_case_study_report

    cfg = CaseStudyConfig.from_dict({**SMALL, "camera_types": ["basler1"],
                                     "cameras": [{"name": "a/../../evil", "position_m": [9, 9], "pan_deg": 45}]})
    res = analyse(build_scene(cfg), cfg.camera_types)
    out = tmp_path / "out"
    paths = write_case_study_report(res, out, heatmap=cfg.heatmap, dpi=30)
    written = sorted(p.name for p in out.iterdir())
    assert all(p.parent == out for p in paths["figures"].values())
    assert not (tmp_path / "evil_view.png").exists() and not list(tmp_path.glob("*.png"))
    assert any(n.startswith("a%2F..%2F..%2Fevil") for n in written), written
    assert not [n for n in written if n.startswith(".")]  # no temporary file left
