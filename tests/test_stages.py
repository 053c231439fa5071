"""Long commands are never silent: a line per stage on stderr (with the seconds since the start), a tqdm bar for
counted steps on a terminal only."""

from __future__ import annotations

import io
import re
import time

from click.testing import CliRunner

from footprint_uq import PanTiltCamera, save_camera
from footprint_uq.cli import common
from footprint_uq.cli.main import main

_LINE = re.compile(r"^footprint-uq: (?P<cmd>[a-z -]+): (?P<msg>.+) \[\d+ s\]$")


def _stages(stderr: str, command: str) -> list[str]:
    return [m["msg"] for m in map(_LINE.match, stderr.splitlines()) if m and m["cmd"] == command]


def test_map_says_its_stages(tmp_path):
    cam = tmp_path / "camera.yaml"
    save_camera(PanTiltCamera(focal_px=400.0, image_size_px=(320, 240), height_m=8.0, pan_deg=0.0, tilt_deg=20.0), cam)
    r = CliRunner().invoke(main, ["map", "--camera", str(cam), "--budget", "basler1", "--out", str(tmp_path / "m"),
                                  "--step-px", "16"])
    assert r.exit_code == 0, r.output
    stages = _stages(r.stderr, "map")
    assert stages[0] == "computing 20 x 15 pixels (every 16 px)" and stages[1] == "figures and arrays", r.stderr
    assert "footprint-uq: map:" not in r.stdout  # stdout keeps the results only


def test_calibrate_synthetic_counts_its_images(tmp_path):
    r = CliRunner().invoke(main, ["calibrate", "synthetic", "--out", str(tmp_path / "s"), "--views", "3",
                                  "--scale", "0.2", "--supersample", "1"])
    assert r.exit_code == 0, r.output
    stages = _stages(r.stderr, "calibrate synthetic")
    assert stages[0].startswith("rendering 3 images") and stages[-1] == "3 of 3 done", r.stderr


def test_bar_only_when_asked_or_on_a_terminal(monkeypatch):
    err = io.StringIO()
    monkeypatch.setattr(common.sys, "stderr", err)
    monkeypatch.setattr(common.click, "echo", lambda msg, err=False: print(msg, file=common.sys.stderr))
    plain = common.Stages("x")  # stderr is no terminal here: no bar
    assert not plain.bar
    plain("stage one")
    for k in range(1, 4):
        plain.count(k, 3)
    assert err.getvalue().count("\r") == 0 and _stages(err.getvalue(), "x") == ["stage one", "3 of 3 done"]
    err = io.StringIO()
    monkeypatch.setattr(common.sys, "stderr", err)
    bar = common.Stages("x", bar=True)
    for k in range(1, 4):
        bar.count(k, 3)
    assert "/3 [" in err.getvalue() and "\r" in err.getvalue()  # tqdm drew its bar (and cleared it)
    assert _stages(err.getvalue(), "x") == ["3 of 3 done"]


def test_a_stage_cut_short_by_an_error_says_nothing(monkeypatch):
    """Bad input stays the one line of its error: a stage that fails within the delay is not said; one that runs
    longer is said while it runs (a timer), and the last one at the end of the block."""
    said = []
    monkeypatch.setattr(common.click, "echo", lambda msg, err=False: said.append(msg))
    try:
        with common.Stages("x", delay_s=5.0) as say:
            say("reading")
            raise ValueError("bad input")
    except ValueError:
        pass
    assert said == []
    with common.Stages("x", delay_s=0.05) as say:
        say("a long stage")
        time.sleep(0.5)
        assert len(said) == 1 and _stages(said[0], "x") == ["a long stage"]  # said while it runs
        say("the last stage")
    assert _stages("\n".join(said), "x") == ["a long stage", "the last stage"]
