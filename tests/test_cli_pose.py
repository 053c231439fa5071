"""A newcomer's command line: a pose for every camera (options, pose file, `camera compose`), budgets without
extrinsic terms named, help for every option, usage on a missing command, one map step, linearity on everywhere,
usable map summaries (issue 24)."""

from __future__ import annotations

import json
from pathlib import Path

import click
import numpy as np
import pytest
from click.testing import CliRunner

from footprint_uq import propagate
from footprint_uq.cli.common import DEFAULT_STEP_PX
from footprint_uq.cli.main import main
from footprint_uq.io import load_camera, save_budget
from footprint_uq.uncertainty.budget import load_budget
from footprint_uq.uncertainty.presets import PRESET_NAMES

DATA = Path(__file__).parent / "data" / "cameras"
INTRINSICS = DATA / "opencv_calibration.yaml"  # OpenCV calibration output: intrinsics only
POSE = {"height_m": 6.5, "pan_deg": 30.0, "tilt_deg": 12.0, "roll_deg": 0.5, "position_m": [12.0, -3.5]}
POSE_ARGS = ["--height-m", 6.5, "--pan-deg", 30, "--tilt-deg", 12, "--roll-deg", 0.5, "--position-m", 12, -3.5]
PIXELS = np.array([[960.0, 1000.0], [300.0, 900.0]])


def run(*args):
    return CliRunner().invoke(main, [str(a) for a in args], prog_name="footprint-uq")


def _locate(*args):
    pix = [a for u, v in PIXELS for a in ("--pixel", u, v)]
    r = run("locate", "--budget", "basler1", *pix, *args)
    assert r.exit_code == 0, r.output
    return json.loads(r.stdout)


def test_intrinsics_only_file_needs_a_pose_and_names_the_options():
    r = run("locate", "--camera", INTRINSICS, "--budget", "basler1", "--pixel", 960, 1000)
    assert r.exit_code == 2
    assert "--pose-file" in r.stderr and "--height-m" in r.stderr and "camera compose" in r.stderr


@pytest.mark.parametrize("how", ["options", "pose-file", "compose"])
def test_pose_from_the_command_line_equals_the_api(tmp_path, how):
    ref_cam = load_camera(INTRINSICS, pose=POSE)
    if how == "options":
        recs = _locate("--camera", INTRINSICS, *POSE_ARGS)
    elif how == "pose-file":
        recs = _locate("--camera", INTRINSICS, "--pose-file", DATA / "pose.yaml")
    else:
        out = tmp_path / "full.yaml"
        r = run("camera", "compose", "--intrinsics", INTRINSICS, *POSE_ARGS, "--out", out)
        assert r.exit_code == 0, r.output
        assert "6.500 m above the ground" in r.stdout
        np.testing.assert_array_equal(load_camera(out).params, ref_cam.params)  # exact round trip
        recs = _locate("--camera", out)
    est = propagate(ref_cam, "basler1", PIXELS)
    got = np.array([[r["x_m"], r["y_m"]] for r in recs])
    np.testing.assert_allclose(got, est.xy_world_m, rtol=1e-12, atol=1e-9)
    np.testing.assert_allclose([r["cov_m2"] for r in recs], est.cov_m2, rtol=1e-12, atol=1e-15)


@pytest.mark.parametrize("args, field", [
    (["--height-m", 6.5, "--pan-deg", 30], "--tilt-deg"),  # incomplete
    (["--roll-deg", 1], "--height-m"),  # a roll alone is no pose
    (["--pose-file", DATA / "pose.yaml", "--tilt-deg", 12], "--tilt-deg"),  # two poses
    (["--height-m", -1, "--pan-deg", 30, "--tilt-deg", 12], "height_m"),  # below the ground
])
def test_bad_pose_options_exit_2_in_one_line(args, field):
    r = run("locate", "--camera", INTRINSICS, "--budget", "basler1", "--pixel", 960, 1000, *args)
    assert r.exit_code == 2
    assert len(r.stderr.strip().splitlines()) == 1 and field in r.stderr


def test_a_pose_on_a_file_that_has_one_is_refused(tmp_path):
    r = run("locate", "--camera", DATA / "pantilt.yaml", "--budget", "basler1", "--pixel", 960, 1000, *POSE_ARGS)
    assert r.exit_code == 2 and "pose" in r.stderr
    r = run("camera", "compose", "--intrinsics", INTRINSICS, "--out", tmp_path / "x.yaml")
    assert r.exit_code == 2 and "--pose-file" in r.stderr and not (tmp_path / "x.yaml").exists()


def test_budget_without_extrinsic_terms_is_named_on_stderr_and_in_the_record(tmp_path):
    intrinsic_only = tmp_path / "budget.yaml"  # what `calibrate intrinsics` writes: intrinsic sigmas only
    save_budget({"name": "calibrated", "focal_px": 0.6, "principal_point_px": [0.3, 0.2],
                 "distortion": [1e-3, 2e-3, 1e-4, 1e-4, 2e-3]}, intrinsic_only)
    assert load_budget(intrinsic_only).missing_terms() == ("extrinsic", "ground")
    pix = ["--pixel", 960, 1000]
    r = run("locate", "--camera", DATA / "pantilt.yaml", "--budget", intrinsic_only, *pix)
    assert r.exit_code == 0
    assert "warning" in r.stderr and "no extrinsic or ground error terms" in r.stderr
    assert json.loads(r.stdout)[0]["budget_missing_terms"] == ["extrinsic", "ground"]
    # the paper's presets have pose terms (no ground terms: recorded, no warning)
    r = run("locate", "--camera", DATA / "pantilt.yaml", "--budget", "basler1", *pix)
    assert r.exit_code == 0 and "warning" not in r.stderr
    assert json.loads(r.stdout)[0]["budget_missing_terms"] == ["ground"]
    for name in PRESET_NAMES:
        assert "extrinsic" not in load_budget(name).missing_terms()
    assert load_budget({"ground_height_m": 0.1, "tilt_deg": 0.01}).missing_terms() == ()


def _commands(cmd, path=()):
    ctx = click.Context(main)
    yield path, cmd
    if isinstance(cmd, click.Group):
        for name in cmd.list_commands(ctx):
            yield from _commands(cmd.get_command(ctx, name), (*path, name))


def test_every_option_has_help_text():
    bare = [(" ".join(path), p.opts[0]) for path, cmd in _commands(main) for p in cmd.params
            if isinstance(p, click.Option) and not p.hidden and not p.help]
    assert bare == []


@pytest.mark.parametrize("args", [[], ["calibrate"], ["camera"], ["carla"]])
def test_a_missing_command_prints_the_usage_not_one_flattened_line(args):
    r = run(*args)
    assert r.exit_code == 2
    lines = r.stderr.splitlines()
    assert lines[0].startswith("Usage: footprint-uq")
    assert "Commands:" in lines and len(lines) > 5
    assert lines[-1].startswith("footprint-uq: error: missing command")


def test_one_step_and_linearity_on_everywhere():
    ctx = click.Context(main)
    defaults = {name: {p.name: p.default for p in main.get_command(ctx, name).params}
                for name in ("map", "demo", "objects", "serve")}
    assert defaults["map"]["step_px"] == defaults["demo"]["step_px"] == DEFAULT_STEP_PX
    assert defaults["map"]["linearity"] is defaults["objects"]["linearity"] is defaults["serve"]["linearity"] is True
    readme = (Path(__file__).parents[1] / "README.md").read_text(encoding="utf-8")
    assert "--step-px" not in readme or f"--step-px {DEFAULT_STEP_PX}" in readme


def test_map_summary_without_a_range_reports_usable_figures(tmp_path):
    r = run("map", "--camera", DATA / "pantilt.yaml", "--budget", "basler1", "--out", tmp_path, "--step-px", 16)
    assert r.exit_code == 0, r.output
    s = json.loads((tmp_path / "summary.json").read_text())
    assert s["semi_major_m_max"] > 1e4  # pixels just below the horizon
    assert s["semi_major_m_p90"] <= s["semi_major_m_p95"] <= s["semi_major_m_p99"] <= s["semi_major_m_max"]
    near = {w["range_m"]: w for w in s["within_range"]}
    assert 0.1 < near[50.0]["semi_major_m_max"] <= near[100.0]["semi_major_m_max"] <= near[200.0]["semi_major_m_max"]
    assert near[200.0]["semi_major_m_max"] < 50
    assert "largest within 50 m" in r.stdout and "--max-range-m" in r.stdout
