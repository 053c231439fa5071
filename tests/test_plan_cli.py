"""``footprint-uq plan``: the layout files, the report, ``--evaluate``, bad input; the sensitivity table."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import urllib.request

import numpy as np
import pytest
import yaml
from click.testing import CliRunner

from footprint_uq.cli.main import main
from footprint_uq.io import load_camera
from footprint_uq.planning.coverage import CameraConfig, build_camera
from footprint_uq.planning.geometry import ground_samples
from footprint_uq.planning.layout import (
    LayoutCamera,
    evaluate_cameras,
    layout_from_configs,
    perturbed_camera,
    read_layout,
    sensitivity,
)
from footprint_uq.planning.site import load_site
from test_planning import small_site_dict


@pytest.fixture(scope="module")
def planned(tmp_path_factory):
    d = tmp_path_factory.mktemp("plan")
    site = d / "site.yaml"
    site.write_text(yaml.safe_dump(small_site_dict()))
    out = d / "out"
    r = CliRunner().invoke(main, ["plan", "--site", str(site), "--out", str(out), "--no-progress",
                                  "--max-refine-evals", "15", "--seed", "2"])
    assert r.exit_code == 0, r.output
    return site, out, r.output


def test_plan_writes_camera_files_usable_everywhere(planned):
    site_path, out, text = planned
    site = load_site(site_path)
    doc = yaml.safe_load((out / "layout.yaml").read_text())
    assert 1 <= len(doc["cameras"]) <= 2
    summary = json.loads((out / "plan.json").read_text())
    for e in doc["cameras"]:
        cam = load_camera(out / e["camera_file"])
        cfg = next(CameraConfig(**c) for c in summary["cameras"] if c["mount"] == e["mount"])
        np.testing.assert_allclose(cam.params, build_camera(site, cfg).params, rtol=1e-12, atol=1e-12)
    assert summary["refined_value_m2"] >= summary["discrete_value_m2"]
    assert f"weighted met area {100 * summary['fraction_met']:.1f} %" in text
    html = (out / "report.html").read_text()
    assert html.count("<img") == 2 + 1 + len(site.zones) and "Sensitivity" in html


def test_evaluate_reproduces_the_plan(planned, tmp_path):
    site_path, out, _ = planned
    r = CliRunner().invoke(main, ["plan", "--site", str(site_path), "--evaluate", str(out / "layout.yaml"),
                                  "--out", str(tmp_path), "--no-sensitivity"])
    assert r.exit_code == 0, r.output
    ev = json.loads((tmp_path / "evaluation.json").read_text())
    plan = json.loads((out / "plan.json").read_text())
    assert ev["fraction_met"] == pytest.approx(plan["fraction_met"], abs=1e-12)
    assert ev["zones"] == plan["zones"]


@pytest.mark.parametrize("change, field", [
    ({"zones": [{"name": "z", "polygon_m": [[0, 0], [1, 0], [1, 1]], "max_semi_major_m": "wide"}]},
     "zones[0].max_semi_major_m"),
    ({"mounts": []}, "mounts"),
    ({"surprise": 1}, "surprise"),
])
def test_bad_site_file_exits_2_in_one_line(tmp_path, change, field):
    p = tmp_path / "site.yaml"
    p.write_text(yaml.safe_dump({**small_site_dict(), **change}))
    r = CliRunner().invoke(main, ["plan", "--site", str(p), "--out", str(tmp_path / "o"), "--no-progress"])
    assert r.exit_code == 2, r.output
    line = r.output.strip()
    assert "\n" not in line and f"{p}: {field}:" in line and "Traceback" not in line


def test_bad_layout_exits_2(planned, tmp_path):
    site_path, out, _ = planned
    doc = yaml.safe_load((out / "layout.yaml").read_text())
    doc["cameras"][0]["budget"] = "no-such-budget"
    doc["cameras"][0]["camera_file"] = str(out / doc["cameras"][0]["camera_file"])
    bad = tmp_path / "layout.yaml"
    bad.write_text(yaml.safe_dump(doc))
    r = CliRunner().invoke(main, ["plan", "--site", str(site_path), "--evaluate", str(bad), "--out", str(tmp_path)])
    assert r.exit_code == 2 and "cameras[0].budget" in r.output and "\n" not in r.output.strip()
    r = CliRunner().invoke(main, ["plan", "--site", str(site_path)])
    assert r.exit_code == 2 and "--out" in r.output


def test_perturbed_camera_equals_the_moved_configuration(planned):
    site = load_site(planned[0])
    for lens in ("n", "w"):  # pan-tilt and OpenCV (distorted) models
        cfg = CameraConfig("a", "hd", lens, 6.5, 100.0, 25.0)
        moved = perturbed_camera(build_camera(site, cfg), height_m=1.0, tilt_deg=2.0, pan_deg=-5.0)
        ref = build_camera(site, cfg.replace(height_m=7.5, tilt_deg=27.0, pan_deg=95.0))
        assert type(moved) is type(ref)
        np.testing.assert_allclose(moved.params, ref.params, rtol=1e-12, atol=1e-12)


def test_sensitivity_rows(planned):
    site = load_site(planned[0])
    samples = ground_samples(site)
    cams = read_layout(planned[1] / "layout.yaml", site)
    rows = sensitivity(site, samples, cams)
    base = evaluate_cameras(site, samples, cams)[0].fraction
    assert rows[0]["fraction_met"] == pytest.approx(base)
    assert [r["change"] for r in rows if r["camera"] == "all"] == ["as planned", "height +1 m", "height -1 m",
                                                                    "tilt +2 deg", "tilt -2 deg", "budget sigmas x2"]
    assert len(rows) == 6 + 4 * len(cams)
    # doubling every sigma doubles every semi-major axis: the met area can only shrink
    assert rows[-1]["fraction_met"] <= base
    assert all(abs(r["delta_points"] - 100 * (r["fraction_met"] - base)) < 1e-9 for r in rows)
    assert layout_from_configs(site, [c.config for c in cams])[0].name == cams[0].name
    # the rows against evaluations of the moved layouts themselves
    up = [LayoutCamera(c.name, perturbed_camera(c.camera, height_m=1.0), c.budget) for c in cams]
    got = {(r["change"], r["camera"]): r["fraction_met"] for r in rows}
    assert got[("height +1 m", "all")] == pytest.approx(evaluate_cameras(site, samples, up)[0].fraction, abs=1e-12)
    one = [up[0]] + cams[1:]
    assert got[("height +1 m", cams[0].name)] == pytest.approx(evaluate_cameras(site, samples, one)[0].fraction,
                                                                abs=1e-12)
    tilted = [LayoutCamera(c.name, perturbed_camera(c.camera, tilt_deg=-2.0), c.budget) for c in cams]
    assert got[("tilt -2 deg", "all")] == pytest.approx(evaluate_cameras(site, samples, tilted)[0].fraction, abs=1e-12)


def test_serve_command_listens_on_loopback(planned):
    """``plan --serve`` through the command line: prints its URL on 127.0.0.1 and serves the page."""
    site_path, out, _ = planned
    env = {**os.environ, "PYTHONUNBUFFERED": "1"}
    proc = subprocess.Popen([sys.executable, "-m", "footprint_uq.cli", "plan", "--site", str(site_path), "--serve",
                             "--layout", str(out / "layout.yaml"), "--port", "0"], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, env=env)
    try:
        line = proc.stdout.readline()
        assert "http://127.0.0.1:" in line, line + proc.stderr.read() if proc.poll() is not None else line
        url = line.split("http://", 1)[1].split()[0]
        with urllib.request.urlopen(f"http://{url}", timeout=60) as r:
            page = r.read().decode()
        assert 'id="tilt_deg"' in page and "data:image/png;base64," in page
    finally:
        proc.terminate()
        proc.wait(timeout=30)


def test_nothing_affordable_warns_and_writes_an_empty_layout(planned, tmp_path):
    r = CliRunner().invoke(main, ["plan", "--site", str(planned[0]), "--out", str(tmp_path), "--max-cost", "0.5",
                                  "--no-progress", "--no-sensitivity"])
    assert r.exit_code == 0 and "warning: no candidate camera" in r.output
    assert yaml.safe_load((tmp_path / "layout.yaml").read_text())["cameras"] == []
    assert json.loads((tmp_path / "plan.json").read_text())["fraction_met"] == 0.0
