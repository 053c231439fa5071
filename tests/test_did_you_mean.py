"""Small courtesies of the command line: a typo in a preset, a command or an option gets a "did you mean"."""

from __future__ import annotations

import pytest
from click.testing import CliRunner

from footprint_uq import ErrorBudget, PanTiltCamera, load_budget, save_camera
from footprint_uq.cli.main import main
from footprint_uq.errors import ConfigError
from footprint_uq.uncertainty.presets import suggest_preset


@pytest.mark.parametrize("typo, meant", [
    ("basler", "basler1"), ("BASLR2", "basler2"), ("bw-cub1", "bw-cube1"), ("bwcube2", "bw-cube2"),
    ("bw-bulet2@deg", "bw-bullet2@deg"), ("basler1@rad", "basler1@deg"), ("basler1@", "basler1@deg"),
])
def test_preset_typos_are_suggested(typo, meant):
    assert suggest_preset(typo) == meant
    for call in (load_budget, ErrorBudget.preset):
        with pytest.raises(ConfigError, match=f"did you mean '{meant}'"):
            call(typo)


@pytest.mark.parametrize("name", ["basler1", "BW-Cube1@deg", "my-site.yaml", "zzz"])
def test_no_suggestion_for_a_preset_or_nothing_close(name):
    assert suggest_preset(name) is None


def _run(args):
    r = CliRunner().invoke(main, args)
    assert r.exit_code == 2 and r.stderr.count("\n") == 1, r.output
    return r.stderr


def test_commands_options_and_presets_on_the_command_line(tmp_path):
    assert "Did you mean 'locate'?" in _run(["locat"])
    assert "Did you mean 'synthetic'?" in _run(["calibrate", "synthtic"])
    assert "Did you mean 'compose'?" in _run(["camera", "compos"])
    assert "Did you mean" not in _run(["zzz"])
    assert "Did you mean '--camera'?" in _run(["locate", "--camra", "x"])
    cam = tmp_path / "camera.yaml"
    save_camera(PanTiltCamera(focal_px=1400, image_size_px=(1920, 1080), height_m=8.0, pan_deg=30.0, tilt_deg=20.0),
                cam)
    err = _run(["locate", "--camera", str(cam), "--budget", "bw-cub1", "--pixel", "959.5", "800"])
    assert "budget: got 'bw-cub1'" in err and "did you mean 'bw-cube1'?" in err
