"""First runs: numba's cache folder (package folder, else the user's cache), the cold-cache notice, `warmup`."""

from __future__ import annotations

from pathlib import Path
from types import SimpleNamespace

from click.testing import CliRunner

from footprint_uq import _numba_cache
from footprint_uq.cli.main import main
from footprint_uq.products import warmup as W


def test_cache_folder_is_the_users_when_the_package_is_read_only(monkeypatch, tmp_path):
    env = {"XDG_CACHE_HOME": str(tmp_path)}
    monkeypatch.setattr(_numba_cache, "_writable", lambda folder: True)
    assert _numba_cache.configure(env) is None and "NUMBA_CACHE_DIR" not in env  # numba's default, beside the code
    monkeypatch.setattr(_numba_cache, "_writable", lambda folder: False)
    assert _numba_cache.configure(env) == tmp_path / "footprint-uq" / "numba"
    assert env["NUMBA_CACHE_DIR"] == str(tmp_path / "footprint-uq" / "numba")
    mine = {"NUMBA_CACHE_DIR": "/somewhere", "XDG_CACHE_HOME": str(tmp_path)}
    assert _numba_cache.configure(mine) is None and mine["NUMBA_CACHE_DIR"] == "/somewhere"  # the user's wins
    assert _numba_cache.user_cache_dir({}) == Path.home() / ".cache" / "footprint-uq" / "numba"


def _fake(index: Path):
    return SimpleNamespace(_cache=SimpleNamespace(_cache_file=SimpleNamespace(_index_path=str(index))))


def test_notice_only_when_a_groups_cache_is_cold(monkeypatch, tmp_path):
    have = tmp_path / "k.nbi"
    have.write_bytes(b"")
    monkeypatch.setitem(W.GROUPS, "objects", (_fake(have),))
    monkeypatch.setitem(W.GROUPS, "map", (_fake(have), _fake(tmp_path / "missing.nbi")))
    assert W.cold_groups(["objects", "map"]) == ["map"]
    assert W.compile_notice(["objects"]) is None
    msg = W.compile_notice(["map", "objects"])
    assert msg.startswith("compiling the map kernels once: about 10 s") and "warmup" in msg


def test_warmup_fills_the_cache_and_the_command_reports_it():
    W.warmup(["objects"])  # compiled by the suite already, or now
    assert W.cold_groups(["objects"]) == []
    r = CliRunner().invoke(main, ["warmup", "--only", "objects"])
    assert r.exit_code == 0, r.output
    assert "objects:" in r.stdout and "loaded from the cache" in r.stdout and "cache: " in r.stdout


def test_the_notice_never_comes_before_an_input_error(monkeypatch, tmp_path):
    """A cold cache's notice is said right before the kernels run, after every input is checked: a bad option is
    still one line on stderr; a good run says the notice once, before its output."""
    from footprint_uq import PanTiltCamera, save_camera

    monkeypatch.setattr(W, "cold_groups", lambda groups: list(groups))  # every group "cold"
    cam = tmp_path / "cam.yaml"
    save_camera(PanTiltCamera(focal_px=400.0, image_size_px=(320, 240), height_m=8.0, pan_deg=0.0, tilt_deg=20.0),
                cam)
    base = ["map", "--camera", str(cam), "--budget", "basler1", "--out", str(tmp_path / "m")]
    r = CliRunner().invoke(main, [*base, "--max-range-m", "-5"])
    assert r.exit_code == 2 and r.stderr.count("\n") == 1 and "max_range_m" in r.stderr, r.stderr
    r = CliRunner().invoke(main, [*base, "--step-px", "16"])
    assert r.exit_code == 0, r.output
    assert r.stderr.count("compiling the map kernels once") == 1
