"""The paper's case-study statements as tests that can fail (footprint_uq.scenario.claims).

Tolerances are the module's constants (fixed before the results were looked at).  For
each statement: the verdict of the default scene under both readings of Table 3's angles,
and a configuration under which it FAILS (``claims.FAILING_EXAMPLES``).
"""

from __future__ import annotations

import numpy as np
import pytest

from footprint_uq.scenario import CaseStudyConfig, analyse, build_scene
from footprint_uq.scenario import claims as C


def _run(config: dict | None = None, reading: str = ""):
    cfg = CaseStudyConfig.from_dict(config or {})
    types = {k: (v + reading if isinstance(v, str) else v) for k, v in cfg.camera_types.items()}
    return analyse(build_scene(cfg), types)


@pytest.fixture(scope="module")
def default_results():
    return {"printed": _run(), "deg": _run(reading="@deg")}


def _claim(result, cid):
    return next(c for c in C.evaluate_claims(result) if c["id"] == cid)


def test_tolerances_are_the_stated_ones():
    assert C.XY_MAJORITY == 0.8 and C.XY_MIDDLE == (1 / 3, 2 / 3) and C.LANE_BAND == 0.25
    assert C.RANK_MARGIN == 1.10 and C.XY_AXES == "north-east" and C.FARTHEST_SHARE == 0.9


@pytest.mark.parametrize("reading", ["printed", "deg"])
def test_xy_sequence_camera1_passes_camera2_fails(default_results, reading):
    c = _claim(default_results[reading], "xy_sequence")
    assert c["per_camera"] == {"camera1": "PASS", "camera2": "FAIL"} and c["verdict"] == "FAIL"
    d = {(x["camera"], x["camera_type"]): x for x in c["details"]}
    for ct in default_results[reading].type_names:
        cam1 = d[("camera1", ct)]
        assert cam1["share_X_gt_Y_entry"] >= 0.8 and cam1["share_Y_gt_X_exit"] >= 0.8
        assert 1 / 3 <= cam1["crossing_position_in_junction"] <= 2 / 3
        # camera 2 looks roughly south: north (X) dominates far down the exit lane
        assert d[("camera2", ct)]["share_Y_gt_X_exit"] < 0.5


@pytest.mark.parametrize("reading", ["printed", "deg"])
def test_lane_width_passes_with_one_measure(default_results, reading):
    c = _claim(default_results[reading], "lane_width")
    assert c["verdict"] == "PASS"
    for p in c["details"]:
        assert 0.75 * 3.5 <= p["value_m"] <= 1.25 * 3.5
        # the measure is twice the junction median of the BW-Cube centre sigma_major
        r = default_results[reading].rows(p["camera"], p["camera_type"])
        x0, y0, x1, y1 = default_results[reading].scene.layout.junction_box_m
        inside = r.box_x_m.between(x0, x1) & r.box_y_m.between(y0, y1) & r.centre_valid
        assert p["value_m"] == pytest.approx(2 * np.median(r.centre_semi_major_m[inside]), rel=1e-12)


def test_ranking_fails_in_both_readings_for_different_reasons(default_results):
    printed = _claim(default_results["printed"], "ranking")
    deg = _claim(default_results["deg"], "ranking")
    assert printed["verdict"] == deg["verdict"] == "FAIL"
    for p in printed["details"]:
        # as printed BW-Bullet1's smaller height error puts it below Basler1
        assert p["ratio_to_basler"]["bw-bullet1"] < 1.0 and not p["basler_lowest"]
        assert p["ratio_to_basler"]["bw-cube1"] > 4.0
    for p in deg["details"]:
        # read as degrees Basler ranks best, as the paper says, but BW-Bullet1 is only ~2 % above it
        assert p["basler_lowest"] and 1.0 < p["ratio_to_basler"]["bw-bullet1"] < 1.10
        assert p["ratio_to_basler"]["bw-cube1"] > 4.0


@pytest.mark.parametrize("cid", sorted(C.FAILING_EXAMPLES))
def test_failing_example_fails(cid):
    ex = C.FAILING_EXAMPLES[cid]
    c = _claim(_run(ex["config"]), cid)
    assert c["verdict"] == "FAIL", c["why"]
    assert ex["why"]


def test_roles_and_missing_types():
    assert C.type_roles(["basler1@deg", "bw-cube1", "mine"]) == {"basler1": "basler1@deg", "bw-cube1": "bw-cube1"}
    r = _run({"camera_types": ["basler1"]})
    lw = _claim(r, "lane_width")
    rk = _claim(r, "ranking")
    assert lw["verdict"] == "FAIL" and "no BW-Cube" in lw["why"]
    assert rk["verdict"] == "FAIL" and "lacks" in rk["why"]


@pytest.mark.parametrize("reading", ["printed", "deg"])
def test_farthest_corner_is_the_most_uncertain(default_results, reading):
    c = _claim(default_results[reading], "farthest_corner")
    assert c["verdict"] == "PASS"
    for p in c["details"]:
        assert min(p["share_farthest_is_largest"].values()) >= 0.9
